"""The three mean distances on arrangements worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.metrics import (
    centroid_distance,
    nearest_neighbor_distance,
    orbit_metrics,
    pairwise_distance,
    swarm_metrics,
)

# A unit square: 4 pairs at 1 m and 2 at √2 m; every nearest neighbour at 1 m.
SQUARE = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])


def test_pairwise_and_nearest_on_a_square() -> None:
    assert pairwise_distance(SQUARE) == pytest.approx((4 + 2 * math.sqrt(2)) / 6)
    assert nearest_neighbor_distance(SQUARE) == pytest.approx(1.0)


def test_centroid_of_the_others_on_a_square() -> None:
    # For (0,0): others' centroid is (2/3, 2/3), at distance (2/3)·√2; same for every corner.
    assert centroid_distance(SQUARE) == pytest.approx(2 / 3 * math.sqrt(2))


def test_single_fish_and_neighbors_seen() -> None:
    values = swarm_metrics(SQUARE[:1], np.array([0]))
    assert values == {
        "centroid_distance": 0.0,
        "pairwise_distance": 0.0,
        "nearest_neighbor_distance": 0.0,
        "neighbors_seen": 0.0,
    }
    assert swarm_metrics(SQUARE, np.array([3, 2, 1, 2]))["neighbors_seen"] == 2.0


def test_orbit_metrics_of_a_fish_on_a_circle_by_hand() -> None:
    # Eight ticks of 1 s, one eighth of a turn each, clockwise in an overhead plot (the angle
    # atan2(y, x) decreases), radius 0.5 m around (1, 1).
    angle = -np.arange(9) * np.pi / 4
    track = np.stack([1 + 0.5 * np.cos(angle), 1 + 0.5 * np.sin(angle), np.full(9, 0.5)], -1)
    metrics = orbit_metrics(
        track[:, None], centre=np.array([1.0, 1.0, 0.5]), period=1.0, contact=0.13
    )
    np.testing.assert_allclose(metrics[:, 0], 0.5)
    np.testing.assert_allclose(metrics[:, 1], np.arange(9) / 8)
    # Chord of an eighth of a circle: 2 · 0.5 · sin(π/8).
    np.testing.assert_allclose(metrics[1:, 2], 2 * 0.5 * math.sin(math.pi / 8))
    assert metrics[0, 2] == 0.0
    assert metrics[:, 3].tolist() == [0.0] * 9


def test_orbit_metrics_of_a_pair_use_the_barycentre_and_count_contacts() -> None:
    # Two fish 0.1 m apart (closer than a body length), then 0.4 m.
    position = np.array([[[1.0, 1.0, 0.5], [1.1, 1.0, 0.5]], [[1.0, 1.0, 0.5], [1.4, 1.0, 0.5]]])
    metrics = orbit_metrics(position, centre=None, period=1.0, contact=0.13)
    np.testing.assert_allclose(metrics[:, 0], [0.05, 0.2])
    assert metrics[:, 3].tolist() == [1.0, 0.0]
