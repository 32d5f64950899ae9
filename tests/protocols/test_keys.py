"""The key space: one spelling per key, clear errors for bad names."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fishswarm.protocols.keys import MAX_FISH_ID, KeySpace, Member, fish_id_of


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


def test_names_may_have_64_characters_and_no_more() -> None:
    assert KeySpace("s" * 64).prefix == "fishswarm/" + "s" * 64
    with pytest.raises(ValueError, match="1 to 64 letters"):
        KeySpace("s" * 65)


def test_a_fish_id_in_a_key_is_all_digits_and_at_most_18_of_them() -> None:
    assert fish_id_of("0") == 0
    assert fish_id_of("9" * 18) == MAX_FISH_ID
    assert fish_id_of("1" * 19) is None
    assert fish_id_of("12abc") is None
    assert fish_id_of("") is None


def test_every_name_that_goes_into_a_key_is_checked() -> None:
    keys = KeySpace()
    with pytest.raises(ValueError, match="role name"):
        keys.alive("fish/x", 3)
    with pytest.raises(ValueError, match="school name"):
        keys.school_perceptions("w/0")
    with pytest.raises(ValueError, match="school name"):
        keys.school_commands("w/0")
    with pytest.raises(ValueError, match="school name"):
        keys.about(3, "w/0")
    with pytest.raises(ValueError, match="kind name"):
        keys.every_school("**")


def test_wildcards_match_every_member_and_every_school() -> None:
    keys = KeySpace("t")
    assert keys.about(3) == "fishswarm/t/fish/3/about"
    assert keys.about(3, "w0") == "fishswarm/t/school/w0/about"
    assert keys.abouts() == ("fishswarm/t/fish/*/about", "fishswarm/t/school/*/about")
    # ** so that a fish's token naming its school (one chunk more) matches too.
    assert keys.alive_all("fish") == "fishswarm/t/alive/fish/**"
    assert keys.alive_all() == "fishswarm/t/alive/*/**"
    assert keys.fish_outboxes() == "fishswarm/t/fish/*/outbox"
    assert keys.fish_inboxes() == "fishswarm/t/fish/*/inbox"
    assert keys.robot_statuses() == "fishswarm/t/robot/*/status"


def test_school_of_key_names_the_school_of_school_keys_only() -> None:
    keys = KeySpace("t")
    assert keys.school_of_key(keys.school_commands("w0")) == "w0"
    assert keys.school_of_key(keys.about(3, "w1")) == "w1"
    assert keys.school_of_key(keys.command(3)) is None
    assert keys.school_of_key("fishswarm/t/school/w0/commands/more") is None
    assert keys.school_of_key("fishswarm/other/school/w0/commands") is None


@given(
    arrived=st.integers(min_value=0, max_value=2**63),
    run=st.integers(min_value=0, max_value=2**62 - 1),
)
def test_a_worlds_place_in_the_queue_round_trips_through_its_token(arrived: int, run: int) -> None:
    keys = KeySpace("tank")
    member = keys.parse_alive(keys.queue_place(arrived, run))
    assert member == Member("queue", f"{arrived}-{run}")
    assert keys.place_of(member.member_id) == (arrived, run)


@pytest.mark.parametrize("member_id", ["12", "12-", "-3", "1-2-3", "a-1", "1-b", "١-2", "1-2 "])
def test_a_token_id_that_names_no_place_is_none(member_id: str) -> None:
    assert KeySpace("tank").place_of(member_id) is None
