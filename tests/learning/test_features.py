"""What a classifier sees of a track: speed, turning, the nearest schoolmate, counts within
fixed and learned radii — on tracks drawn by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.learning.arena import Arena
from fishswarm.learning.features import (
    COUNT_RADII,
    check_inputs,
    feature_count,
    neighbor_counts,
    samples_from,
)


def _line_of_three() -> np.ndarray:
    """One trial, three fish on the x axis at 0, 10 and 30; over one step the first moves
    3 along x and 4 along y (speed 5), the others stay."""
    start = np.array([[0.0, 0.0], [10.0, 0.0], [30.0, 0.0]])
    after = start.copy()
    after[0] = [3.0, 4.0]
    return np.stack([start, after])[None]  # (1, 2, 3, 2)


def test_speed_and_the_nearest_schoolmate_by_hand() -> None:
    arena = Arena()
    samples = samples_from(_line_of_three(), ("speed", "nearest"), arena=arena)
    assert feature_count(("speed", "nearest")) == 2
    assert samples.fixed.shape == (3, 1, 2)
    # Speeds 5, 0, 0 over the cap; nearest distances after the step: fish 0 at (3, 4) is
    # √(7² + 4²) from fish 1, fish 1 the same from fish 0, fish 2 is 20 from fish 1.
    np.testing.assert_allclose(samples.fixed[:, 0, 0], [5 / arena.speed_cap, 0.0, 0.0])
    nearest = [math.hypot(7, 4), math.hypot(7, 4), 20.0]
    np.testing.assert_allclose(
        samples.fixed[:, 0, 1], np.array(nearest) / arena.communication_range
    )


def test_a_turn_across_the_back_of_the_compass_is_the_short_way_round() -> None:
    # Fish 0 swims 5 at heading 179°, then 5 at −179°: a turn of 2°, not 358°. Fish 1 stays.
    def five_at(degrees: float) -> np.ndarray:
        return np.array(
            [[5 * math.cos(math.radians(degrees)), 5 * math.sin(math.radians(degrees))], [0.0, 0.0]]
        )

    start = np.array([[100.0, 100.0], [50.0, 50.0]])
    middle = start + five_at(179.0)
    end = middle + five_at(-179.0)
    samples = samples_from(np.stack([start, middle, end])[None], ("angular-speed",), arena=Arena())
    # No turn before the first step; then 2° over π (180°).
    np.testing.assert_allclose(samples.fixed[:, :, 0], [[0.0, 2 / 180], [0.0, 0.0]], atol=1e-12)


def test_the_nearest_distance_is_capped_at_the_communication_range() -> None:
    arena = Arena()
    far = _line_of_three() * 100.0
    samples = samples_from(far, ("nearest",), arena=arena)
    assert samples.fixed[:, 0, 0].tolist() == [1.0, 1.0, 1.0]


def test_counts_within_fixed_radii_by_hand() -> None:
    samples = samples_from(_line_of_three(), ("speed", "counts"), arena=Arena())
    assert COUNT_RADII == (15.0, 30.0, 60.0)
    assert feature_count(("speed", "counts")) == 4
    assert feature_count(("counts", "neighbors")) == 4
    # After the step fish 0 and 1 are √65 ≈ 8.1 apart, 1 and 2 are 20, 0 and 2 √745 ≈ 27.3:
    # within 15, 30 and 60 of each, out of its two schoolmates.
    np.testing.assert_array_equal(
        samples.fixed[:, 0, 1:], [[0.5, 1.0, 1.0], [0.5, 1.0, 1.0], [0.0, 1.0, 1.0]]
    )


def test_counts_within_a_learned_radius_by_hand() -> None:
    samples = samples_from(_line_of_three(), ("neighbors",), arena=Arena())
    assert samples.fixed.shape == (3, 1, 0)
    counts = neighbor_counts(samples, np.array([[9.0], [21.0]]))
    # Radius 9: fish 0 and 1, √65 ≈ 8.06 apart, see each other; fish 2 is 20 from anyone.
    assert counts[0, :, 0, 0].tolist() == [0.5, 0.5, 0.0]
    # Radius 21: fish 1 sees both (20 < 21); fish 0 and fish 2 are √745 ≈ 27.3 apart.
    assert counts[1, :, 0, 0].tolist() == [0.5, 1.0, 0.5]


def test_inputs_are_checked() -> None:
    assert check_inputs(("nearest", "neighbors")) == ("nearest", "neighbors")
    with pytest.raises(ValueError, match="distinct names"):
        check_inputs(("nearest", "nearest"))
    with pytest.raises(ValueError, match="distinct names"):
        check_inputs(("closest",))
