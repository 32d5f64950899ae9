"""The world's membership bookkeeping: schools numbered once, renumbered when they change."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fishswarm.actors.bus import Declared
from fishswarm.actors.roster import Roster
from fishswarm.protocols.keys import KeySpace


class _Subscription:
    def undeclare(self) -> None:
        pass


def _roster() -> Roster:
    def subscribe(key: str, kind: str) -> Declared:
        return _Subscription()

    return Roster(KeySpace(), subscribe)


def test_schools_are_numbered_once_while_nothing_changes() -> None:
    keys, roster = KeySpace(), _roster()
    for fish_id, school in [(0, "b"), (1, "a"), (2, None)]:
        roster.on_alive(keys.alive("fish", fish_id, school), True, now=0.0)
    ids = np.array([0, 1, 2])
    first = roster.schools(ids)
    assert first.names == ("a", "b") and first.number.tolist() == [1, 0, -1]
    assert roster.schools(ids) is first
    # The same fish's token again (a second session, say): nothing changes.
    roster.on_alive(keys.alive("fish", 1, "a"), True, now=1.0)
    assert roster.schools(ids) is first


def test_a_fish_in_another_school_or_new_ids_renumber() -> None:
    keys, roster = KeySpace(), _roster()
    for fish_id, school in [(0, "b"), (1, "a")]:
        roster.on_alive(keys.alive("fish", fish_id, school), True, now=0.0)
    ids = np.array([0, 1])
    assert roster.schools(ids).number.tolist() == [1, 0]
    # Fish 0 leaves school b and comes back in school a: the world's ids are the same array,
    # the numbering not.
    assert roster.on_alive(keys.alive("fish", 0, "b"), False, now=0.5) == 0
    roster.on_alive(keys.alive("fish", 0, "a"), True, now=1.0)
    assert roster.schools(ids).names == ("a",)
    assert roster.schools(ids).number.tolist() == [0, 0]
    # A fish joins: the world has a new ids array, numbered anew.
    roster.on_alive(keys.alive("fish", 5, None), True, now=2.0)
    grown = np.array([0, 1, 5])
    assert roster.schools(grown).number.tolist() == [0, 0, -1]


def test_a_fish_that_moves_to_another_school_sends_on_its_new_key_once_the_old_one_goes(
    caplog: pytest.LogCaptureFixture,
) -> None:
    keys, roster = KeySpace(), _roster()
    roster.on_alive(keys.alive("fish", 0, "a"), True, now=0.0)
    roster.on_alive(keys.alive("fish", 1, "a"), True, now=0.0)
    school_a, school_b = keys.school_commands("a"), keys.school_commands("b")
    assert roster.all_on(school_a, np.array([0, 1]))
    # Fish 1 comes up in school b (a restart, or a second process given its id) while its
    # token in school a is up: school a keeps it, and the world hears of the second one.
    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.roster"):
        assert roster.on_alive(keys.alive("fish", 1, "b"), True, now=1.0) is None
    assert (
        f"fish 1 is served by two processes, {keys.alive('fish', 1, 'a')} and "
        f"{keys.alive('fish', 1, 'b')}: "
        f"this world takes the commands of {keys.alive('fish', 1, 'a')}, heard of first"
    ) in caplog.text
    assert roster.all_on(school_a, np.array([0, 1]))
    # School a's token of fish 1 goes: the fish leaves the world (this tick's perception
    # went to school a), and school b's token takes it over, to bring it back.
    assert roster.on_alive(keys.alive("fish", 1, "a"), False, now=2.0) == 1
    assert roster.mark_lost(1, 7, "left", now=2.0)  # as the world loses it
    assert not roster.all_on(school_a, np.array([0, 1]))
    assert roster.all_on(school_a, np.array([0])) and roster.all_on(school_b, np.array([1]))
    assert roster.alive == {0, 1}
    assert roster.ready({0}, now=3.0, admit_delay=0.1) == [1]  # it comes back


def test_a_second_process_with_a_taken_id_leaves_without_taking_the_fish_along() -> None:
    # A run's own fish 2 in school worker-0, and a `fishswarm fish --id 2` started by mistake,
    # which comes and goes: the run's fish 2 stays, in its school, and is not lost.
    keys, roster = KeySpace(), _roster()
    for fish_id in range(4):
        roster.on_alive(keys.alive("fish", fish_id, "worker-0"), True, now=0.0)
    school = keys.school_commands("worker-0")
    roster.on_alive(keys.alive("fish", 2), True, now=1.0)
    assert roster.all_on(school, np.arange(4))
    assert roster.on_alive(keys.alive("fish", 2), False, now=2.0) is None
    assert roster.all_on(school, np.arange(4)) and roster.alive == {0, 1, 2, 3}
    # The school's own token of fish 2 going is the fish leaving.
    assert roster.on_alive(keys.alive("fish", 2, "worker-0"), False, now=3.0) == 2
    assert roster.alive == {0, 1, 3}


def test_a_spare_takes_over_a_fish_lost_while_its_process_hangs() -> None:
    # Fish 4's second process comes up while the first still answers (a spare); then the
    # first hangs, its token up: the world loses fish 4, and the spare brings it back.
    keys, roster = KeySpace(), _roster()
    roster.on_alive(keys.alive("fish", 4, "old"), True, now=0.0)
    roster.on_alive(keys.alive("fish", 4, "new"), True, now=1.0)
    assert roster.mark_lost(4, 3, "no command within 10 s", now=12.0)
    assert roster.alive == {4} and roster.all_on(keys.school_commands("new"), np.array([4]))
    assert roster.ready(set(), now=13.0, admit_delay=0.1) == [4]
    # Without a spare, a lost fish stays out.
    roster.on_alive(keys.alive("fish", 5), True, now=0.0)
    assert roster.mark_lost(5, 3, "silent", now=12.0) and 5 not in roster.alive


def test_a_lost_fish_is_taken_over_at_once_by_a_process_that_comes_up_for_it() -> None:
    # Fish 4's process hangs (its token stays up, its commands stop): the world loses it; a
    # new process for fish 4 in another school speaks for it from then on.
    keys, roster = KeySpace(), _roster()
    roster.on_alive(keys.alive("fish", 4, "old"), True, now=0.0)
    assert roster.mark_lost(4, 3, "silent")
    roster.on_alive(keys.alive("fish", 4, "new"), True, now=5.0)
    assert roster.alive == {4} and roster.all_on(keys.school_commands("new"), np.array([4]))
    # The hung process's token going at last loses nothing.
    assert roster.on_alive(keys.alive("fish", 4, "old"), False, now=9.0) is None
    assert roster.alive == {4}


def test_channels_are_counted_up_and_down_by_their_tokens() -> None:
    keys, roster = KeySpace(), _roster()
    roster.on_alive(keys.alive("channel", "c1"), True, now=0.0)
    roster.on_alive(keys.alive("channel", "c2"), True, now=0.0)
    roster.on_alive(keys.alive("channel", "c1"), False, now=1.0)
    assert roster.channels == 1


def test_a_fish_is_lost_once_a_tick_and_again_at_a_later_one() -> None:
    keys, roster = KeySpace(), _roster()
    roster.on_alive(keys.alive("fish", 4), True, now=0.0)
    assert roster.mark_lost(4, 3, "silent") and not roster.mark_lost(4, 3, "silent")
    assert roster.alive == set()
    roster.on_alive(keys.alive("fish", 4), True, now=5.0)  # back, and lost again later
    assert roster.mark_lost(4, 7, "silent")
    assert [(f.fish_id, f.tick) for f in roster.lost] == [(4, 3), (4, 7)]


def test_a_fish_is_ready_once_its_command_subscription_has_had_time_to_spread() -> None:
    keys, roster = KeySpace(), _roster()
    roster.on_alive(keys.alive("fish", 2), True, now=10.0)
    roster.on_alive(keys.alive("fish", 3), True, now=10.5)
    assert roster.ready(set(), now=10.4, admit_delay=0.5) == []
    assert roster.ready(set(), now=11.0, admit_delay=0.5) == [2, 3]
    assert roster.ready({2}, now=11.0, admit_delay=0.5) == [3]


def test_the_roster_keeps_the_places_queue_tokens_name_until_they_go() -> None:
    """A world's place token adds its place (arrival µs, run id), under its token, and takes
    it away when it goes; a queue token that names no place adds none (nor does one that
    goes without having come)."""
    keys, roster = KeySpace(), _roster()
    place = keys.queue_place(1_700_000_000_000_000, 42)
    roster.on_alive(place, True, now=0.0)
    roster.on_alive(keys.alive("queue", "soon"), True, now=0.0)
    roster.on_alive(keys.alive("queue", "12-x"), True, now=0.0)
    assert roster.queue == {place: (1_700_000_000_000_000, 42)}
    roster.on_alive(keys.queue_place(5, 6), False, now=1.0)
    roster.on_alive(place, False, now=1.0)
    assert roster.queue == {} and roster.worlds == set() and roster.alive == set()
