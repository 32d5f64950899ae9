"""The simulated broadcast medium: who hears a broadcast, from where, and which deliveries
a lossy channel drops."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.behaviors.core import Outbox
from fishswarm.behaviors.formation import FORMATION_KIND, NO_HOPS
from fishswarm.bluebot.vision import Vision
from fishswarm.protocols.messages import BROADCAST_KINDS, FORMATION_SHAPES, FormationFlag
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.medium import deliver, one_bit, receptions, seeing
from fishswarm.sim.scenario import Scenario

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


# Three fish in a row along +x, 1 m apart, all facing +x: each sees the one ahead of it
# (the one beyond is hidden behind it); the ones behind are in its blind spot.
ROW = np.array([[0.0, 1.0, 0.5], [1.0, 1.0, 0.5], [2.0, 1.0, 0.5]])
AHEAD = np.zeros(3)


def test_each_fish_sees_the_one_ahead_and_neither_the_hidden_nor_those_behind() -> None:
    seen = seeing(ROW, AHEAD, vision=Vision(noise=0.3))
    assert seen.tolist() == [
        [False, True, False],  # fish 2 hidden behind fish 1
        [False, False, True],  # fish 0 in the blind spot behind
        [False, False, False],
    ]


def joined_flag(joined: bool, slot: int = 4) -> np.ndarray:
    return FormationFlag(
        FORMATION_SHAPES.index("pyramid"), slot, joined, 2, 90_000, 7, 55, 1
    ).values()


def test_light_carries_only_a_joined_formation_flag_and_only_that_it_is_joined() -> None:
    said = one_bit(FORMATION_KIND, joined_flag(True))
    assert said is not None
    flag = FormationFlag.from_values(said)
    # The shape and orientation (which all fish of a school share), joined; no slot, hops,
    # sequence, effort or swap.
    assert flag == FormationFlag(FORMATION_SHAPES.index("pyramid"), -1, True, NO_HOPS, 90_000, 0)
    assert one_bit(FORMATION_KIND, joined_flag(False)) is None
    assert one_bit(BROADCAST_KINDS.index("signal"), joined_flag(True)) is None


def test_flags_by_light_reach_only_the_fish_that_see_their_sender_and_by_beacon_all() -> None:
    """Fish 0 and 2 hold their places, fish 1 seeks one: by light, fish 1 alone sees a
    joined flagger (fish 2, 1 m ahead of it); fish 0's flag reaches no one (fish 1 has it
    behind, fish 2 too), and fish 1's is not sent at all."""
    values = np.stack([joined_flag(True), joined_flag(False), joined_flag(True)])
    outbox = Outbox(np.full(3, FORMATION_KIND), values, np.ones(3, dtype=bool))
    rngs = [np.random.default_rng(n) for n in range(3)]
    inbox = deliver(
        ROW, AHEAD, outbox, channel_range=3.0, loss=0.0, rngs=rngs, sight=Vision(),
        one_bit_flags=True,
    )  # fmt: skip
    assert inbox.mask.sum(axis=1).tolist() == [0, 1, 0]
    np.testing.assert_array_equal(inbox.values[1, 0], one_bit(FORMATION_KIND, values[2]))
    np.testing.assert_allclose(inbox.sender[1, 0], [1.0, 0.0, 0.0], atol=1e-12)
    # By the channel, every flag reaches both others; by beacon, the two joined fish's
    # flags, reduced as by light, reach both others whether they see them or not.
    by_channel = deliver(ROW, AHEAD, outbox, channel_range=3.0, loss=0.0, rngs=rngs)
    assert by_channel.mask.sum(axis=1).tolist() == [2, 2, 2]
    by_beacon = deliver(
        ROW, AHEAD, outbox, channel_range=3.0, loss=0.0, rngs=rngs, one_bit_flags=True
    )
    assert by_beacon.mask.sum(axis=1).tolist() == [1, 2, 1]
    np.testing.assert_array_equal(by_beacon.values[0, 0], one_bit(FORMATION_KIND, values[2]))


@pytest.mark.parametrize("shape", ["pyramid", "column", "trigonal-planar"])
def test_flags_by_light_tell_a_formation_fish_nothing_its_eyes_do_not(shape: str) -> None:
    """By light a flag reaches only fish that see its sender, and says only that it holds
    its place, where it is seen: with the geometric vision model (noiseless, as in the
    experiments) a formation fish takes nothing from it that sight does not give. The run
    is the one in which flags are sent and none arrives (docs/robot.md); a beacon's same
    one bit, reaching fish that do not see its sender, changes it."""
    base = Scenario(
        fish=7, behavior="formation", formation=shape, duration=6.0, seed=5, controller="pid",
        spawn_radius=0.3, spacing=0.25,
    )  # fmt: skip
    light = simulate_batch(base.replace(flag_medium="light")).position
    none_arrive = simulate_batch(base.replace(channel_range=1e-9)).position
    beacon = simulate_batch(base.replace(flag_medium="beacon")).position
    np.testing.assert_array_equal(light, none_arrive)
    assert not np.array_equal(beacon, none_arrive)


@pytest.mark.parametrize("changes", [{"vision_model": "camera"}, {"vision_noise": 0.06}])
def test_with_eyes_that_miss_flags_by_light_tell_what_they_miss(changes: dict[str, object]) -> None:
    """The limit of the above: a flag by light shows its sender where it is, and reaches
    the fish the geometric model says see it; a fish that sees through its cameras' images,
    or with noise over half the tolerance, misses or misplaces some of them, and the flags
    then change its run."""
    base = Scenario(
        fish=7, behavior="formation", formation="column", duration=6.0, seed=5,
        controller="pid", spawn_radius=0.3, spacing=0.25,
    ).replace(**changes)  # fmt: skip
    light = simulate_batch(base.replace(flag_medium="light")).position
    none_arrive = simulate_batch(base.replace(channel_range=1e-9)).position
    assert not np.array_equal(light, none_arrive)
