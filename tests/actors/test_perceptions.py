"""Cutting a tick's vision into messages: per-fish perceptions and school batches."""

from __future__ import annotations

import numpy as np

from fishswarm.actors.perceptions import perception_messages
from fishswarm.bluebot.vision import Perceived
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
        school_of={1: "s", 4: None, 7: "s"},
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
        school_of={1: "s", 4: None, 7: "s"},
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
