"""A whole decision, batched: batch equals a loop of single fish, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.behaviors.policy import Memory, Policy, act


@pytest.mark.parametrize("controller", ["homing", "pid"])
@pytest.mark.parametrize("behavior", [("aggregation", 0.26), ("dispersion", 2.517)])
def test_batch_equals_loop_of_single_fish(controller: str, behavior: tuple[str, float]) -> None:
    rng = np.random.default_rng(8)
    count, width = 9, 6
    neighbors = rng.normal(0, 0.5, (count, width, 3))
    seen = rng.integers(0, width + 1, count)
    mask = np.arange(width)[None, :] < seen[:, None]
    neighbors[~mask] = 0.0
    policy = Policy(behavior[0], behavior[1], controller=controller)
    memory = Memory.fresh(count)
    for _ in range(3):
        fins, next_memory = act(policy, neighbors, mask, memory)
        for i in range(count):
            own = neighbors[i : i + 1, : seen[i]]
            single, _ = act(policy, own, np.ones((1, seen[i]), bool), memory.take(np.array([i])))
            np.testing.assert_array_equal(single[0], fins[i])
        memory = next_memory
        neighbors = neighbors + rng.normal(0, 0.05, neighbors.shape) * mask[..., None]
