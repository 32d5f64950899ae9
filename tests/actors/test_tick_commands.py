"""A tick's commands taken in as arrays: who is awaited, who answered, and lookups by id."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from fishswarm.actors.tick_commands import TickCommands, among, values_at


def test_a_tick_takes_each_awaited_fish_once_and_knows_who_is_left() -> None:
    tick = TickCommands.of(7, np.array([2, 5, 9, 11]))
    assert tick.left == 4 and tick.waiting_ids() == [2, 5, 9, 11]
    rows = tick.rows_awaited(np.array([5, 11]))
    assert rows is not None and rows.tolist() == [1, 3]
    tick.take(rows, np.array([[0.1, 0, 0, 0], [0.3, 0, 0, 0]]), [1, 0])
    assert tick.left == 2 and tick.waiting_ids() == [2, 9]
    # Answered already, never asked (between, beyond, below the ids): none is taken.
    for ids in ([5], [9, 11], [6], [12], [1]):
        assert tick.rows_awaited(np.array(ids)) is None
    assert tick.rows_awaited(np.zeros(0, dtype=np.int64)) is not None
    tick.give_up(9)
    tick.give_up(9)  # twice is once
    tick.give_up(4)  # never asked: nothing
    assert tick.left == 1 and tick.waiting_ids() == [2]
    assert tick.answered.tolist() == [False, True, False, True]  # a lost fish did not answer
    np.testing.assert_array_equal(tick.fins[:, 0], [0.0, 0.1, 0.0, 0.3])
    assert tick.broadcasts.tolist() == [0, 1, 0, 0]


def test_values_are_found_by_id_and_zero_for_fish_not_listed() -> None:
    ids = np.array([3, 4, 8])
    values = np.array([30, 40, 80])
    assert values_at(ids, values, np.array([1, 3, 5, 8, 9])).tolist() == [0, 30, 0, 80, 0]
    assert values_at(ids[:0], values[:0], np.array([1, 2])).tolist() == [0, 0]
    assert values_at(ids, values, np.zeros(0, dtype=np.int64)).tolist() == []


def test_membership_among_sorted_ids_drawn_on_paper() -> None:
    ids = np.array([3, 4, 8])
    assert among(ids, np.array([1, 3, 5, 8, 9, 4])).tolist() == [
        False,
        True,
        False,
        True,
        False,
        True,
    ]
    assert among(ids[:0], np.array([1, 2])).tolist() == [False, False]
    assert among(ids, np.zeros(0, dtype=np.int64)).tolist() == []


@given(
    st.sets(st.integers(0, 60), max_size=30),
    st.lists(st.integers(-5, 70), max_size=30),
)
def test_membership_among_sorted_ids_is_numpys_isin(ids: set[int], wanted: list[int]) -> None:
    haystack = np.array(sorted(ids), dtype=np.int64)
    needles = np.array(wanted, dtype=np.int64)
    assert among(haystack, needles).tolist() == np.isin(needles, haystack).tolist()
