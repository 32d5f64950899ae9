"""The field checks every message runs: their limits, and arrays that cannot change."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.protocols.checks import MAX_ROWS, MAX_TEXT, check_float, check_text
from fishswarm.protocols.messages import CommandBatch, ControlReply, Perception, PerceptionBatch


def test_a_number_field_refuses_a_bool() -> None:
    check_float("time", 1)
    with pytest.raises(TypeError, match="time must be a number, got bool"):
        check_float("time", True)


def test_text_may_have_max_text_characters_and_no_more() -> None:
    check_text("state", "s" * MAX_TEXT)
    with pytest.raises(ValueError, match=f"state must have 1 to {MAX_TEXT} characters, got 65"):
        check_text("state", "s" * (MAX_TEXT + 1))
    assert ControlReply("running", 0, 0.0, 0, refused="r" * MAX_TEXT).refused == "r" * MAX_TEXT


def test_an_array_may_have_max_rows_rows_and_no_more() -> None:
    rows = np.zeros((MAX_ROWS, 3))
    perception = Perception(0, 0, 0.0, 0.0, rows, np.zeros((0, 3)))
    assert perception.neighbors.shape == (MAX_ROWS, 3)
    with pytest.raises(ValueError, match=f"more than the limit {MAX_ROWS}"):
        Perception(0, 0, 0.0, 0.0, np.zeros((MAX_ROWS + 1, 3)), np.zeros((0, 3)))


def test_a_message_keeps_its_arrays_whatever_the_caller_does_with_its_own() -> None:
    neighbors = np.array([[1.0, 2.0, 3.0]])
    perception = Perception(0, 0, 0.0, 0.0, neighbors, np.zeros((0, 3)))
    neighbors[0, 0] = 9.0
    assert perception.neighbors.tolist() == [[1.0, 2.0, 3.0]]
    with pytest.raises(ValueError, match="read-only"):
        perception.neighbors[0, 0] = 9.0


def test_a_message_keeps_its_arrays_from_memory_the_caller_can_still_change() -> None:
    memory = np.array([[1.0, 2.0, 3.0]])
    view = memory[:]
    view.setflags(write=False)  # read-only itself, but a view of what the caller may write
    perception = Perception(0, 0, 0.0, 0.0, view, np.zeros((0, 3)))
    memory[0, 0] = 9.0
    assert perception.neighbors.tolist() == [[1.0, 2.0, 3.0]]


def test_nobody_can_make_an_array_the_checks_copied_writable_again() -> None:
    perception = Perception(0, 0, 0.0, 0.0, np.array([[1.0, 2.0, 3.0]]), np.zeros((0, 3)))
    for array in (perception.neighbors, perception.neighbors[:1], perception.landmarks):
        with pytest.raises(ValueError, match="WRITEABLE"):
            array.setflags(write=True)


def test_a_read_only_array_that_owns_its_memory_is_kept_as_it_is() -> None:
    owned = np.array([[1.0, 2.0, 3.0]])
    owned.setflags(write=False)  # a promise its holder keeps: no copy
    assert Perception(0, 0, 0.0, 0.0, owned, np.zeros((0, 3))).neighbors is owned


def test_an_array_of_an_equal_dtype_of_another_name_is_stored_as_the_messages_own() -> None:
    ids = np.array([2, 3], dtype=np.longlong)  # equal to int64, but not int64 by name
    batch = CommandBatch(1, ids, np.zeros((2, 4)), np.ones(2, dtype=bool), np.zeros(2, int))
    assert batch.ids.dtype is np.dtype(np.int64)
    assert type(batch.ids[0]) is np.int64
    assert batch.ids.tolist() == [2, 3]


def test_an_empty_list_may_stand_for_no_booleans_and_no_integers() -> None:
    # An empty list has no dtype to tell a boolean or integer array from another
    # (np.asarray makes it float64): empty is empty, whatever its dtype.
    batch = CommandBatch(1, [], np.zeros((0, 4)), [], [])  # type: ignore[arg-type]
    assert [str(a.dtype) for a in (batch.ids, batch.led, batch.broadcasts)] == [
        "int64", "bool", "int64",
    ]  # fmt: skip
    assert batch.led.shape == batch.ids.shape == (0,)
    with pytest.raises(TypeError, match="led must be a boolean array"):
        CommandBatch(1, np.array([0]), np.zeros((1, 4)), np.array([1.0]), np.array([0]))
    with pytest.raises(TypeError, match="ids must be an integer array"):
        CommandBatch(1, np.array([0.0]), np.zeros((1, 4)), np.array([True]), np.array([0]))


def test_counts_that_add_up_to_fewer_rows_than_there_are_are_refused() -> None:
    with pytest.raises(ValueError, match="add up to 1, but neighbors has 2 rows"):
        PerceptionBatch(
            1, 1.0, np.array([0, 1]), np.array([0.5, 0.5]), np.array([1, 0]), np.zeros((2, 3)),
            np.array([0, 0]), np.zeros((0, 3)), np.array([0, 0]),
        )  # fmt: skip


def test_a_formation_order_names_one_shape_and_no_other_order_names_one() -> None:
    from fishswarm.protocols.messages import RobotOrder

    assert RobotOrder("formation", formation="diamond").formation == "diamond"
    with pytest.raises(ValueError, match="a formation order names its shape"):
        RobotOrder("formation")
    with pytest.raises(ValueError, match="action 'stop' with formation 'column'"):
        RobotOrder("stop", formation="column")
    with pytest.raises(ValueError, match="formation must be one of"):
        RobotOrder("formation", formation="circle")
