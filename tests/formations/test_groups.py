"""Whether a fish completes its local shape: groups against ideal shapes, on cases drawn on
paper and on random groups against a brute-force alignment."""

from __future__ import annotations

import itertools
import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fishswarm.formations.groups import (
    _MATCHINGS,
    completion,
    group_errors,
    ideal_local_shape,
)
from fishswarm.formations.maps import target_map
from fishswarm.formations.metrics import align, local_shape_error, local_shape_errors

L = 0.25
TOLERANCE = 0.0625


def _turn(yaw: float, pitch: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    about_z = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    c, s = math.cos(pitch), math.sin(pitch)
    about_y = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    turn: np.ndarray = about_z @ about_y
    return turn


def test_a_shape_moved_turned_and_reordered_is_the_shape() -> None:
    for shape in _MATCHINGS:
        ideal = ideal_local_shape(shape, spacing=L)
        moved = ideal @ _turn(0.7, 0.4).T + [1.0, -2.0, 0.5]
        for order in itertools.permutations(range(len(ideal))):
            rms, largest = group_errors(moved[list(order)][None], ideal)
            assert rms[0] < 1e-12 and largest[0] < 1e-12


def test_a_stretched_triangle_is_off_by_what_paper_says() -> None:
    # An isosceles triangle with base L and height 2·H against the equilateral one (height
    # H): by symmetry the best fit only moves centroid onto centroid, which leaves each base
    # corner H/3 and the apex 2H/3 from its place.
    height = L * math.sqrt(3) / 2
    stretched = np.array([[0.0, 0, 0], [L, 0, 0], [L / 2, 2 * height, 0]])
    rms, largest = group_errors(stretched[None], ideal_local_shape("triangle", spacing=L))
    offsets = np.array([height / 3, height / 3, 2 * height / 3])
    assert math.isclose(largest[0], offsets.max(), rel_tol=1e-9)
    assert math.isclose(rms[0], math.sqrt(np.mean(offsets**2)), rel_tol=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    shape=st.sampled_from(sorted(_MATCHINGS)),
    seed=st.integers(0, 2**31 - 1),
    noise=st.floats(0.0, 0.1),
)
def test_fits_equal_a_brute_force_alignment(shape: str, seed: int, noise: float) -> None:
    rng = np.random.default_rng(seed)
    ideal = ideal_local_shape(shape, spacing=L)
    group = ideal @ _turn(*rng.uniform(0, 2 * math.pi, 2)).T + rng.normal(0, noise, ideal.shape)
    group = group[rng.permutation(len(ideal))]
    rms, _ = group_errors(group[None], ideal, orders=_MATCHINGS[shape])
    every_order, _ = group_errors(group[None], ideal)
    assert math.isclose(rms[0], every_order[0], rel_tol=1e-9, abs_tol=1e-12)
    # metrics.align fits with turns and the Hungarian method: never better than the best.
    assert rms[0] <= align(group, ideal, starts=12).rms + 1e-12


def test_every_fish_of_a_perfect_lattice_completes_a_triangle() -> None:
    # The pyramid of 15 is a patch of the triangular lattice: inside it a fish has six
    # neighbours at one spacing, and whichever two count as "nearest", it has joined.
    lattice = target_map("pyramid", 15, spacing=L)
    fit = local_shape_errors(lattice, "triangle", spacing=L, tolerance=TOLERANCE)
    np.testing.assert_allclose(fit.largest, 0.0, atol=1e-12)
    assert local_shape_error(lattice, "triangle", spacing=L, tolerance=TOLERANCE) == (
        fit.rms.mean(),
        1.0,
    )
    # A fish amid a ring of six, the two strictly nearest on opposite sides (1 and 0.5 mm
    # nearer than the others): with them alone it makes no triangle (a straight line); with
    # any two adjacent ones of its six it does.
    ring = [L * np.array([math.cos(a), math.sin(a), 0.0]) for a in np.radians(range(0, 360, 60))]
    ring[0] *= (L - 0.001) / L
    ring[3] *= (L - 0.0005) / L
    others = np.array([ring])
    mask = np.ones((1, 6), dtype=np.bool_)
    here = np.zeros((1, 1, 3))
    strict = completion(here, others, mask, "triangle", spacing=L, tolerance=TOLERANCE, among=2)
    assert strict.largest[0, 0] > TOLERANCE
    ring_fit = completion(here, others, mask, "triangle", spacing=L, tolerance=TOLERANCE)
    assert ring_fit.largest[0, 0] < 0.001


def test_a_stranger_nearer_than_the_members_spoils_the_shape() -> None:
    triangle = ideal_local_shape("triangle", spacing=L)
    # A fourth fish 0.1 m from the first corner, on the far side from the others.
    stranger = triangle[0] + [-0.1, 0.0, 0.0]
    school = np.vstack([triangle, stranger])
    fit = local_shape_errors(school, "triangle", spacing=L, tolerance=TOLERANCE)
    assert not fit.joined(TOLERANCE)[0]  # the stranger is nearer than its corners
    # Corner 1 has its partners at L and the stranger at L + 0.1: farther than both, so it
    # spoils nothing there.
    assert fit.joined(TOLERANCE)[1]
    # Far enough away, the stranger spoils nothing.
    school[3] = triangle[0] + [-1.0, 0.0, 0.0]
    far = local_shape_errors(school, "triangle", spacing=L, tolerance=TOLERANCE)
    assert far.joined(TOLERANCE)[:3].all() and not far.joined(TOLERANCE)[3]


def test_candidate_spots_are_judged_with_the_fish_that_would_surround_them() -> None:
    # Two neighbours L apart; of the two apexes, the one with a third fish 0.05 m from it
    # would be crowded, the other completes the triangle.
    height = L * math.sqrt(3) / 2
    others = np.array([[[0.5, -L / 2, 0.0], [0.5, L / 2, 0.0], [0.5 + height + 0.05, 0, 0]]])
    spots = np.array([[[0.5 - height, 0.0, 0.0], [0.5 + height, 0.0, 0.0]]])
    fit = completion(
        spots, others, np.ones((1, 3), dtype=np.bool_), "triangle", spacing=L, tolerance=TOLERANCE
    )
    assert fit.largest[0, 0] < 1e-12 and not fit.joined(TOLERANCE)[0, 1]
    # Fewer fish than the shape needs: nothing completes it.
    lone = completion(
        spots, others[:, :1], np.ones((1, 1), dtype=np.bool_), "triangle", spacing=L,
        tolerance=TOLERANCE,
    )  # fmt: skip
    assert np.isinf(lone.largest).all()


def test_judging_each_fish_with_its_nearest_few_equals_judging_it_with_all() -> None:
    rng = np.random.default_rng(3)
    school = rng.uniform(0.0, 1.0, (40, 3))
    everyone = np.broadcast_to(school[None], (40, 40, 3))
    for shape in _MATCHINGS:
        few = local_shape_errors(school, shape, spacing=L, tolerance=TOLERANCE)
        every = completion(
            school[:, None, :], everyone, ~np.eye(40, dtype=np.bool_), shape, spacing=L,
            tolerance=TOLERANCE,
        )  # fmt: skip
        np.testing.assert_array_equal(few.largest, every.largest[:, 0])
        np.testing.assert_array_equal(few.rms, every.rms[:, 0])


def test_the_edges_of_completed_shapes_are_the_sides_of_their_triangles() -> None:
    from fishswarm.formations.metrics import shape_edges

    # Two triangles of side L sharing the edge 1–2, and a fifth fish far off (no shape).
    height = L * math.sqrt(3) / 2
    school = np.array(
        [[0, 0, 0], [L, 0, 0], [L / 2, height, 0], [1.5 * L, height, 0], [5.0, 5.0, 0]]
    )
    fit = local_shape_errors(school, "triangle", spacing=L, tolerance=TOLERANCE)
    assert fit.joined(TOLERANCE).tolist() == [True, True, True, True, False]
    assert sorted(fit.members[0].tolist()) == [1, 2] and sorted(fit.members[3].tolist()) == [1, 2]
    edges = shape_edges(fit, TOLERANCE, position=school, spacing=L)
    assert edges.tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]


