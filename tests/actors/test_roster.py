"""The world's membership bookkeeping: schools numbered once, renumbered when they change."""

from __future__ import annotations

import numpy as np

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
    # Fish 0 comes back in school a: the world's ids are the same array, the numbering not.
    roster.on_alive(keys.alive("fish", 0, "a"), True, now=1.0)
    assert roster.schools(ids).names == ("a",)
    assert roster.schools(ids).number.tolist() == [0, 0]
    # A fish joins: the world has a new ids array, numbered anew.
    roster.on_alive(keys.alive("fish", 5, None), True, now=2.0)
    grown = np.array([0, 1, 5])
    assert roster.schools(grown).number.tolist() == [0, 0, -1]
