"""The key space: one spelling per key, clear errors for bad names."""

from __future__ import annotations

import pytest

from fishswarm.protocols.keys import KeySpace, Member


def test_keys_live_under_the_swarm() -> None:
    keys = KeySpace("tank2")
    assert keys.perception(3) == "fishswarm/tank2/fish/3/perception"
    assert keys.command(3) == "fishswarm/tank2/fish/3/command"
    assert keys.snapshot == "fishswarm/tank2/world/snapshot"
    assert keys.alive("fish", 3) == "fishswarm/tank2/alive/fish/3"
    assert keys.alive("fish", 3, "worker-1") == "fishswarm/tank2/alive/fish/3/worker-1"
    assert keys.school_perceptions("worker-1") == "fishswarm/tank2/school/worker-1/perceptions"
    assert keys.school_commands("worker-1") == "fishswarm/tank2/school/worker-1/commands"


def test_member_of_parses_fish_keys() -> None:
    keys = KeySpace()
    assert keys.member_of(keys.command(12)) == ("12", "command")
    with pytest.raises(ValueError, match="not a per-member key"):
        keys.member_of("fishswarm/other/fish/1/command")
    with pytest.raises(ValueError, match="not a per-member key"):
        keys.member_of(keys.alive("fish", 4))


def test_parse_alive_tells_own_keys_from_a_school() -> None:
    keys = KeySpace()
    assert keys.parse_alive(keys.alive("fish", 4)) == Member("fish", "4")
    assert keys.parse_alive(keys.alive("fish", 4, "w0")) == Member("fish", "4", "w0")
    assert keys.parse_alive(keys.alive("world", 0)) == Member("world", "0")
    with pytest.raises(ValueError, match="not a liveliness token"):
        keys.parse_alive(keys.command(4))
    with pytest.raises(ValueError, match="school name"):
        keys.alive("fish", 4, "w/0")


def test_bad_swarm_name_is_explained() -> None:
    with pytest.raises(ValueError, match="letters, digits"):
        KeySpace("my swarm/x")
