"""Vision: range, blind spot and occlusion cases drawn on paper."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fishswarm.bluebot.vision import Vision, in_blind_spot, perceive, perceive_landmarks, to_body

NO_OCCLUSION = Vision(blind_width=0.0, sphere_radius=0.0)


def _seen(
    positions: Sequence[Sequence[float]], yaw: Sequence[float], vision: Vision
) -> list[set[int]]:
    result = perceive(np.array(positions, dtype=float), np.array(yaw, dtype=float), vision=vision)
    return [set(int(j) for j in row[row >= 0]) for row in result.index]


def test_body_frame_rotation() -> None:
    # A fish facing +y (yaw π/2) sees a neighbour at +y straight ahead, one at −x to its right.
    body = to_body(np.array([[[0.0, 1.0, 0.2], [-1.0, 0.0, 0.0]]]), np.array([math.pi / 2]))
    np.testing.assert_allclose(body[0], [[1.0, 0.0, 0.2], [0.0, 1.0, 0.0]], atol=1e-12)


def test_range_limits_what_is_seen() -> None:
    seen = _seen([[0, 0, 0], [2.9, 0, 0], [3.1, 0, 0]], [0, 0, 0], Vision(3.0, 0.0, 0.0))
    assert seen[0] == {1}


def test_blind_spot_hides_a_fish_directly_behind() -> None:
    # Observer at origin facing +x. Behind at (−1, 0.01): lateral 0.01 < w/2 = 0.025 → hidden.
    # Behind at (−1, 0.03): lateral 0.03 > 0.025 → seen. In front at (1, 0): seen.
    positions: list[list[float]] = [[1, 1, 0], [0, 1.01, 0], [0, 1.03, 0], [2, 1, 0]]
    seen = _seen(positions, [0, 0, 0, 0], Vision(blind_width=0.05, sphere_radius=0.0))
    assert seen[0] == {2, 3}


def test_blind_strip_is_unbounded_in_depth() -> None:
    hidden = in_blind_spot(np.array([[[-1.0, 0.0, 5.0]]]), np.array([0.0]), blind_width=0.05)
    assert hidden[0, 0]


def test_blind_width_zero_sees_all_and_diagonal_gives_half_field() -> None:
    relative = np.array([[[-1.0, 0.5, 0.0], [-0.1, -2.0, 0.0], [0.1, 2.0, 0.0]]])
    assert not in_blind_spot(relative, np.array([0.0]), blind_width=0.0).any()
    hidden = in_blind_spot(relative, np.array([0.0]), blind_width=2.517)
    # Behind within 1.26 m of the heading line: the first (lateral 0.5); the second is behind
    # but 2 m to the side; the third is in front.
    assert hidden.tolist() == [[True, False, False]]


def test_collinear_fish_are_occluded_by_the_nearer() -> None:
    positions = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]
    assert _seen(positions, [0, 0, 0], Vision(blind_width=0, sphere_radius=0.065))[0] == {1}
    assert _seen(positions, [0, 0, 0], NO_OCCLUSION)[0] == {1, 2}


def test_occlusion_angle_threshold() -> None:
    # Blocker at (1, 0): hides directions within atan(0.065/1) = 3.72° of it.
    # Target at (2, 2·tan 3°) → angle 3° → hidden; at (2, 2·tan 5°) → 5° → seen.
    vision = Vision(blind_width=0, sphere_radius=0.065)
    hidden = _seen([[0, 0, 0], [1, 0, 0], [2, 2 * math.tan(math.radians(3)), 0]], [0] * 3, vision)
    shown = _seen([[0, 0, 0], [1, 0, 0], [2, 2 * math.tan(math.radians(5)), 0]], [0] * 3, vision)
    assert hidden[0] == {1}
    assert shown[0] == {1, 2}
    # Close either side of 3.72°: 3.5° hidden, 3.9° seen.
    for degrees, expected in ((3.5, {1}), (3.9, {1, 2})):
        target = [2, 2 * math.tan(math.radians(degrees)), 0]
        assert _seen([[0, 0, 0], [1, 0, 0], target], [0] * 3, vision)[0] == expected


def test_only_visible_fish_occlude() -> None:
    # Observer at (1, 1) facing +x. Fish 1 straight behind at 0.5 m is in the blind strip;
    # fish 2 behind at (0, 1.04) lies 0.04 m off the heading line (outside the strip) and
    # within atan(0.065/0.5) = 7.4° of fish 1's direction (2.3°).
    positions: list[list[float]] = [[1, 1, 0], [0.5, 1, 0], [0, 1.04, 0]]
    # Fish 1 is unseen, so it cannot hide fish 2.
    assert _seen(positions, [0] * 3, Vision(blind_width=0.05, sphere_radius=0.065))[0] == {2}
    # Without a blind spot, fish 1 is seen and hides fish 2.
    assert _seen(positions, [0] * 3, Vision(blind_width=0.0, sphere_radius=0.065))[0] == {1}


def test_coincident_fish_do_not_crash() -> None:
    positions = [[1, 1, 1], [1, 1, 1], [1, 1, 1], [2, 1, 1]]
    result = perceive(np.array(positions, float), np.zeros(4), vision=Vision())
    assert np.all(np.isfinite(result.neighbors))
    assert result.counts[0] == 3
    np.testing.assert_allclose(result.of(0)[0], [0, 0, 0])


def test_neighbours_come_nearest_first_in_body_frame() -> None:
    result = perceive(
        np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [0.5, 0.8, 0.5]]),
        np.array([0.0, math.pi, 0.0]),
        vision=NO_OCCLUSION,
    )
    np.testing.assert_allclose(result.of(0), [[0.0, 0.3, 0.0], [1.0, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(result.of(1)[0], [1.0, 0.0, 0.0], atol=1e-12)


def test_noise_is_per_fish_and_proportional_to_distance() -> None:
    positions = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.0, 2.0, 0]])
    vision = Vision(blind_width=0, sphere_radius=0, noise=0.1)
    first = perceive(
        positions, np.zeros(3), vision=vision, rngs=[np.random.default_rng(i) for i in range(3)]
    )
    second = perceive(
        positions, np.zeros(3), vision=vision, rngs=[np.random.default_rng(i) for i in range(3)]
    )
    np.testing.assert_array_equal(first.neighbors, second.neighbors)
    clean = perceive(positions, np.zeros(3), vision=NO_OCCLUSION)
    assert not np.array_equal(first.neighbors, clean.neighbors)
    # Fish 0 sees fish 1 at 1 m and fish 2 at 2 m (nearest first; facing +x, so its body
    # frame is the tank's): each is off by noise·distance·z, z drawn from fish 0's own
    # generator, one normal triple per neighbour in that order.
    z = np.random.default_rng(0).normal(0.0, 1.0, (2, 3))
    np.testing.assert_allclose(
        first.of(0) - clean.of(0), 0.1 * np.array([[1.0], [2.0]]) * z, atol=1e-12
    )
    with pytest.raises(ValueError, match="one random generator per fish"):
        perceive(positions, np.zeros(3), vision=vision)


def test_landmark_in_blind_spot_is_hidden() -> None:
    result = perceive_landmarks(
        np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 0.5]]),
        np.array([0.0, 0.0]),
        np.array([[0.5, 1.0, 0.5]]),
        vision=Vision(),
    )
    assert result.mask.tolist() == [[False], [True]]
    np.testing.assert_allclose(result.of(1), [[0.5, 0.0, 0.0]])


def test_a_landmark_exactly_at_the_visual_range_is_seen() -> None:
    result = perceive_landmarks(
        np.array([[0.5, 1.0, 0.5], [0.4, 1.0, 0.5]]),
        np.zeros(2),
        np.array([[3.5, 1.0, 0.5]]),
        vision=Vision(visual_range=3.0),
    )
    # 3.0 m ahead of the first fish (seen), 3.1 m ahead of the second (not).
    assert result.mask.tolist() == [[True], [False]]
    np.testing.assert_allclose(result.of(0), [[3.0, 0.0, 0.0]])


def test_no_landmarks_are_seen_by_every_fish_as_nothing() -> None:
    result = perceive_landmarks(
        np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 0.5]]), np.zeros(2), np.zeros((0, 3)), vision=Vision()
    )
    assert result.neighbors.shape == (2, 0, 3) and result.neighbors.dtype == np.float64
    assert result.mask.shape == (2, 0) and result.mask.dtype == np.bool_
    assert result.index.shape == (2, 0) and result.index.dtype == np.intp
    assert result.counts.tolist() == [0, 0] and result.of(1).shape == (0, 3)


@settings(max_examples=50, deadline=None)
@given(
    positions=hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 12), st.just(3)),
        elements=st.sampled_from([0.0, 0.5, 1.0, 1.5]),
    ),
    yaw=st.floats(-math.pi, math.pi),
)
def test_vision_is_finite_and_sane_for_any_arrangement(positions: np.ndarray, yaw: float) -> None:
    count = positions.shape[0]
    result = perceive(positions, np.full(count, yaw), vision=Vision(sphere_radius=0.2))
    assert np.all(np.isfinite(result.neighbors))
    assert np.all(result.counts <= count - 1)
    for fish in range(count):
        assert fish not in set(result.index[fish].tolist())
        # the nearest non-blind neighbour is always visible
    assert result.mask.shape == result.index.shape


def test_manhattan_links_on_drawn_cases() -> None:
    # A fish at the origin facing +x, range 3 m, no blind spot, no occlusion. Drawn:
    #   (2, 0, 0)      straight line 2.00, |dx|+|dy|+|dz| 2.0  → seen both ways
    #   (0, 1.5, -1.5) straight line 2.12, Manhattan 3.0 (on the edge) → seen both ways
    #   (1.5, 1.5, 0.5) straight line 2.18, Manhattan 3.5 → only the straight line sees it
    #   (0, -2.9, 0.2) straight line 2.91, Manhattan 3.1 → only the straight line sees it
    position = (
        np.array(
            [[0, 0, 0], [2, 0, 0], [0, 1.5, -1.5], [1.5, 1.5, 0.5], [0, -2.9, 0.2]], dtype=float
        )
        + 5.0
    )
    yaw = np.zeros(5)
    straight = Vision(3.0, 0.0, 0.0)
    manhattan = Vision(3.0, 0.0, 0.0, manhattan=True)
    seen_straight = perceive(position, yaw, vision=straight)
    seen_manhattan = perceive(position, yaw, vision=manhattan)
    assert sorted(seen_straight.index[0][seen_straight.mask[0]].tolist()) == [1, 2, 3, 4]
    assert sorted(seen_manhattan.index[0][seen_manhattan.mask[0]].tolist()) == [1, 2]
    # Links are symmetric: fish 3 does not see fish 0 either.
    assert 0 not in seen_manhattan.index[3].tolist()
    assert 0 in seen_straight.index[3].tolist()


def test_vision_parameters_must_be_finite() -> None:
    for name in ("visual_range", "blind_width", "sphere_radius", "noise"):
        with pytest.raises(ValueError, match=f"vision {name} must be a finite non-negative"):
            Vision(**{name: math.inf})  # type: ignore[arg-type]


def test_noise_with_too_few_generators_is_refused() -> None:
    positions = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    with pytest.raises(ValueError, match="one random generator per fish"):
        perceive(positions, np.zeros(2), vision=Vision(noise=0.1), rngs=[np.random.default_rng(0)])


def test_a_landmark_out_of_sight_has_no_index_and_no_position() -> None:
    # Two landmarks ahead of a fish facing +x: 1 m (seen) and 4 m (beyond the 3-m range).
    result = perceive_landmarks(
        np.array([[0.5, 1.0, 0.5]]),
        np.zeros(1),
        np.array([[1.5, 1.0, 0.5], [4.5, 1.0, 0.5]]),
        vision=Vision(visual_range=3.0),
    )
    assert result.mask.tolist() == [[True, False]]
    assert result.index.tolist() == [[0, -1]]
    assert result.neighbors.tolist() == [[[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]]


def test_occlusion_in_blocks_of_fish_gives_the_same_bits_as_all_at_once(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A tank where every fish sees every other: the cosines of all at once would take 60 GB
    # at 2 000 fish, so they are made a block of fish at a time.
    from fishswarm.bluebot import vision

    rng = np.random.default_rng(1)
    directions = rng.normal(size=(40, 30, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    distance = np.sort(rng.uniform(0.1, 3.0, (40, 30)), axis=1)
    candidate = rng.uniform(size=(40, 30)) < 0.9
    whole = vision._occlusion(directions, distance, candidate, sphere_radius=0.2)
    monkeypatch.setattr(vision, "OCCLUSION_BLOCK", 3 * 30 * 30)  # three fish at a time
    blocks = vision._occlusion(directions, distance, candidate, sphere_radius=0.2)
    np.testing.assert_array_equal(blocks, whole)
    assert 0 < whole.sum() < candidate.sum()  # some hidden, some seen
