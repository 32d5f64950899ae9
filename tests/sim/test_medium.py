"""The simulated broadcast medium: who hears a broadcast, from where, and which deliveries
a lossy channel drops."""

from __future__ import annotations

import numpy as np

from fishswarm.sim.medium import receptions

# Four fish on the x axis, at 0, 0.95, 1.0 and 1.5 m; all facing +x except fish 2, which
# faces +y (yaw 90°).
POSITION = np.array([[0.0, 0, 0], [0.95, 0, 0], [1.0, 0, 0], [1.5, 0, 0]])
YAW = np.array([0.0, 0.0, np.pi / 2, 0.0])


def test_a_broadcast_reaches_every_other_fish_within_range_and_no_farther() -> None:
    rngs = [np.random.default_rng(n) for n in range(4)]
    found = receptions(POSITION, YAW, [0], channel_range=1.0, loss=0.0, rngs=rngs)
    # Fish 1 at 0.95 m and fish 2 at exactly 1.0 m hear it; fish 3 at 1.5 m does not, and
    # the sender does not hear itself.
    assert [(r.receiver, r.sender, r.broadcast) for r in found] == [(1, 0, 0), (2, 0, 0)]
    # Where the sender is, in each receiver's body frame (x ahead, y right, z down): 0.95 m
    # behind fish 1; 1 m to the right of fish 2, which faces +y (with z down, a fish facing
    # +y has -x on its right).
    np.testing.assert_allclose(found[0].sender_position, [-0.95, 0, 0], atol=1e-12)
    np.testing.assert_allclose(found[1].sender_position, [0, 1.0, 0], atol=1e-12)


def test_each_receiver_draws_its_losses_from_its_own_generator() -> None:
    # Receiver 2's deliveries depend on its own generator alone: the others' generators,
    # however seeded, change nothing about what it hears.
    def heard_by(receiver: int, seeds: list[int]) -> list[int]:
        rngs = [np.random.default_rng(seed) for seed in seeds]
        found = receptions(
            POSITION, YAW, [0, 1, 3, 0, 1, 3, 0, 1], channel_range=2.0, loss=0.5, rngs=rngs
        )
        return [r.broadcast for r in found if r.receiver == receiver]

    base = heard_by(2, [0, 1, 2, 3])
    assert 0 < len(base) < 8  # some lost, some heard
    assert heard_by(2, [9, 8, 2, 7]) == base
    assert heard_by(2, [0, 1, 5, 3]) != base
