"""Lennard-Jones forces: signs, magnitudes and the averaging over neighbours."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.behaviors.lennard_jones import lennard_jones, lennard_jones_force


def test_force_is_zero_at_the_target_distance_and_changes_sign() -> None:
    assert lennard_jones_force(np.array(0.26), target_distance=0.26, epsilon=1.0) == 0.0
    assert lennard_jones_force(np.array(0.2), target_distance=0.26, epsilon=1.0) > 0
    assert lennard_jones_force(np.array(0.3), target_distance=0.26, epsilon=1.0) < 0


def test_force_magnitude_by_hand() -> None:
    # r = r_t/2: −dV/dr = 12ε/r·(2¹² − 2⁶) = 12·1/0.5·4032 = 96768 for r_t = 1.
    value = lennard_jones_force(np.array(0.5), target_distance=1.0, epsilon=1.0)
    assert float(value) == pytest.approx(96768.0)


def test_near_neighbour_repels_far_one_attracts() -> None:
    neighbors = np.array([[[0.1, 0.0, 0.0]], [[1.0, 0.0, 0.0]]])
    mask = np.ones((2, 1), dtype=bool)
    result = lennard_jones(neighbors, mask, target_distance=0.26)
    assert result[0, 0] < 0  # neighbour ahead and too close: move back
    assert result[1, 0] > 0  # neighbour ahead and far: move towards it
    np.testing.assert_array_equal(result[:, 1:], 0.0)


def test_vector_magnitude_by_hand() -> None:
    # One neighbour 0.39 m ahead (= r_t + 1 body length), ε = 1, r_t = 0.26:
    # −dV/dr = 12/0.39·(0.0077073 − 0.0877915) = −2.4641 → 2.4641 m towards it.
    result = lennard_jones(
        np.array([[[0.39, 0.0, 0.0]]]), np.ones((1, 1), bool), target_distance=0.26
    )
    ratio6 = (0.26 / 0.39) ** 6
    expected = -12.0 / 0.39 * (ratio6**2 - ratio6)
    assert result[0, 0] == pytest.approx(expected)
    assert result[0, 0] == pytest.approx(2.4641, abs=1e-4)


def test_far_distances_are_capped() -> None:
    mask = np.ones((1, 1), bool)
    near_cap = lennard_jones(np.array([[[0.39, 0, 0]]]), mask, target_distance=0.26)
    far = lennard_jones(np.array([[[2.5, 0, 0]]]), mask, target_distance=0.26)
    np.testing.assert_allclose(near_cap, far)


def test_contributions_are_averaged_and_padding_ignored() -> None:
    neighbors = np.array([[[0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [9.0, 9.0, 9.0]]])
    mask = np.array([[True, True, False]])
    result = lennard_jones(neighbors, mask, target_distance=0.26, epsilon=1.0)
    single = lennard_jones(neighbors[:, :1], mask[:, :1], target_distance=0.26, epsilon=1.0)
    assert result[0, 0] == pytest.approx(single[0, 0] / 2)
    assert result[0, 1] == pytest.approx(single[0, 0] / 2)


def test_lonely_and_coincident_fish_stay_finite() -> None:
    result = lennard_jones(np.zeros((2, 1, 3)), np.array([[False], [True]]), target_distance=2.5)
    np.testing.assert_array_equal(result, 0.0)
