"""Local shapes and the study's rules, on cases drawn on paper (body frame: x forward,
y right, z down; the fish at the origin)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.formations.local import (
    LOCAL_SHAPES,
    local_spots,
    nearest_neighbors,
    triangle_spots,
    trigonal_planar_spots,
)
from fishswarm.formations.maps import target_map
from fishswarm.formations.rules import (
    STAY,
    choose_spot,
    formation_axes,
    leader_and_rank,
    nearest_only,
    place_map,
)

L = 0.3
H = L * math.sqrt(3) / 2  # height of an equilateral triangle of side L


def _one(*points: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    neighbors = np.array([points], dtype=np.float64).reshape(1, -1, 3)
    return neighbors, np.ones(neighbors.shape[:2], dtype=np.bool_)


def test_a_fish_with_two_neighbours_takes_the_near_apex_of_their_triangle() -> None:
    # Two neighbours side by side 0.3 m ahead, 0.3 m apart: the apexes of the equilateral
    # triangles on them are on the x axis, at 0.3 ± H; the fish takes the near one.
    neighbors, mask = _one((0.3, -0.15, 0.0), (0.3, 0.15, 0.0))
    spots, valid, preference = local_spots("triangle", neighbors, mask, spacing=L)
    assert valid.tolist() == [[True, True, False, False, False, False]]
    np.testing.assert_allclose(spots[0, :2], [[0.3 - H, 0, 0], [0.3 + H, 0, 0]], atol=1e-12)
    rivals = np.zeros_like(mask)  # the pair is the shape, not rivals
    choice = choose_spot(
        spots, valid, neighbors, mask, tolerance=0.25 * L, rivals=rivals, preference=preference
    )
    np.testing.assert_allclose(spots[0, choice[0]], [0.3 - H, 0.0, 0.0], atol=1e-12)


def test_an_occupied_spot_and_a_nearer_rival_send_a_fish_on_or_keep_it_still() -> None:
    # As above, plus a third fish right on the near apex: occupied. The far apex has a rival
    # (that third fish) nearer to it than our fish: taken too. No spot left: stay.
    pair, pair_mask = _one((0.3, -0.15, 0.0), (0.3, 0.15, 0.0))
    spots, valid, _ = local_spots("triangle", pair, pair_mask, spacing=L)
    neighbors, mask = _one((0.3, -0.15, 0.0), (0.3, 0.15, 0.0), (0.3 - H + 0.01, 0.0, 0.0))
    rivals = np.array([[False, False, True]])
    assert choose_spot(spots, valid, neighbors, mask, tolerance=0.25 * L, rivals=rivals) == [STAY]
    # Moved off the near apex by more than the tolerance, but still nearer to it than our
    # fish: our fish goes for the far apex only if it is nearer to it than that rival.
    neighbors[0, 2] = [0.3 + H + 0.2, 0.0, 0.0]
    choice = choose_spot(spots, valid, neighbors, mask, tolerance=0.25 * L, rivals=rivals)
    np.testing.assert_allclose(spots[0, choice[0]], [0.3 - H, 0.0, 0.0], atol=1e-12)
    # A flag claims the near apex: the fish takes the far one if no rival is nearer to it.
    neighbors[0, 2] = [-1.0, 0.0, 0.0]
    claimed = np.isclose(spots[:, :, 0], 0.3 - H)
    choice = choose_spot(
        spots, valid, neighbors, mask, tolerance=0.25 * L, rivals=rivals, claimed=claimed
    )
    np.testing.assert_allclose(spots[0, choice[0]], [0.3 + H, 0.0, 0.0], atol=1e-12)


def test_trigonal_planar_completes_the_star_around_its_centre() -> None:
    # A centre 0.5 m ahead with two arms at 90° and 210°: the missing arm is at 330°.
    centre = np.array([0.5, 0.0, 0.0])
    arm = [
        centre + L * np.array([math.cos(a), math.sin(a), 0.0]) for a in map(math.radians, (90, 210))
    ]
    neighbors, mask = _one(tuple(arm[0]), tuple(centre), tuple(arm[1]))
    spots, valid, _ = local_spots("trigonal-planar", neighbors, mask, spacing=L)
    assert valid.tolist() == [[True, False]]
    missing = centre + L * np.array([math.cos(math.radians(330)), math.sin(math.radians(330)), 0])
    np.testing.assert_allclose(spots[0, 0], missing, atol=1e-12)
    # Three arms without their centre: the fish's spot is the centre.
    ring = [
        centre + L * np.array([math.cos(a), math.sin(a), 0.0])
        for a in map(math.radians, (90, 210, 330))
    ]
    neighbors, mask = _one(*(tuple(p) for p in ring))
    spots, valid, _ = local_spots("trigonal-planar", neighbors, mask, spacing=L)
    assert valid.tolist() == [[False, True]]
    np.testing.assert_allclose(spots[0, 1], centre, atol=1e-12)


def test_a_triangle_is_also_tried_with_the_nearest_and_a_neighbour_a_spacing_from_it() -> None:
    # Nearest A 0.2 m ahead, B 0.22 m behind (0.42 m from A: their spots are the points
    # 0.3 m from both, at x = -0.01, y = ±0.214), C 0.5 m ahead — 0.3 m from A, so A and C
    # already make an edge of the shape: their spots are at x = 0.35, y = ±H. D, 0.66 m
    # ahead, is 0.46 m from A: more than half a spacing off an edge, no spots.
    neighbors, mask = _one((0.2, 0, 0), (-0.22, 0, 0), (0.5, 0, 0), (0.66, 0, 0))
    spots, valid, preference = local_spots("triangle", neighbors, mask, spacing=L)
    assert valid.tolist() == [[True, True, True, True, False, False]]
    side = math.sqrt(L**2 - 0.21**2)
    np.testing.assert_allclose(np.abs(spots[0, :2]), [[0.01, side, 0]] * 2, atol=1e-12)
    np.testing.assert_allclose(np.abs(spots[0, 2:4]), [[0.35, H, 0]] * 2, atol=1e-12)
    assert preference[0, 1] < preference[0, 2]  # the two nearest first
    # Both spots of the nearest pair claimed by flags: the fish goes for the A–C edge's.
    claimed = np.array([[True, True, False, False, False, False]])
    choice = choose_spot(
        spots, valid, neighbors, mask, tolerance=0.25 * L, rivals=np.zeros_like(mask),
        claimed=claimed, preference=preference,
    )  # fmt: skip
    np.testing.assert_allclose(np.abs(spots[0, choice[0]]), [0.35, H, 0], atol=1e-12)
    # Only the two nearest: no other spots.
    spots, valid, _ = local_spots("triangle", neighbors, mask, spacing=L, among=2)
    assert spots.shape == (1, 2, 3) and valid.all()


def test_tetrahedron_apexes_stand_above_and_below_the_triangle() -> None:
    # An equilateral triangle of side L at depth 0.5, 1 m ahead: apexes at its centroid
    # ± L·√(2/3) in depth, each L from the three corners.
    corners = [(1.0 + L / math.sqrt(3) * math.cos(a), L / math.sqrt(3) * math.sin(a), 0.5)
               for a in (0, 2 * math.pi / 3, 4 * math.pi / 3)]  # fmt: skip
    neighbors, mask = _one(*corners)
    spots, valid, _ = local_spots("tetrahedron", neighbors, mask, spacing=L)
    assert valid.all()
    np.testing.assert_allclose(
        sorted(spots[0, :, 2]), [0.5 - L * math.sqrt(2 / 3), 0.5 + L * math.sqrt(2 / 3)]
    )
    for spot in spots[0]:
        np.testing.assert_allclose(np.linalg.norm(neighbors[0] - spot, axis=1), [L] * 3)


def test_too_few_neighbours_means_no_spot_and_a_fish_stays() -> None:
    neighbors, mask = _one((0.3, 0.0, 0.0))
    for shape in LOCAL_SHAPES:
        spots, valid, _ = local_spots(shape, neighbors, mask, spacing=L)
        assert not valid.any()
        assert choose_spot(spots, valid, neighbors, mask, tolerance=0.1) == [STAY]
    with pytest.raises(ValueError, match="local shape must be one of"):
        local_spots("hexagon", neighbors, mask, spacing=L)


def test_nearest_neighbours_in_order_with_padding() -> None:
    neighbors = np.array(
        [[[2.0, 0, 0], [0.5, 0, 0], [1.0, 0, 0]], [[0.2, 0, 0], [0, 0, 0], [0, 0, 0]]]
    )
    mask = np.array([[True, True, True], [True, False, False]])
    near, real = nearest_neighbors(neighbors, mask, 2)
    assert near[0, :, 0].tolist() == [0.5, 1.0] and real[0].tolist() == [True, True]
    assert near[1, :, 0].tolist() == [0.2, 0.0] and real[1].tolist() == [True, False]


def test_leader_is_furthest_along_the_orientation_and_the_map_hangs_from_it() -> None:
    # Orientation +y in the fish's body frame (the school heads to the fish's right).
    neighbors, mask = _one((1.0, 0.2, 0.0), (0.0, 0.8, 0.1), (-0.5, -0.3, 0.0))
    orientation = np.array([[0.0, 1.0, 0.0]])
    leader, rank = leader_and_rank(neighbors, mask, orientation)
    np.testing.assert_array_equal(leader[0], [0.0, 0.8, 0.1])
    assert rank.tolist() == [2]  # two neighbours are further along +y than the fish
    slots = place_map(leader, orientation, target_map("column", 3, spacing=L))
    # A column behind the leader along −y (x forward → +y, so behind → −y).
    np.testing.assert_allclose(slots[0], [[0, 0.8, 0.1], [0, 0.8 - L, 0.1], [0, 0.8 - 2 * L, 0.1]])
    # The fish wants slot 2 (its rank); slot 2 is free and nobody is nearer: it takes it.
    choice = choose_spot(
        slots, np.ones((1, 3), bool), neighbors, mask, tolerance=0.25 * L, first=rank
    )
    assert choice.tolist() == [2]


def test_a_fish_ahead_of_all_it_sees_leads_from_where_it_is() -> None:
    neighbors, mask = _one((-1.0, 0.0, 0.0), (-0.5, 0.5, 0.0))
    leader, rank = leader_and_rank(neighbors, mask, np.array([[1.0, 0.0, 0.0]]))
    assert leader.tolist() == [[0.0, 0.0, 0.0]] and rank.tolist() == [0]


def test_a_fish_level_with_a_neighbour_ranks_behind_it_and_hangs_its_map_from_it() -> None:
    # Orientation +x; a neighbour abreast, 0.3 m to the right, is as far along as the fish.
    # Ranked behind it, the fish must not anchor the map at itself too: its slot 1 would
    # then lie behind itself wherever it swims, a place it could never reach.
    neighbors, mask = _one((0.0, 0.3, 0.0), (-0.4, 0.0, 0.0))
    leader, rank = leader_and_rank(neighbors, mask, np.array([[1.0, 0.0, 0.0]]))
    assert rank.tolist() == [1]
    assert leader.tolist() == [[0.0, 0.3, 0.0]]


def test_the_conflict_rule_compares_with_the_nearest_after_those_skipped() -> None:
    neighbors, mask = _one((2.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 3.0, 0.0))
    assert nearest_only(neighbors, mask).tolist() == [[False, True, False]]
    assert nearest_only(neighbors, mask, skip=1).tolist() == [[True, False, False]]
    # A settled neighbour competes for nothing: the next one is marked instead.
    settled = np.array([[False, True, False]])
    assert nearest_only(neighbors, mask, settled=settled).tolist() == [[True, False, False]]


def test_a_rival_exactly_as_far_from_a_spot_as_the_fish_does_not_take_it() -> None:
    # Spot 0.3 m ahead; a rival 0.3 m beyond it. Level: the fish takes the spot.
    neighbors, mask = _one((0.6, 0.0, 0.0))
    spots = np.array([[[0.3, 0.0, 0.0]]])
    valid = np.ones((1, 1), dtype=np.bool_)
    assert choose_spot(spots, valid, neighbors, mask, tolerance=0.075).tolist() == [0]
    neighbors[0, 0, 0] = 0.59  # nearer than the fish: the spot is the rival's
    assert choose_spot(spots, valid, neighbors, mask, tolerance=0.075).tolist() == [STAY]


def test_the_formation_frame_is_level_whatever_the_orientations_pitch() -> None:
    # Heading forward and 45° down: the frame keeps x forward, y right, z down; straight
    # down has no horizontal part, and the frame falls back to the body's axes.
    axes = formation_axes(np.array([[1.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, -2.0, 0.5]]))
    np.testing.assert_allclose(axes[0], np.eye(3))
    np.testing.assert_allclose(axes[1], np.eye(3))
    np.testing.assert_allclose(axes[2], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


def test_spots_are_tried_in_the_order_of_the_preference_when_one_is_given() -> None:
    spots = np.array([[[0.3, 0.0, 0.0], [0.6, 0.0, 0.0]]])
    valid = np.ones((1, 2), dtype=np.bool_)
    nobody, none = np.zeros((1, 0, 3)), np.zeros((1, 0), dtype=np.bool_)
    assert choose_spot(spots, valid, nobody, none, tolerance=0.05).tolist() == [0]
    preferred = choose_spot(
        spots, valid, nobody, none, tolerance=0.05, preference=np.array([[1.0, 0.0]])
    )
    assert preferred.tolist() == [1]


def test_a_neighbour_on_a_spot_of_its_own_seeks_no_share_of_the_free_ones() -> None:
    # Spots at 1 m and 1.5 m ahead; a neighbour sits on the second, 0.5 m from the first.
    # It is nearer to the one free spot than the fish, but it holds a spot already: when the
    # free spots are shared out, the fish is the only seeker and takes the first.
    neighbors, mask = _one((1.5, 0.0, 0.0))
    spots = np.array([[[1.0, 0.0, 0.0], [1.5, 0.0, 0.0]]])
    valid = np.ones((1, 2), dtype=np.bool_)
    assert choose_spot(spots, valid, neighbors, mask, tolerance=0.1).tolist() == [0]


def test_nearest_neighbours_are_zero_where_a_fish_sees_too_few() -> None:
    # The second row is not real (masked), whatever numbers it holds.
    neighbors = np.array([[[0.4, 0.1, 0.0], [0.2, 5.0, 7.0]]])
    near, real = nearest_neighbors(neighbors, np.array([[True, False]]), 2)
    assert near.tolist() == [[[0.4, 0.1, 0.0], [0.0, 0.0, 0.0]]]
    assert real.tolist() == [[True, False]]


def test_a_triangles_apexes_are_measured_across_the_water_level() -> None:
    # Neighbours L apart across, the second 0.2 m deeper: the apexes stand H ahead and
    # behind their midpoint, at their mean depth (the depth difference does not count).
    first, second = np.array([[0.5, -L / 2, 0.0]]), np.array([[0.5, L / 2, 0.2]])
    spots = triangle_spots(first, second, spacing=L)
    np.testing.assert_allclose(spots[0], [[0.5 - H, 0.0, 0.1], [0.5 + H, 0.0, 0.1]])
    # One straight above the other: no horizontal direction of their own; across is +y.
    above = triangle_spots(np.array([[0.5, 0.0, 0.0]]), np.array([[0.5, 0.0, 0.2]]), spacing=L)
    np.testing.assert_allclose(above[0], [[0.5, L, 0.1], [0.5, -L, 0.1]])


def _star_with_arms_apart(
    degrees: float, depths: tuple[float, float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Trigonal-planar spots of a centre at (0.5, 0) and two arms ``degrees`` apart,
    symmetric about −x (the outer spot then lies along +x from the centre)."""
    half = math.radians(degrees) / 2
    centre = np.array([[0.5, 0.0, depths[0]]])
    left = np.array([[0.5 - L * math.cos(half), -L * math.sin(half), depths[1]]])
    right = np.array([[0.5 - L * math.cos(half), L * math.sin(half), depths[2]]])
    return trigonal_planar_spots(left, centre, right, spacing=L)


