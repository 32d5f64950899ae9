"""Decoding what arrives: bad payloads are counted and logged, the log bounded whatever keys
a sender chooses."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.actors.intake import LOGGED_SENDERS, Intake
from fishswarm.protocols.codec import encode
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


def test_a_valid_message_refused_counts_as_rejected_not_accepted() -> None:
    intake = Intake("channel")
    mine = encode(Broadcast(3, 1, "signal", np.array([1])))
    theirs = encode(Broadcast(4, 1, "signal", np.array([1])))
    key = "fishswarm/default/fish/3/outbox"
    assert intake.decode_addressed(key, mine, Broadcast, field="sender_id", owner=3) is not None
    assert intake.decode_addressed(key, theirs, Broadcast, field="sender_id", owner=3) is None
    assert intake.decode(key, mine, Broadcast) is not None
    intake.refuse(key, "stale", "a broadcast of a tick gone by")
    assert intake.accepted == 1
    assert intake.rejected == {"misaddressed": 1, "stale": 1}
