"""Decoding what arrives: bad payloads are counted and logged, the log bounded whatever keys
a sender chooses."""

from __future__ import annotations

import pytest

from fishswarm.actors.intake import LOGGED_SENDERS, Intake
from fishswarm.protocols.messages import Broadcast


def test_rejections_from_ever_new_keys_are_all_counted_but_the_log_stays_bounded(
    caplog: pytest.LogCaptureFixture,
) -> None:
    intake = Intake("channel")
    with caplog.at_level("WARNING", logger="fishswarm.actors.intake"):
        for fish_id in range(10_000):
            assert (
                intake.decode(f"fishswarm/default/fish/{fish_id}/outbox", b"\x00", Broadcast)
                is None
            )
        # The same sender again: counted, not logged again.
        intake.decode("fishswarm/default/fish/0/outbox", b"\x00", Broadcast)
    assert intake.rejected == {"malformed": 10_001}
    lines = [record.getMessage() for record in caplog.records]
    assert len(lines) == LOGGED_SENDERS + 1
    assert "further malformed rejections are counted, not logged" in lines[-1]
    assert len(intake._logged) == LOGGED_SENDERS
