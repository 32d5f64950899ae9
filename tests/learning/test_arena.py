"""The 2-D arena: the ideal fish by hand, their settling, batch equals loop."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from fishswarm.learning.arena import (
    SPREADS,
    Arena,
    arena_from,
    cap_speed,
    ideal_velocity,
    initial_positions,
    replica_contributions,
    replica_velocity,
    simulate,
    spacing_and_speed,
)

ARENA = Arena()


def test_ideal_pair_by_hand() -> None:
    # 50 apart: gap +10 → k·10² = 0.3 towards each other; 30 apart: 0.3 apart; 120: no one.
    for distance, expected in ((50.0, 0.3), (30.0, -0.3), (120.0, 0.0)):
        positions = np.array([[[100.0, 100.0], [100.0 + distance, 100.0]]])
        velocity = ideal_velocity(positions, arena=ARENA)
        np.testing.assert_allclose(velocity[0, 0], [expected, 0.0], atol=1e-12)
        np.testing.assert_allclose(velocity[0, 1], [-expected, 0.0], atol=1e-12)


def test_speed_is_capped() -> None:
    capped = cap_speed(np.array([[30.0, 40.0], [1.0, 0.0]]), cap=9.0)
    np.testing.assert_allclose(capped, [[5.4, 7.2], [1.0, 0.0]])


@pytest.mark.parametrize("behavior", ["dispersion", "aggregation"])
def test_ideal_fish_settle_near_sigma_and_come_to_rest(behavior: str) -> None:
    arena = dataclasses.replace(ARENA, steps=40)
    start = initial_positions(
        np.random.default_rng(4), arena=arena, spread=SPREADS[behavior], models=1
    )
    tracks = simulate(lambda p: ideal_velocity(p, arena=arena), start, arena=arena)
    spacing, speed = spacing_and_speed(tracks, arena=arena)
    if behavior == "dispersion":
        assert spacing[0, 0] < 15
    else:
        assert spacing[0, 0] > 45
    assert 0.8 * arena.spacing < spacing[0, -1] < arena.spacing
    assert speed[0, -1] < 0.1


def test_spacing_is_averaged_over_the_fish_that_have_schoolmates_in_range() -> None:
    # Fish 0 and 1 are 10 apart; fish 2 is 190 from the nearer of them, beyond the range of
    # 100: it has no spacing and does not count, so the school's is 10 (not 20/3). A fish
    # moves 5 in the second step: mean speed 5/3.
    still = np.array([[0.0, 0.0], [10.0, 0.0], [200.0, 0.0]])
    moved = still + np.array([[0.0, 0.0], [0.0, 0.0], [3.0, 4.0]])
    tracks = np.stack([still, still, moved])[None]
    spacing, speed = spacing_and_speed(tracks, arena=ARENA)
    np.testing.assert_allclose(spacing, [[10.0, 10.0, 10.0]])
    np.testing.assert_allclose(speed, [[0.0, 5 / 3]])
    # Nobody in range of anybody: no spacing at all.
    alone = np.array([[0.0, 0.0], [150.0, 0.0], [300.0, 0.0]])
    spacing, _ = spacing_and_speed(np.stack([alone, alone])[None], arena=ARENA)
    assert np.isnan(spacing).all()


def test_models_in_a_batch_run_as_if_alone() -> None:
    rng = np.random.default_rng(1)
    weights = rng.normal(0, 1, (4, 21))
    start = initial_positions(rng, arena=ARENA, spread=100.0, models=4)
    together = simulate(lambda p: replica_velocity(p, weights, arena=ARENA), start, arena=ARENA)
    for model in range(4):
        own = weights[model : model + 1]

        def velocity(positions: np.ndarray, own: np.ndarray = own) -> np.ndarray:
            return replica_velocity(positions, own, arena=ARENA)

        alone = simulate(velocity, start[model : model + 1], arena=ARENA)
        np.testing.assert_allclose(alone[0], together[model], rtol=0, atol=1e-9)
    assert np.all((together >= 0) & (together <= ARENA.side))


def test_a_replica_sees_positions_over_the_input_scale() -> None:
    # The same network, a neighbour 40 units away seen over 40 and one 100 away over 100:
    # both are input (1, 0), so both fish move alike.
    weights = np.random.default_rng(2).normal(0, 2, (1, 21))
    near = np.array([[[100.0, 100.0], [140.0, 100.0]]])
    far = np.array([[[100.0, 100.0], [200.0, 100.0]]])
    seen_over_40 = replica_velocity(near, weights, arena=ARENA)
    seen_over_100 = replica_velocity(
        far, weights, arena=dataclasses.replace(ARENA, replica_input_scale=100.0)
    )
    np.testing.assert_allclose(seen_over_40, seen_over_100, rtol=0, atol=1e-12)
    assert np.abs(seen_over_40).max() > 0.1


def test_files_from_before_the_input_scale_keep_the_old_one() -> None:
    saved = dataclasses.asdict(ARENA)
    assert arena_from(saved) == ARENA and ARENA.replica_input_scale == 40.0
    del saved["replica_input_scale"]
    assert arena_from(saved).replica_input_scale == 100.0


def test_files_from_before_the_replica_kind_keep_the_replica_they_were_learned_with() -> None:
    saved = dataclasses.asdict(dataclasses.replace(ARENA, replica="isotropic"))
    assert arena_from(saved).replica == "isotropic"
    del saved["replica"]
    assert arena_from(saved).replica == "study"  # before reciprocal replicas
    # Between 2026-11-25 and the isotropic replica, files said replica_reciprocal.
    assert arena_from({**saved, "replica_reciprocal": True}).replica == "reciprocal"
    assert arena_from({**saved, "replica_reciprocal": False}).replica == "study"
    with pytest.raises(ValueError, match="replica must be one of study, reciprocal, isotropic"):
        Arena(replica="mirror")


@given(
    seed=st.integers(0, 2**32 - 1),
    x=st.floats(-150, 150),
    y=st.floats(-150, 150),
)
def test_a_reciprocal_replica_pushes_the_other_way_for_a_neighbour_on_the_other_side(
    seed: int, x: float, y: float
) -> None:
    weights = np.random.default_rng(seed).normal(0, 3, (1, 21))
    relative = np.array([[[x, y], [-x, -y]]])
    within = np.ones((1, 2), dtype=np.bool_)
    reciprocal = dataclasses.replace(ARENA, replica="reciprocal")
    push = replica_contributions(weights, relative, within, arena=reciprocal)
    np.testing.assert_array_equal(push[0, 0], -push[0, 1])
    # The study's replica is half of it: its own push minus the mirrored one, halved.
    plain = replica_contributions(weights, relative, within, arena=ARENA)
    np.testing.assert_allclose(push[0, 0], (plain[0, 0] - plain[0, 1]) / 2, rtol=0, atol=1e-12)


def test_a_reciprocal_replica_in_a_ring_of_neighbours_stays_where_it_is() -> None:
    # A fish at the centre of six neighbours at 60° steps: whatever its network, the pushes
    # of opposite neighbours cancel. The study's replica with output biases drifts.
    angles = np.arange(6) * np.pi / 3
    ring = 150.0 + 25.0 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    positions = np.concatenate([[[150.0, 150.0]], ring])[None]
    weights = np.random.default_rng(5).normal(0, 3, (1, 21))
    weights[0, 18:21] += 4.0
    reciprocal = dataclasses.replace(ARENA, replica="reciprocal")
    centre = replica_velocity(positions, weights, arena=reciprocal)[0, 0]
    np.testing.assert_allclose(centre, [0.0, 0.0], atol=1e-12)
    assert np.linalg.norm(replica_velocity(positions, weights, arena=ARENA)[0, 0]) > 1.0


ISOTROPIC = dataclasses.replace(ARENA, replica="isotropic")


def test_an_isotropic_replica_turns_its_answer_to_each_neighbours_bearing() -> None:
    # Drawn on paper: the network answers (along, across) for a neighbour straight ahead
    # at 20 units; a neighbour at 20 units on +y gets that answer turned a quarter turn
    # anticlockwise, (−across, along), and one at the fish's own place none.
    weights = np.random.default_rng(11).normal(0, 2, (1, 21))
    ahead = replica_contributions(
        weights, np.array([[[20.0, 0.0]]]), np.ones((1, 1), np.bool_), arena=ISOTROPIC
    )[0, 0]
    study = replica_contributions(
        weights, np.array([[[20.0, 0.0]]]), np.ones((1, 1), np.bool_), arena=ARENA
    )[0, 0]
    np.testing.assert_allclose(ahead, study, rtol=0, atol=1e-12)  # on the x axis, as the study's
    relative = np.array([[[0.0, 20.0], [0.0, 0.0]]])
    push = replica_contributions(weights, relative, np.ones((1, 2), np.bool_), arena=ISOTROPIC)
    np.testing.assert_allclose(push[0, 0], [-ahead[1], ahead[0]], rtol=0, atol=1e-12)
    np.testing.assert_array_equal(push[0, 1], [0.0, 0.0])


@given(
    seed=st.integers(0, 2**32 - 1),
    x=st.floats(-150, 150),
    y=st.floats(-150, 150),
    angle=st.floats(-np.pi, np.pi),
)
def test_an_isotropic_replica_obeys_the_same_law_in_every_direction(
    seed: int, x: float, y: float, angle: float
) -> None:
    # Relative positions in the arena are differences of coordinates in [0, 300]: zero, or
    # at least the spacing of floats there (6e-14). Far below that (1e-160, say) the squared
    # distance is subnormal, its last digits gone, and no bearing can be told to 1e-9.
    assume(x == y == 0.0 or math.hypot(x, y) >= 1e-12)
    weights = np.random.default_rng(seed).normal(0, 3, (1, 21))
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    relative = np.array([[[x, y], turn @ [x, y], [-x, -y]]])
    push = replica_contributions(weights, relative, np.ones((1, 3), np.bool_), arena=ISOTROPIC)
    # A neighbour turned about the fish turns its push with it; one on the other side
    # pushes exactly the other way (no drift of the school as one).
    np.testing.assert_allclose(push[0, 1], turn @ push[0, 0], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(push[0, 2], -push[0, 0])


def test_an_isotropic_replica_in_a_ring_of_neighbours_stays_where_it_is() -> None:
    angles = np.arange(6) * np.pi / 3
    ring = 150.0 + 25.0 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    positions = np.concatenate([[[150.0, 150.0]], ring])[None]
    weights = np.random.default_rng(5).normal(0, 3, (1, 21))
    weights[0, 18:21] += 4.0  # output biases: the study's replica drifts (test above)
    centre = replica_velocity(positions, weights, arena=ISOTROPIC)[0, 0]
    np.testing.assert_allclose(centre, [0.0, 0.0], atol=1e-12)
