"""The compiled distances of the swarm metrics against scipy and numpy, and drawn on paper."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist

from fishswarm.sim import kernels
from fishswarm.study import distance_kernels
from fishswarm.study.metrics import (
    _sampled_pairs,
    nearest_neighbor_distance,
    pairwise_distance,
    swarm_metrics,
)

pytest.importorskip("numba")


def _kd_nearest(position: np.ndarray) -> np.ndarray:
    distance: np.ndarray = cKDTree(position).query(position, k=2)[0]
    return distance[:, 1]


def test_the_mean_over_all_pairs_equals_scipys() -> None:
    rng = np.random.default_rng(11)
    for count in (2, 3, 257):
        position = rng.uniform(0.0, 5.0, (count, 3))
        assert distance_kernels.mean_pairwise_distance(position) == pytest.approx(
            float(pdist(position).mean()), rel=1e-13
        )
    # A unit square: 4 pairs at 1 m and 2 at √2 m.
    square = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    assert distance_kernels.mean_pairwise_distance(square) == pytest.approx(
        (4 + 2 * np.sqrt(2)) / 6, rel=1e-15
    )
    assert distance_kernels.mean_pairwise_distance(square[:1]) == 0.0
    # The swarm metric takes the kernel from 200 fish on, with the same value.
    many = rng.uniform(0.0, 5.0, (400, 3))
    assert kernels.COMPILED_MIN_FISH <= 400
    assert pairwise_distance(many) == pytest.approx(float(pdist(many).mean()), rel=1e-13)


def test_listed_pairs_are_measured_as_numpy_measures_them() -> None:
    # A 3-4-5 triangle with a third fish 12 m above the second: 5 m and 13 m.
    position = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 4.0, 12.0]])
    first = np.array([0, 0, 1], dtype=np.intp)
    second = np.array([1, 2, 2], dtype=np.intp)
    np.testing.assert_array_equal(
        distance_kernels.pair_distances(position, first, second), [5.0, 13.0, 12.0]
    )
    rng = np.random.default_rng(5)
    school = rng.uniform(0.0, 80.0, (3000, 3))
    first, second = _sampled_pairs(3000)
    expected = np.sqrt(((school[first] - school[second]) ** 2).sum(axis=1))
    np.testing.assert_array_equal(distance_kernels.pair_distances(school, first, second), expected)


def test_a_pair_naming_a_fish_not_there_is_refused() -> None:
    position = np.zeros((3, 3))
    # The kernel checks each pair as it reads it: a bad pair after good ones too.
    for first, second in (([0], [3]), ([-1], [0]), ([0, 1, 2], [1, 2, 3])):
        with pytest.raises(IndexError, match="outside 0…2"):
            distance_kernels.pair_distances(
                position, np.array(first, dtype=np.intp), np.array(second, dtype=np.intp)
            )


def test_nearest_distances_drawn_on_paper() -> None:
    # Two pairs far apart: 0.5 m within the first (one fish above the other), 3 m within
    # the second, 10 m between them; and a fish 0.5 m from the first pair's lower fish.
    position = np.array(
        [[0.0, 0.0, 0.0], [0.0, 0.0, 0.5], [10.0, 0.0, 0.0], [13.0, 0.0, 0.0], [0.3, 0.4, 0.0]]
    )
    np.testing.assert_array_equal(
        distance_kernels.nearest_distances(position), [0.5, 0.5, 3.0, 3.0, 0.5]
    )
    with pytest.raises(ValueError, match="two fish"):
        distance_kernels.nearest_distances(position[:1])


@pytest.mark.parametrize(
    "layout",
    ["uniform", "coincident", "line", "thin-line", "vertical", "clusters", "one-far"],
)
def test_nearest_distances_equal_scipys_on_awkward_schools(layout: str) -> None:
    rng = np.random.default_rng(3)
    if layout == "uniform":
        position = np.c_[rng.uniform(0, 106, (10_000, 2)), rng.uniform(0, 1.5, 10_000)]
    elif layout == "coincident":
        position = np.zeros((5, 3))
    elif layout == "line":
        position = np.c_[np.linspace(0, 10, 50), np.zeros(50), np.zeros(50)]
    elif layout == "thin-line":
        position = np.c_[np.linspace(0, 10, 50), np.linspace(0, 1e-7, 50), np.zeros(50)]
    elif layout == "vertical":
        position = np.c_[np.zeros(40), np.zeros(40), np.linspace(0, 1, 40)]
    elif layout == "clusters":
        position = rng.uniform(0, 5, (300, 3))
        position[::3] = position[0]
    else:
        position = np.r_[rng.normal(0, 0.01, (500, 3)), [[100.0, 100.0, 0.0]]]
    np.testing.assert_array_equal(
        distance_kernels.nearest_distances(position), _kd_nearest(position)
    )


@settings(max_examples=60, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(2, 60), st.just(3)),
        elements=st.floats(-50.0, 50.0, allow_nan=False, width=32),
    )
)
def test_nearest_distances_equal_scipys(position: np.ndarray) -> None:
    np.testing.assert_array_equal(
        distance_kernels.nearest_distances(position), _kd_nearest(position)
    )


def test_the_nearest_neighbour_metric_is_the_same_compiled() -> None:
    rng = np.random.default_rng(9)
    school = np.c_[rng.uniform(0, 20, (500, 2)), rng.uniform(0, 1.2, 500)]
    assert kernels.COMPILED_MIN_FISH <= 500
    assert nearest_neighbor_distance(school) == float(_kd_nearest(school).mean())


def test_pairs_must_be_integer_lists_of_one_length() -> None:
    position = np.zeros((3, 3))
    two, one = np.array([0, 1], dtype=np.intp), np.array([2], dtype=np.intp)
    with pytest.raises(ValueError, match="one length"):
        distance_kernels.pair_distances(position, two, one)
    with pytest.raises(ValueError, match="integer"):
        distance_kernels.pair_distances(position, np.array([0.0, 1.0]), two)


def test_a_position_that_is_not_finite_is_refused() -> None:
    position = np.zeros((4, 3))
    position[2, 2] = np.nan
    with pytest.raises(ValueError, match="finite"):
        distance_kernels.nearest_distances(position)


def test_a_school_the_columns_cannot_split_goes_to_the_k_d_tree(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    asked: list[int] = []
    tree = cKDTree

    def spy(points: np.ndarray) -> object:
        asked.append(points.shape[0])
        return tree(points)

    monkeypatch.setattr(distance_kernels, "cKDTree", spy)
    rng = np.random.default_rng(4)
    spread = np.c_[rng.uniform(0, 30, (1000, 2)), rng.uniform(0, 1.2, 1000)]
    distance_kernels.nearest_distances(spread)
    assert asked == []
    # A school 1 m across and one straggler 100 m off: the columns (sized from the whole
    # footprint, 4.5 m) hold the school in a few, more than CROWDED_COLUMN each.
    straggling = np.r_[rng.normal(0.0, 0.3, (1000, 3)), [[100.0, 100.0, 0.5]]]
    np.testing.assert_array_equal(
        distance_kernels.nearest_distances(straggling), _kd_nearest(straggling)
    )
    assert asked == [1001]
    # Fish stacked over one another with a nanometre of sideways jitter: columns of about two
    # fish each, a nanometre wide, with the nearest fish a millimetre above: the search
    # spends its COLUMNS_PER_FISH and hands over.
    stacked = np.c_[rng.uniform(0, 1e-9, (1000, 2)), np.linspace(0.0, 1.0, 1000)]
    np.testing.assert_array_equal(distance_kernels.nearest_distances(stacked), _kd_nearest(stacked))
    assert asked == [1001, 1000]


def test_the_distances_in_one_call_are_those_of_the_kernels_one_by_one() -> None:
    rng = np.random.default_rng(12)
    # Spread over a tank (all pairs), a school of 3 000 (sampled pairs), and a school with
    # a straggler 100 m off, whose nearest neighbours come from the k-d tree.
    spread = np.c_[rng.uniform(0, 3, (1000, 2)), rng.uniform(0, 1.2, 1000)]
    large = rng.uniform(0.0, 80.0, (3000, 3))
    straggling = np.r_[rng.normal(0.0, 0.3, (1000, 3)), [[100.0, 100.0, 0.5]]]
    for position in (spread, straggling, spread[:2]):
        mean, nearest = distance_kernels.school_distances(position)
        assert mean == distance_kernels.mean_pairwise_distance(position)
        np.testing.assert_array_equal(nearest, distance_kernels.nearest_distances(position))
    pairs = _sampled_pairs(3000)
    mean, nearest = distance_kernels.school_distances(large, pairs)
    assert mean == float(distance_kernels.pair_distances(large, *pairs).mean())
    np.testing.assert_array_equal(nearest, distance_kernels.nearest_distances(large))
    # Drawn on paper: a 3-4-5 triangle, its pairs 5, 4 and 3 m apart.
    triangle = np.array([[0.0, 0.0, 0.0], [3.0, 4.0, 0.0], [3.0, 0.0, 0.0]])
    mean, nearest = distance_kernels.school_distances(triangle)
    assert mean == pytest.approx(4.0, rel=1e-15)
    np.testing.assert_array_equal(nearest, [3.0, 4.0, 3.0])


def test_the_distances_in_one_call_refuse_what_the_kernels_refuse() -> None:
    with pytest.raises(ValueError, match="two fish"):
        distance_kernels.school_distances(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="finite"):
        distance_kernels.school_distances(np.array([[0.0, 0.0, 0.0], [np.inf, 0.0, 0.0]]))
    with pytest.raises(IndexError, match="outside"):
        distance_kernels.school_distances(np.zeros((2, 3)), (np.array([0]), np.array([2])))


def test_the_swarm_metrics_of_a_compiled_school_are_its_distances_one_by_one() -> None:
    rng = np.random.default_rng(13)
    for count in (kernels.COMPILED_MIN_FISH, 2100):  # 2 100 fish: sampled pairs
        position = np.c_[rng.uniform(0, 5, (count, 2)), rng.uniform(0, 1.2, count)]
        metrics = swarm_metrics(position, np.zeros(count, dtype=np.int64))
        assert metrics["pairwise_distance"] == pairwise_distance(position)
        assert metrics["nearest_neighbor_distance"] == nearest_neighbor_distance(position)