def test_a_star_gets_an_outer_spot_only_when_its_arms_are_more_than_90_degrees_apart() -> None:
    spots, applies = _star_with_arms_apart(100.0, (0.1, 0.1, 0.4))
    assert applies.tolist() == [[True, False]]
    # Opposite the arms' bisector, L from the centre, at the three fish's mean depth.
    np.testing.assert_allclose(spots[0, 0], [0.5 + L, 0.0, 0.2], atol=1e-12)
    _, applies = _star_with_arms_apart(80.0, (0.0, 0.0, 0.0))
    assert applies.tolist() == [[False, True]]


def test_the_spots_of_the_two_nearest_come_before_nearer_spots_of_other_pairs() -> None:
    # Nearest 0.2 m ahead and 0.21 m behind (0.41 m apart): their apexes are 0.143 m to
    # either side. The nearest and a third fish a spacing from it give an apex 0.126 m away,
    # nearer, but of a later pair: the fish takes an apex of its two nearest.
    spacing = 0.25
    neighbors, mask = _one((0.2, 0.0, 0.0), (-0.21, 0.0, 0.0), (0.2, 0.25, 0.0))
    spots, valid, preference = local_spots("triangle", neighbors, mask, spacing=spacing)
    distance = np.linalg.norm(spots[0], axis=1)
    assert valid[0, :4].all() and distance[2] < distance[0] == distance[1]
    choice = choose_spot(
        spots, valid, neighbors, mask, tolerance=spacing / 4, preference=preference
    )
    assert choice.tolist() == [0]
    np.testing.assert_allclose(spots[0, 0], [-0.005, -math.sqrt(spacing**2 - 0.205**2), 0.0])
