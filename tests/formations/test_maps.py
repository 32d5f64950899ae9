"""Target maps, checked against coordinates drawn on paper."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.distance import pdist

from fishswarm.formations.maps import MAPS, THREE_D, target_map

H = math.sqrt(3) / 2  # row gap of the triangular lattice, in spacings

# Drawn on paper with l = 1: x forward, y right; rows from the middle out, left first.
PYRAMID_15 = [
    (0, 0),
    (-H, -0.5), (-H, 0.5),
    (-2 * H, 0), (-2 * H, -1), (-2 * H, 1),
    (-3 * H, -0.5), (-3 * H, 0.5), (-3 * H, -1.5), (-3 * H, 1.5),
    (-4 * H, 0), (-4 * H, -1), (-4 * H, 1), (-4 * H, -2), (-4 * H, 2),
]  # fmt: skip
FIBONACCI_15 = [
    (0, 0),
    (-1, 0),
    (-2, -0.5), (-2, 0.5),
    (-3, 0), (-3, -1), (-3, 1),
    (-4, 0), (-4, -1), (-4, 1), (-4, -2), (-4, 2),
    (-5, -0.5), (-5, 0.5), (-5, -1.5),
]  # fmt: skip


@pytest.mark.parametrize(("name", "drawn"), [("pyramid", PYRAMID_15), ("fibonacci", FIBONACCI_15)])
@pytest.mark.parametrize("count", range(1, 16))
def test_flat_maps_equal_the_drawing(
    name: str, drawn: list[tuple[float, float]], count: int
) -> None:
    spacing = 0.3
    expected = np.array([(x, y, 0.0) for x, y in drawn[:count]]) * spacing
    np.testing.assert_allclose(target_map(name, count, spacing=spacing), expected, atol=1e-12)


def test_three_d_maps_drawn_on_paper() -> None:
    # Tetrahedron, l = 1: the apex, then a triangle of 3 one layer (√(2/3)) behind, centred
    # on the axis, at distance 1/√3 from it: a regular tetrahedron with edges 1.
    tetrahedron = target_map("tetrahedral-pyramid", 4, spacing=1.0)
    layer = math.sqrt(2 / 3)
    np.testing.assert_allclose(tetrahedron[1:, 0], [-layer] * 3, atol=1e-12)
    np.testing.assert_allclose(np.hypot(tetrahedron[1:, 1], tetrahedron[1:, 2]), [3**-0.5] * 3)
    np.testing.assert_allclose(pdist(tetrahedron), [1.0] * 6, atol=1e-12)
    # Diamond, 6 fish: an octahedron of edge 1 — the tip, a square, the tail.
    diamond = target_map("diamond", 6, spacing=1.0)
    s = 1 / math.sqrt(2)
    expected = [(0, 0, 0), (-s, -s, 0), (-s, s, 0), (-s, 0, -s), (-s, 0, s), (-2 * s, 0, 0)]
    np.testing.assert_allclose(diamond, expected, atol=1e-12)
    # Phalanx, 4 fish: a 2 × 2 wall abreast, the leader's slot at the origin.
    phalanx = target_map("phalanx", 4, spacing=1.0)
    np.testing.assert_allclose(phalanx[:, 0], [0.0] * 4)
    assert sorted(map(tuple, phalanx[:, 1:].round(12).tolist())) == [
        (0.0, 0.0), (0.0, 1.0), (1.0, 0.0), (1.0, 1.0),
    ]  # fmt: skip
    np.testing.assert_allclose(target_map("column", 3, spacing=0.5)[:, 0], [0, -0.5, -1.0])


@given(st.sampled_from(sorted(MAPS)), st.integers(2, 60), st.floats(0.05, 2.0))
def test_every_map_keeps_nearest_slots_one_spacing_apart(
    name: str, count: int, spacing: float
) -> None:
    slots = target_map(name, count, spacing=spacing)
    assert slots.shape == (count, 3)
    assert np.array_equal(slots[0], np.zeros(3))  # the leader's slot
    assert pdist(slots).min() == pytest.approx(spacing, rel=1e-9)
    if name != "phalanx":  # the wall's width depends on how many fish it holds
        np.testing.assert_allclose(target_map(name, count + 5, spacing=spacing)[:count], slots)
    if count >= 4:  # a 3-D map of 2 or 3 fish may still lie in a plane
        assert (slots[:, 2] == 0).all() == (name not in THREE_D)


def test_bad_maps_are_explained() -> None:
    with pytest.raises(ValueError, match="must be one of fibonacci, pyramid"):
        target_map("circle", 5, spacing=1.0)
    with pytest.raises(ValueError, match="1 to 10000 fish"):
        target_map("pyramid", 0, spacing=1.0)
    with pytest.raises(ValueError, match="1 to 10000 fish, got 10001"):
        target_map("column", 10_001, spacing=1.0)
    assert target_map("column", 10_000, spacing=0.3).shape == (10_000, 3)  # the largest
    with pytest.raises(ValueError, match="positive length"):
        target_map("pyramid", 5, spacing=-1.0)


def test_a_phalanx_fills_its_square_from_the_top_row_left_first() -> None:
    from fishswarm.formations.maps import phalanx

    # Four fish: a 2 × 2 wall, all corners equally far from the middle; the upper row
    # (z up is −z) first, left (−y) before right in each row.
    slots = phalanx(4, spacing=1.0)
    assert slots.tolist() == [
        [0.0, -0.5, -0.5], [0.0, 0.5, -0.5], [0.0, -0.5, 0.5], [0.0, 0.5, 0.5],
    ]  # fmt: skip
