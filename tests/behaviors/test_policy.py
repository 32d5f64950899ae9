"""A whole decision, batched: batch equals a loop of single fish, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.behaviors.policy import Memory, Policy, act, pad_neighbors
from fishswarm.behaviors.replica import STUDY_SCALE, replica_motion

REPLICA = tuple(np.random.default_rng(0).normal(0, 1, 21).tolist())


@pytest.mark.parametrize("controller", ["homing", "pid"])
@pytest.mark.parametrize(
    "behavior", [("aggregation", 0.26), ("dispersion", 2.517), ("replica", 0.26)]
)
def test_batch_equals_loop_of_single_fish(controller: str, behavior: tuple[str, float]) -> None:
    rng = np.random.default_rng(8)
    count, width = 9, 6
    neighbors = rng.normal(0, 0.5, (count, width, 3))
    seen = rng.integers(0, width + 1, count)
    mask = np.arange(width)[None, :] < seen[:, None]
    neighbors[~mask] = 0.0
    depth = rng.uniform(0.2, 1.0, count)
    weights = REPLICA if behavior[0] == "replica" else None
    policy = Policy(behavior[0], behavior[1], controller=controller, replica_weights=weights)
    memory = Memory.fresh(count)
    for _ in range(3):
        fins, next_memory = act(policy, neighbors, mask, depth, memory)
        for i in range(count):
            own = neighbors[i : i + 1, : seen[i]]
            single, _ = act(
                policy,
                own,
                np.ones((1, seen[i]), bool),
                depth[i : i + 1],
                memory.take(np.array([i])),
            )
            np.testing.assert_array_equal(single[0], fins[i])
        memory = next_memory
        neighbors = neighbors + rng.normal(0, 0.05, neighbors.shape) * mask[..., None]
        depth = depth + 0.01


def test_replica_motion_by_hand() -> None:
    # Hidden weights 0 → hidden 0.5; output biases +50, 0, +50 → outputs (1, 0.5, 1):
    # direction (+1, 0), speed 9 per neighbour; two neighbours sum to 18, capped at 9 units/s:
    # 9 × 1 s × 1.78/300 m = 0.0534 m straight ahead.
    weights = np.zeros(21)
    weights[18:21] = [50.0, 0.0, 50.0]
    neighbors = np.array([[[0.3, 0.1, 0.0], [-0.2, 0.2, 0.1], [9.0, 9.0, 0.0]]])
    mask = np.array([[True, True, False]])
    motion = replica_motion(neighbors, mask, weights=weights)
    np.testing.assert_allclose(motion, [[9 * STUDY_SCALE, 0.0]], atol=1e-15)
    # A neighbour beyond the communication range (100 units = 0.593 m) counts for nothing.
    far = replica_motion(np.array([[[0.7, 0.0, 0.0]]]), np.ones((1, 1), bool), weights=weights)
    np.testing.assert_array_equal(far, [[0.0, 0.0]])


def test_replica_holds_its_first_depth() -> None:
    weights = np.zeros(21)
    policy = Policy("replica", 0.26, replica_weights=tuple(weights.tolist()))
    no_neighbors = np.zeros((1, 0, 3))
    _, memory = act(policy, no_neighbors, np.zeros((1, 0), bool), np.array([0.5]), Memory.fresh(1))
    assert memory.hold_depth.tolist() == [0.5]
    # Now 5 cm shallower: the target points down (z > 0), so the dorsal fin comes on.
    fins, memory = act(policy, no_neighbors, np.zeros((1, 0), bool), np.array([0.45]), memory)
    assert fins[0, 1] == 1.0
    assert memory.hold_depth.tolist() == [0.5]


def test_replica_needs_its_weights() -> None:
    with pytest.raises(ValueError, match="21 weights"):
        Policy("replica", 0.26)


def test_pad_neighbors_unstacks_fish_after_fish() -> None:
    stacked = np.arange(9.0).reshape(3, 3)
    neighbors, mask = pad_neighbors(np.array([2, 0, 1]), stacked)
    assert neighbors.shape == (3, 2, 3)
    assert mask.tolist() == [[True, True], [False, False], [True, False]]
    np.testing.assert_array_equal(neighbors[0], stacked[:2])
    np.testing.assert_array_equal(neighbors[1], np.zeros((2, 3)))
    np.testing.assert_array_equal(neighbors[2], [stacked[2], [0.0, 0.0, 0.0]])
    empty, empty_mask = pad_neighbors(np.zeros(0, dtype=np.int64), np.zeros((0, 3)))
    assert empty.shape == (0, 0, 3) and empty_mask.shape == (0, 0)
