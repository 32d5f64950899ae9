"""Orbit, milling and waltz: geometry of the heading rule, and the behaviour in the batch
engine (the actor system gives the same trajectories, tests/actors/test_sweep.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.behaviors.core import Inbox, NoMemory, Perception
from fishswarm.behaviors.orbit import OrbitParams, milling, orbit, steer_orbit, waltz
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario


def _heading_deg(target: np.ndarray) -> np.ndarray:
    heading: np.ndarray = np.degrees(np.arctan2(target[:, 1], target[:, 0]))
    return heading


def test_heading_rule_by_zone() -> None:
    radius = 0.5
    centre = np.array(
        [
            [0.0, -0.5, 0.1],  # on the circle, centre on the left: straight on
            [1.0, 0.0, 0.0],  # outside, centre dead ahead at 1 m: tangent point at 30° right
            [-1.0, 0.0, 0.0],  # outside, centre behind: the tangent point the short way
            [0.0, -0.25, 0.0],  # inside, halfway, centre on the left: veer out 45° right
            [0.3, 0.0, 0.0],  # not seen
        ]
    )
    seen = np.array([True, True, True, True, False])
    target = orbit(centre, seen, radius=radius)
    heading = _heading_deg(target)
    assert heading[0] == pytest.approx(0.0, abs=1e-9)
    assert heading[1] == pytest.approx(30.0)
    assert heading[2] == pytest.approx(-150.0)  # 180° + 30° wrapped
    assert heading[3] == pytest.approx(45.0)
    assert heading[4] == 0.0 and target[4, 2] == 0.0
    np.testing.assert_allclose(np.hypot(target[:, 0], target[:, 1]), radius)
    assert target[0, 2] == pytest.approx(0.1)  # holds the centre's depth


def test_just_outside_the_circle_the_fish_heads_for_the_tangent_point() -> None:
    # The centre dead ahead at 1.02 R: the tangent point lies asin(1/1.02) = 78.6° right,
    # where veering out as from inside would give 90° − 90°·0.02 = 88.2°.
    target = orbit(np.array([[0.51, 0.0, 0.0]]), np.array([True]), radius=0.5)
    assert _heading_deg(target)[0] == pytest.approx(math.degrees(math.asin(0.5 / 0.51)))
    assert _heading_deg(target)[0] == pytest.approx(78.636, abs=1e-3)


def test_an_orbit_radius_of_zero_or_less_is_refused() -> None:
    for radius in (0.0, -0.5):
        with pytest.raises(ValueError, match="radius must be positive"):
            orbit(np.array([[1.0, 0.0, 0.0]]), np.array([True]), radius=radius)


def test_the_first_landmark_seen_is_the_centre() -> None:
    # Two landmarks: the post (first) 1 m ahead, another 1 m to the left.
    perception = Perception(
        time=np.zeros(1),
        depth=np.zeros(1),
        neighbors=np.zeros((1, 0, 3)),
        neighbor_mask=np.zeros((1, 0), bool),
        landmarks=np.array([[[1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]]),
        landmark_mask=np.array([[True, True]]),
    )
    _, steering = steer_orbit(
        NoMemory(), perception, Inbox.empty(1), params=OrbitParams(radius=0.5)
    )
    assert _heading_deg(steering.target)[0] == pytest.approx(30.0)  # as the zone test's


def test_waltz_orbits_the_nearest_neighbour() -> None:
    neighbors = np.array([[[2.0, 0.0, 0.0], [0.0, -0.5, 0.0]]])
    mask = np.array([[True, True]])
    target = waltz(neighbors, mask, radius=0.5)
    assert _heading_deg(target)[0] == pytest.approx(0.0, abs=1e-9)
    alone = waltz(np.zeros((1, 0, 3)), np.zeros((1, 0), bool), radius=0.5)
    assert _heading_deg(alone)[0] == 0.0


def test_milling_pushes_off_a_close_neighbour() -> None:
    centre = np.array([[0.0, -0.5, 0.0]])
    seen = np.array([True])
    right_behind = np.array([[[0.0, 0.1, 0.0]]])  # 0.1 m to the right: closer than 0.26 m
    target = milling(centre, seen, right_behind, np.array([[True]]), radius=0.5)
    assert target[0, 1] < 0  # pushed left, away from the neighbour
    far = np.array([[[0.0, 1.0, 0.0]]])
    unchanged = milling(centre, seen, far, np.array([[True]]), radius=0.5)
    np.testing.assert_array_equal(unchanged, orbit(centre, seen, radius=0.5))
    # Just beyond the spacing (0.3 against 0.26 m): ignored, not pulled towards.
    beyond = np.array([[[0.0, 0.3, 0.0]]])
    unchanged = milling(centre, seen, beyond, np.array([[True]]), radius=0.5)
    np.testing.assert_array_equal(unchanged, orbit(centre, seen, radius=0.5))


def test_one_fish_settles_on_a_circle_near_r() -> None:
    scenario = Scenario(fish=1, behavior="orbit", duration=120, spawn_radius=0.6, seed=2)
    trajectory = simulate_batch(scenario)
    centre = scenario.landmarks()[0]
    radius = np.hypot(*(trajectory.position[60:, 0, :2] - centre[:2]).T)
    assert abs(radius.mean() - 0.45) < 0.03
    assert radius.max() - radius.min() < 0.15
    angle = np.unwrap(np.arctan2(*(trajectory.position[:, 0, 1::-1] - centre[1::-1]).T))
    assert abs(angle[-1] - angle[0]) / (2 * math.pi) > 1.5  # it goes round


def test_two_waltzing_fish_stay_together_and_their_barycentre_barely_moves() -> None:
    scenario = Scenario(fish=2, behavior="waltz", duration=120, spawn_radius=0.3, seed=1)
    position = simulate_batch(scenario).position[30:]
    separation = np.linalg.norm(position[:, 0] - position[:, 1], axis=1)
    assert separation.min() > 0.3 and separation.max() < 0.7  # R = 0.45
    barycentre = position.mean(axis=1)
    drift = np.linalg.norm(barycentre - barycentre[0], axis=1).max()
    path = np.linalg.norm(np.diff(position[:, 0], axis=0), axis=1).sum()
    assert path > 2.0  # each fish swims metres …
    assert drift < 0.1 * path  # … while their barycentre moves a few centimetres


def test_milling_fish_stay_around_the_centre_with_few_collisions() -> None:
    scenario = Scenario(
        fish=25, behavior="milling", duration=90, spawn_radius=0.6, seed=3, orbit_radius=0.6
    )
    position = simulate_batch(scenario).position
    centre = scenario.landmarks()[0]
    radius = np.hypot(position[45:, :, 0] - centre[0], position[45:, :, 1] - centre[1])
    assert abs(radius.mean() - 0.6) < 0.1
    assert (radius < 1.0).all()
    # Contacts: pairs closer than 5 cm (robots ~5 cm wide touch), per tick, out of 300 pairs.
    gaps = np.linalg.norm(position[45:, :, None] - position[45:, None], axis=-1)
    contacts = (np.triu(gaps < 0.05, k=1)).sum(axis=(1, 2))
    assert contacts.mean() < 1.0


def test_a_fish_that_does_not_see_its_centre_swims_straight_on_at_its_depth() -> None:
    # Whatever a padded centre row holds, unseen is straight ahead, level: (R, 0, 0).
    centre = np.array([[0.3, -0.2, 0.4]])
    target = orbit(centre, np.array([False]), radius=0.5)
    np.testing.assert_array_equal(target, [[0.5, 0.0, 0.0]])


def test_a_push_off_a_neighbour_longer_than_r_is_cut_to_r() -> None:
    """The push off the close neighbour, found by bisection on its distance, is 1.05 R
    long: milling adds it cut to exactly R (a little cut, not just a large one)."""
    from fishswarm.behaviors.lennard_jones import lennard_jones
    from fishswarm.behaviors.orbit import MILLING_SPACING

    radius = 0.2
    centre, seen, mask = np.array([[0.0, -0.5, 0.0]]), np.array([True]), np.array([[True]])

    def push(gap: float) -> np.ndarray:
        neighbour = np.array([[[0.0, gap, 0.0]]])
        motion: np.ndarray = lennard_jones(neighbour, mask, target_distance=MILLING_SPACING)[0]
        return motion

    near, far = 1e-3, MILLING_SPACING  # the push shrinks as the neighbour moves off
    for _ in range(200):
        middle = (near + far) / 2
        near, far = (
            (middle, far) if np.linalg.norm(push(middle)) > 1.05 * radius else (near, middle)
        )
    pushed = push(near)
    assert np.linalg.norm(pushed) == pytest.approx(1.05 * radius, rel=1e-6)
    target = milling(centre, seen, np.array([[[0.0, near, 0.0]]]), mask, radius=radius)
    added = target - orbit(centre, seen, radius=radius)
    np.testing.assert_allclose(np.linalg.norm(added), radius, rtol=1e-12)
    np.testing.assert_allclose(added[0], pushed * radius / np.linalg.norm(pushed), rtol=1e-12)
