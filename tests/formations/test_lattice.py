"""Star maps: places on a triangular lattice where every fish completes a trigonal-planar star,
checked against stars drawn on paper and against the observer's own measure."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.distance import pdist

from fishswarm.formations.groups import completion
from fishswarm.formations.lattice import close_packing, completes_star, star_map, star_sites

# Lattice places are steps along two axes 60° apart: (1, 0) at 0°, (0, 1) at 60°,
# (-1, 1) at 120°, (-1, 0) at 180°, (0, -1) at 240°, (1, -1) at 300°.
STAR = {(0, 0), (1, 0), (-1, 1), (0, -1)}  # a centre and arms at 0°, 120°, 240°
FAN = {(0, 0), (1, 0), (0, 1), (-1, 1)}  # arms at 0°, 60°, 120°: no star
HEXAGON = {(0, 0), (1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1)}  # a centre and its ring


def _observed(places: np.ndarray, spacing: float, shape: str = "trigonal-planar") -> np.ndarray:
    """Which fish at ``places`` (N, 3) complete their shape by the observer's measure."""
    count = places.shape[0]
    others = np.array([np.delete(places, i, axis=0) for i in range(count)])
    fit = completion(
        places[:, None, :], others, np.ones(others.shape[:2], dtype=np.bool_),
        shape, spacing=spacing, tolerance=spacing / 4,
    )  # fmt: skip
    joined: np.ndarray = fit.joined(spacing / 4)[:, 0]
    return joined


def _points(sites: list[tuple[int, int]], spacing: float) -> np.ndarray:
    return np.array([(a + b / 2, b * math.sqrt(3) / 2, 0.0) for a, b in sites]) * spacing


def test_a_star_drawn_on_paper_is_complete_for_every_fish() -> None:
    assert all(completes_star(site, STAR) for site in STAR)
    # Arms 60° apart make no star, and an arm that touches another arm is no arm.
    assert not any(completes_star(site, FAN) for site in FAN)


def test_a_hexagon_completes_only_its_centre_until_each_corner_grows_an_arm() -> None:
    assert [site for site in HEXAGON if completes_star(site, HEXAGON)] == [(0, 0)]
    # An arm out of every corner, away from the centre: every corner is then a centre
    # (its two ring neighbours and its arm are 120° apart) and every arm an arm of it.
    arms = {(2 * a, 2 * b) for a, b in HEXAGON - {(0, 0)}}
    school = HEXAGON | arms
    assert all(completes_star(site, school) for site in school)


@pytest.mark.parametrize("count", range(1, 31))
def test_the_rule_agrees_with_the_observers_measure(count: int) -> None:
    sites = star_sites(count)
    by_rule = [completes_star(site, set(sites)) for site in sites]
    np.testing.assert_array_equal(by_rule, _observed(_points(sites, 0.25), 0.25))


@pytest.mark.slow
def test_growth_leaves_at_most_two_fish_without_a_star() -> None:
    done = [sum(completes_star(s, set(star_sites(n))) for s in star_sites(n)) for n in range(1, 31)]
    # 1–3 fish make no star; a star needs four.
    assert done[:3] == [0, 0, 0]
    assert all(count - 2 <= stars <= count for count, stars in enumerate(done[3:], start=4))
    # As grown (measured, kept so that a change to the growth shows): every fish of these.
    full = [count for count, stars in enumerate(done, start=1) if stars == count]
    assert full == [4, 6, 8, 10, 14, 15, 19, 20, 24, 25, 29, 30]


def test_fifteen_fish_all_complete_a_star_around_a_hexagon() -> None:
    spacing = 0.25
    slots = star_map(15, spacing=spacing)
    assert slots.shape == (15, 3) and not slots.flags.writeable
    assert _observed(slots, spacing).all()
    np.testing.assert_array_equal(slots[0], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(slots[:, 2], np.zeros(15))
    # Lattice places: no two nearer than a spacing; a fish with six neighbours in the middle.
    gaps = pdist(slots)
    assert gaps.min() == pytest.approx(spacing)
    neighbours = (np.abs(gaps - spacing) < 1e-9).sum()
    assert neighbours == 6 + 6 + 6 + 2  # the centre's, the ring's, the arms', the grown star
    # The leader stands clearly ahead of the rest (0.48 spacings, the most it can), and the
    # others come row by row backwards.
    assert -slots[1:, 0].max() == pytest.approx(0.48 * spacing, abs=0.002 * spacing)
    assert (np.diff(slots[1:, 0]) <= 1e-12).all()


def test_a_map_is_the_same_for_any_spacing_scaled() -> None:
    np.testing.assert_allclose(star_map(12, spacing=0.5), 2 * star_map(12, spacing=0.25))


@pytest.mark.parametrize(("count", "spacing"), [(0, 0.3), (5, 0.0), (5, -1.0), (5, math.inf)])
def test_bad_maps_are_refused(count: int, spacing: float) -> None:
    with pytest.raises(ValueError, match=r"star map|spacing"):
        star_map(count, spacing=spacing)


@pytest.mark.parametrize("count", [4, 10, 15, 20])
def test_every_fish_in_close_packing_completes_a_tetrahedron(count: int) -> None:
    assert _observed(close_packing(count, spacing=0.25), 0.25, "tetrahedron").all()
    # Each lattice is its own shape's: close packing gives few stars, the flat star map no
    # tetrahedron.
    stars = int(_observed(close_packing(count, spacing=0.25), 0.25).sum())
    assert stars == {4: 0, 10: 0, 15: 4, 20: 4}[count]
    assert not _observed(star_map(count, spacing=0.25), 0.25, "tetrahedron").any()


def test_ties_between_mirror_images_go_to_the_first_fish() -> None:
    from fishswarm.formations.lattice import _hull, _lead_and_turn

    # A kite symmetric about the x axis: fish 1 and 2 are mirror images, equally near the
    # others on average; the first of them leads, ahead of the rest by the widest margin.
    kite = np.array([[0.0, 0.0], [1.0, 1.0], [1.0, -1.0], [3.0, 0.0], [1.0, 0.0]])
    assert _hull(kite).tolist() == [0, 1, 2, 3]  # fish 4 is inside
    leader, angle = _lead_and_turn(kite)
    assert leader == 1
    turn = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    turned = (kite - kite[1]) @ turn.T
    np.testing.assert_allclose(turned[1], [0.0, 0.0])
    assert (np.delete(turned, 1, axis=0)[:, 0] < -0.1).all()
    # The same points in another order: the other mirror image comes first and leads.
    assert _lead_and_turn(kite[[0, 2, 1, 3, 4]])[0] == 1


def test_a_point_on_an_edge_of_the_hull_cannot_lead() -> None:
    from fishswarm.formations.lattice import _hull

    # A unit square's corners, the middle of its right edge, and its centre: only the
    # corners stand ahead of all the others in some direction.
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.5], [0.5, 0.5]])
    assert _hull(points).tolist() == [0, 1, 2, 3]