def test_the_edges_of_a_completed_star_join_its_centre_to_its_arms() -> None:
    from fishswarm.formations.metrics import shape_edges

    # A centre (0) with arms at 0°, 120° and 240° (1–3), 1 cm off; the arms are √3·L apart
    # and are not joined to each other.
    arms = [
        [L * math.cos(a), L * math.sin(a), 0.0] for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
    ]
    school = np.array([[0.0, 0.01, 0.0], *arms])
    fit = local_shape_errors(school, "trigonal-planar", spacing=L, tolerance=TOLERANCE)
    assert fit.joined(TOLERANCE).all()
    edges = shape_edges(fit, TOLERANCE, position=school, spacing=L)
    assert edges.tolist() == [[0, 1], [0, 2], [0, 3]]


def test_a_mirror_image_is_not_the_shape_it_mirrors() -> None:
    # Four points along x, y and z at 1, 2 and 3 m from a corner: a shape with a handedness.
    # Turned and moved it fits exactly; mirrored (x → −x) no turn and no order of its points
    # brings it back, since fish in a tank cannot swap left for right.
    chiral = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.0, 2, 0], [0.0, 0, 3]])
    turned = chiral @ _turn(0.7, 0.4).T + [1.0, -2.0, 0.5]
    rms, largest = group_errors(turned[None], chiral)
    assert rms[0] < 1e-12 and largest[0] < 1e-12
    mirrored = chiral * [-1.0, 1.0, 1.0]
    rms, largest = group_errors(mirrored[None], chiral)
    assert rms[0] > 0.1 and largest[0] > 0.2


def test_a_fish_without_a_group_has_no_fit_and_no_members() -> None:
    others = np.array([[[L, 0.0, 0.0]]])  # one neighbour: a triangle needs two
    fit = completion(
        np.zeros((1, 1, 3)), others, np.ones((1, 1), dtype=np.bool_), "triangle", spacing=L,
        tolerance=TOLERANCE,
    )  # fmt: skip
    assert np.isinf(fit.largest[0, 0]) and np.isinf(fit.rms[0, 0])
    assert fit.members.tolist() == [[[-1, -1]]]
    assert not fit.joined(TOLERANCE)[0, 0]
