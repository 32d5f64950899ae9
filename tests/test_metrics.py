"""The three mean distances on arrangements worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.metrics import (
    centroid_distance,
    nearest_neighbor_distance,
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
