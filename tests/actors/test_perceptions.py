"""Cutting a tick's vision into messages: per-fish perceptions and school batches."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fishswarm.actors.perceptions import Schools, perception_messages
from fishswarm.behaviors.core import stack_rows
from fishswarm.bluebot.vision import Perceived, Stacked
from fishswarm.protocols import codec, decode, encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import Perception, PerceptionBatch


def _perceived(rows: list[list[list[float]]], width: int) -> Perceived:
    neighbors = np.zeros((len(rows), width, 3))
    mask = np.zeros((len(rows), width), dtype=bool)
    for fish, seen in enumerate(rows):
        if seen:
            neighbors[fish, : len(seen)] = seen
            mask[fish, : len(seen)] = True
    return Perceived(neighbors, mask, np.where(mask, 0, -1))


def test_schools_get_one_batch_and_others_their_own_perception() -> None:
    keys = KeySpace()
    ids = np.array([1, 4, 7])
    perceived = _perceived([[[1.0, 0, 0]], [[0, 2.0, 0], [0, 0, 3.0]], []], width=2)
    landmarks = _perceived([[], [[5.0, 0, 0]], [[6.0, 0, 0]]], width=1)
    messages = perception_messages(
        keys,
        ids=ids,
        schools=Schools.of(ids, {1: "s", 4: None, 7: "s"}),
        depth=np.array([0.1, 0.4, 0.7]),
        perceived=perceived,
        landmarks=landmarks,
        inbox_counts=np.array([0, 2, 0]),
        tick=9,
        time=9.0,
    )
    assert [key for key, _ in messages] == [keys.perception(4), keys.school_perceptions("s")]
    alone = messages[0][1]
    assert isinstance(alone, Perception)
    assert alone.fish_id == 4 and alone.depth == 0.4 and alone.inbox_count == 2
    np.testing.assert_array_equal(alone.neighbors, [[0, 2.0, 0], [0, 0, 3.0]])
    np.testing.assert_array_equal(alone.landmarks, [[5.0, 0, 0]])
    batch = messages[1][1]
    assert isinstance(batch, PerceptionBatch)
    assert batch.ids.tolist() == [1, 7] and batch.tick == 9
    assert batch.neighbor_counts.tolist() == [1, 0]
    np.testing.assert_array_equal(batch.neighbors, [[1.0, 0, 0]])
    assert batch.landmark_counts.tolist() == [0, 1]
    np.testing.assert_array_equal(batch.landmarks, [[6.0, 0, 0]])
    only_seven = perception_messages(
        keys,
        ids=ids,
        schools=Schools.of(ids, {1: "s", 4: None, 7: "s"}),
        depth=np.array([0.1, 0.4, 0.7]),
        perceived=perceived,
        landmarks=landmarks,
        inbox_counts=np.zeros(3, dtype=np.int64),
        tick=10,
        time=9.5,
        rows=[2],
    )
    assert len(only_seven) == 1
    assert isinstance(only_seven[0][1], PerceptionBatch)
    assert only_seven[0][1].ids.tolist() == [7]


def test_schools_are_numbered_in_name_order_and_fish_without_one_are_minus_one() -> None:
    ids = np.array([1, 4, 7, 9, 12])
    schools = Schools.of(ids, {1: "b", 4: None, 7: "a", 12: "b"})  # 9: not known, own keys
    assert schools.names == ("a", "b")
    assert schools.number.tolist() == [1, -1, 0, -1, 1]
    assert not schools.number.flags.writeable


def test_numbering_of_other_fish_is_refused() -> None:
    perceived = _perceived([[], []], width=1)
    with pytest.raises(ValueError, match="numbered for 3 fish, not 2"):
        perception_messages(
            KeySpace(),
            ids=np.array([0, 1]),
            schools=Schools.of(np.array([0, 1, 2]), {}),
            depth=np.zeros(2),
            perceived=perceived,
            landmarks=perceived,
            inbox_counts=np.zeros(2, dtype=np.int64),
            tick=1,
            time=1.0,
        )


def test_parts_of_several_schools_take_turns() -> None:
    # Schools a (fish 0-4) and b (fish 5-6), one row each, at most 2 rows a batch: a gets
    # parts [0, 1], [2, 3], [4] and b gets [5, 6]; they go a, b, a, a (b has run out), so
    # that b's worker need not wait for all of a's parts.
    keys = KeySpace()
    ids = np.arange(7)
    common: dict[str, Any] = {
        "ids": ids,
        "schools": Schools.of(ids, {i: "a" if i < 5 else "b" for i in range(7)}),
        "depth": np.zeros(7),
        "perceived": _perceived([[[float(i), 0.0, 0.0]] for i in range(7)], width=1),
        "landmarks": _perceived([[] for _ in range(7)], width=1),
        "inbox_counts": np.zeros(7, dtype=np.int64),
        "tick": 2,
        "time": 2.0,
        "row_limit": 2,
    }
    messages = perception_messages(keys, **common)
    a, b = keys.school_perceptions("a"), keys.school_perceptions("b")
    assert [key for key, _ in messages] == [a, b, a, a]
    batches = [m for _, m in messages if isinstance(m, PerceptionBatch)]
    assert [m.ids.tolist() for m in batches] == [[0, 1], [5, 6], [2, 3], [4]]
    # Only fish 5 due (jitter mode): one batch, for b alone; none, empty, for a.
    due = perception_messages(keys, rows=[5], **common)
    assert [key for key, _ in due] == [b]


def test_a_school_too_large_for_one_batch_gets_consecutive_parts_within_the_limit() -> None:
    # Six fish of one school seeing 3, 1, 4, 1, 5, 2 neighbours, a limit of 5 rows: parts
    # [3, 1] (4 rows), [4, 1] (5), [5] (5), [2]; together exactly the one batch's rows.
    keys = KeySpace()
    seen = [3, 1, 4, 1, 5, 2]
    rows = [[[float(fish), float(k), 0.0] for k in range(n)] for fish, n in enumerate(seen)]
    perceived = _perceived(rows, width=5)
    landmarks = _perceived([[] for _ in seen], width=1)
    common: dict[str, Any] = {
        "ids": np.arange(10, 16),
        "schools": Schools.of(np.arange(10, 16), dict.fromkeys(range(10, 16), "s")),
        "depth": np.linspace(0.1, 0.6, 6),
        "perceived": perceived,
        "landmarks": landmarks,
        "inbox_counts": np.zeros(6, dtype=np.int64),
        "tick": 3,
        "time": 3.0,
    }
    whole = [m for _, m in perception_messages(keys, **common) if isinstance(m, PerceptionBatch)]
    parts = perception_messages(keys, row_limit=5, **common)
    batches = [m for _, m in parts if isinstance(m, PerceptionBatch)]
    assert len(whole) == 1 and len(batches) == len(parts)
    assert [b.ids.tolist() for b in batches] == [[10, 11], [12, 13], [14], [15]]
    assert all(b.neighbors.shape[0] <= 5 for b in batches)
    np.testing.assert_array_equal(
        np.concatenate([b.neighbors for b in batches]), whole[0].neighbors
    )
    # A limit below one fish's rows still sends that fish, alone.
    tight = perception_messages(keys, row_limit=2, **common)
    assert [m.ids.tolist() for _, m in tight if isinstance(m, PerceptionBatch)][:3] == [
        [10],
        [11],
        [12],
    ]


@settings(max_examples=60, deadline=None)
@given(
    seen=st.lists(st.integers(0, 4), min_size=1, max_size=12),
    schools=st.data(),
    row_limit=st.integers(4, 30),
)
def test_every_batch_carries_exactly_its_fishs_rows(
    seen: list[int], schools: st.DataObject, row_limit: int
) -> None:
    # Fish spread over two schools and their own keys at random: every fish's neighbours
    # and landmarks reach it, in its own rows, whichever batch or part carries it.
    count = len(seen)
    rows = [[[float(fish), float(k), 1.0] for k in range(n)] for fish, n in enumerate(seen)]
    perceived = _perceived(rows, width=max(seen) or 1)
    landmarks = _perceived([[[float(fish), 0.0, 2.0]] * (fish % 2) for fish in range(count)], 1)
    school_of = {
        fish_id: schools.draw(st.sampled_from(["a", "b", None])) for fish_id in range(count)
    }
    messages = perception_messages(
        KeySpace(),
        ids=np.arange(count),
        schools=Schools.of(np.arange(count), school_of),
        depth=np.arange(count) / 10,
        perceived=perceived,
        landmarks=landmarks,
        inbox_counts=np.arange(count),
        tick=1,
        time=1.0,
        row_limit=row_limit,
    )
    got: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
    for _, message in messages:
        if isinstance(message, Perception):
            got[message.fish_id] = (message.neighbors, message.landmarks, message.depth)
            continue
        assert isinstance(message, PerceptionBatch)
        starts = np.concatenate([[0], np.cumsum(message.neighbor_counts)])
        marks = np.concatenate([[0], np.cumsum(message.landmark_counts)])
        for n, fish_id in enumerate(message.ids.tolist()):
            got[fish_id] = (
                message.neighbors[starts[n] : starts[n + 1]],
                message.landmarks[marks[n] : marks[n + 1]],
                float(message.depth[n]),
            )
    assert sorted(got) == list(range(count))
    for fish_id, (neighbors, seen_landmarks, depth) in got.items():
        np.testing.assert_array_equal(neighbors, np.array(rows[fish_id]).reshape(-1, 3))
        assert seen_landmarks.shape == (fish_id % 2, 3)
        assert depth == fish_id / 10


def test_time_run_heading_formation_and_inbox_counts_reach_fish_alone_and_in_schools() -> None:
    keys = KeySpace()
    ids = np.array([2, 5, 8])
    nothing = _perceived([[], [], []], width=1)
    messages = perception_messages(
        keys,
        ids=ids,
        schools=Schools.of(ids, {2: "s", 5: None, 8: "s"}),
        depth=np.array([0.1, 0.2, 0.3]),
        perceived=nothing,
        landmarks=nothing,
        inbox_counts=np.array([1, 2, 3]),
        tick=4,
        time=1.25,
        run=3,
        heading=np.array([0.1, -0.2, 3.0]),
        formation="pyramid",
    )
    (_, alone), (_, batch) = messages
    assert isinstance(alone, Perception) and isinstance(batch, PerceptionBatch)
    assert (alone.fish_id, alone.tick, alone.time, alone.run) == (5, 4, 1.25, 3)
    assert (alone.heading, alone.formation, alone.inbox_count) == (-0.2, "pyramid", 2)
    assert (batch.tick, batch.time, batch.run, batch.formation) == (4, 1.25, 3, "pyramid")
    assert batch.heading is not None and batch.heading.tolist() == [0.1, 3.0]
    assert batch.inbox_counts.tolist() == [1, 3]


def _school_of_three(landmark_rows: int, row_limit: int) -> list[list[int]]:
    """The fish of each batch of a school of three fish that see no neighbours and
    ``landmark_rows`` landmarks each."""
    ids = np.arange(3)
    batches = perception_messages(
        KeySpace(),
        ids=ids,
        schools=Schools.of(ids, dict.fromkeys(range(3), "s")),
        depth=np.zeros(3),
        perceived=_perceived([[], [], []], width=1),
        landmarks=_perceived([[[1.0, 0.0, 0.0]] * landmark_rows] * 3, width=2),
        inbox_counts=np.zeros(3, dtype=np.int64),
        tick=1,
        time=1.0,
        row_limit=row_limit,
    )
    return [m.ids.tolist() for _, m in batches if isinstance(m, PerceptionBatch)]


def test_landmark_rows_count_toward_a_batchs_limit() -> None:
    # Two landmarks each, at most 4 rows: two fish (4 rows), then the third.
    assert _school_of_three(landmark_rows=2, row_limit=4) == [[0, 1], [2]]
    assert _school_of_three(landmark_rows=2, row_limit=6) == [[0, 1, 2]]


def test_a_batch_carries_at_most_row_limit_fish_even_when_they_see_nothing() -> None:
    assert _school_of_three(landmark_rows=0, row_limit=2) == [[0, 1], [2]]
    assert _school_of_three(landmark_rows=0, row_limit=1) == [[0], [1], [2]]


def test_a_ticks_batches_are_handed_as_they_are_to_readers_in_this_process() -> None:
    # School a (fish 0, 2, 4) takes its rows out of the stacked ones, a copy; schools b
    # (fish 5, 6) and c (fish 7, 8), consecutive, views of them, which their batches keep
    # without a copy of their own. Fish 1 and 3 have keys of their own.
    keys = KeySpace()
    ids = np.arange(9)
    messages = perception_messages(
        keys,
        ids=ids,
        schools=Schools.of(ids, {0: "a", 2: "a", 4: "a", 5: "b", 6: "b", 7: "c", 8: "c"}),
        depth=np.zeros(9),
        perceived=_perceived([[[float(i), 0.0, 0.0]] for i in range(9)], width=1),
        landmarks=_perceived([[] for _ in range(9)], width=1),
        inbox_counts=np.zeros(9, dtype=np.int64),
        tick=2,
        time=2.0,
    )
    assert len(messages) == 5  # fish 1 and 3 alone, then the batches of a, b and c
    b, c = (message for _, message in messages[3:])
    assert isinstance(b, PerceptionBatch) and isinstance(c, PerceptionBatch)
    assert _memory_of(b.neighbors) is _memory_of(c.neighbors)
    np.testing.assert_array_equal(c.neighbors, [[7.0, 0, 0], [8.0, 0, 0]])
    try:
        for _, message in messages:
            payload = bytes(bytearray(encode(message, reuse=True)))
            assert decode(payload, type(message)) is message
    finally:
        codec._reused.clear()


def _memory_of(array: np.ndarray) -> object:
    """The array or object whose memory ``array`` views, at the end of its bases."""
    while isinstance(array.base, np.ndarray):
        array = array.base
    return array


def test_rows_the_vision_stacked_already_are_sent_as_they_are() -> None:
    keys = KeySpace()
    ids = np.array([2, 5, 6])
    plain = _perceived([[[1.0, 0, 0], [2.0, 0, 0]], [], [[0, 3.0, 0]]], width=2)
    rows = stack_rows(plain.neighbors, plain.mask)
    rows.setflags(write=False)
    counts = np.array([2, 0, 1])
    stacked = Perceived(plain.neighbors, plain.mask, plain.index, Stacked(counts, rows))
    messages = [
        perception_messages(
            keys,
            ids=ids,
            schools=Schools.of(ids, dict.fromkeys(ids.tolist(), "s")),
            depth=np.zeros(3),
            perceived=perceived,
            landmarks=_perceived([[], [], []], width=0),
            inbox_counts=np.zeros(3, dtype=np.int64),
            tick=1,
            time=1.0,
        )
        for perceived in (plain, stacked)
    ]
    assert [encode(message) for _, message in messages[0]] == [
        encode(message) for _, message in messages[1]
    ]
    batch = messages[1][0][1]
    assert isinstance(batch, PerceptionBatch)
    assert np.shares_memory(batch.neighbors, rows)  # not stacked again
    assert stacked.counts is counts
