"""The in-memory Bus: Zenoh's key matching, subscriptions, liveliness with history."""

from __future__ import annotations

import zenoh
from hypothesis import given
from hypothesis import strategies as st

from fishswarm.actors.bus import MemoryBus, key_matches

CHUNKS = st.sampled_from(["a", "b", "fish", "3"])
PATTERN_CHUNKS = st.sampled_from(["a", "b", "fish", "3", "*", "**"])


def _canonical(chunks: list[str]) -> str:
    """Zenoh's canonical form: no ``**/**``, and ``*/**`` rather than ``**/*``."""
    text = "/".join(chunks)
    while True:
        changed = text.replace("**/**", "**").replace("**/*/", "*/**/")
        if changed.endswith("**/*"):
            changed = changed[: -len("**/*")] + "*/**"
        if changed == text:
            return text
        text = changed


@given(st.lists(PATTERN_CHUNKS, min_size=1, max_size=5), st.lists(CHUNKS, min_size=1, max_size=5))
def test_key_matching_agrees_with_zenoh(pattern: list[str], key: list[str]) -> None:
    key_expr, concrete = _canonical(pattern), "/".join(key)
    expected = zenoh.KeyExpr(key_expr).includes(zenoh.KeyExpr(concrete))
    assert key_matches(key_expr, concrete) == expected


def test_keys_drawn_on_paper() -> None:
    assert key_matches("fishswarm/default/fish/*/outbox", "fishswarm/default/fish/3/outbox")
    assert not key_matches("fishswarm/default/fish/*/outbox", "fishswarm/default/fish/3/x/outbox")
    assert key_matches("fishswarm/default/alive/**", "fishswarm/default/alive/fish/3/school")
    assert not key_matches("fishswarm/default/alive/**", "fishswarm/other/alive/fish/3")


def test_puts_reach_matching_subscribers_in_order_until_undeclared() -> None:
    bus = MemoryBus()
    got: list[tuple[str, bytes]] = []
    declared = bus.subscribe("x/*", lambda key, payload: got.append((key, payload)))
    bus.put("x/1", b"a")
    bus.put("y/1", b"b")
    bus.put("x/2", b"c")
    declared.undeclare()
    bus.put("x/3", b"d")
    assert got == [("x/1", b"a"), ("x/2", b"c")]
    assert bus.puts == 4


def test_liveliness_watchers_see_current_tokens_then_changes() -> None:
    bus = MemoryBus()
    first = bus.declare_token("alive/fish/1")
    seen: list[tuple[str, bool]] = []
    watch = bus.watch_alive("alive/**", lambda key, alive: seen.append((key, alive)))
    second = bus.declare_token("alive/fish/2")
    first.undeclare()
    first.undeclare()  # twice is once
    watch.undeclare()
    second.undeclare()
    assert seen == [("alive/fish/1", True), ("alive/fish/2", True), ("alive/fish/1", False)]
