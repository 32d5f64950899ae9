"""What a session that cannot open says: Zenoh's reason, without its Rust source's places."""

from __future__ import annotations

import pytest

from fishswarm.actors.session import _without_source


@pytest.mark.parametrize(
    ("reason", "said"),
    [
        (
            "Unable to connect to any of [Single(tcp/127.0.0.1:1)]. Timeout! at "
            "/root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/zenoh/src/net/"
            "runtime/orchestrator.rs:388.",
            "Unable to connect to any of [Single(tcp/127.0.0.1:1)]. Timeout!",
        ),
        (
            "Can not create a new TCP listener bound to tcp/127.0.0.1:44121: [127.0.0.1:44121: "
            "Address already in use (os error 98) at /root/.cargo/git/checkouts/zenoh-x/"
            "io/zenoh-link-commons/src/tcp.rs:61.]",
            "Can not create a new TCP listener bound to tcp/127.0.0.1:44121: [127.0.0.1:44121: "
            "Address already in use (os error 98)]",
        ),
        ("Unable to open]!  at /root/a/b/c.rs:447.", "Unable to open]!"),
        ("no place in it", "no place in it"),
    ],
)
def test_zenohs_reason_keeps_its_words_and_loses_its_source_places(reason: str, said: str) -> None:
    assert _without_source(reason) == said
