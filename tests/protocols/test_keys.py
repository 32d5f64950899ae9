"""The key space: one spelling per key, clear errors for bad names."""

from __future__ import annotations

import pytest

from fishswarm.protocols.keys import KeySpace


def test_keys_live_under_the_swarm() -> None:
    keys = KeySpace("tank2")
    assert keys.perception(3) == "fishswarm/tank2/fish/3/perception"
    assert keys.command(3) == "fishswarm/tank2/fish/3/command"
    assert keys.snapshot == "fishswarm/tank2/world/snapshot"
    assert keys.alive("fish", 3) == "fishswarm/tank2/alive/fish/3"


def test_member_of_parses_fish_and_alive_keys() -> None:
    keys = KeySpace()
    assert keys.member_of(keys.command(12)) == ("12", "command")
    assert keys.member_of(keys.alive("fish", 4)) == ("4", "fish")
    with pytest.raises(ValueError, match="not a per-member key"):
        keys.member_of("fishswarm/other/fish/1/command")


def test_bad_swarm_name_is_explained() -> None:
    with pytest.raises(ValueError, match="letters, digits"):
        KeySpace("my swarm/x")
