"""Local shapes: the spots that complete a shape with a fish's k nearest visible neighbours.

Each function takes, for B fish, the body-frame positions of their nearest neighbours and
returns candidate spots (B, S, 3) in the same frame, with a mask of the spots that exist.
A fish then picks one with :func:`fishswarm.formations.rules.choose_spot`. Spacing l is the
shape's edge (SPEC §5):

- **triangle** (k = 2): the two points at distance l from both neighbours, in the
  horizontal plane through their mean depth — the apexes of the two triangles on their
  segment (equilateral when the neighbours are l apart);
- **trigonal planar** (k = 3): one centre and three around it at 120°, radius l, in the
  horizontal plane: the spot opposite the bisector of two outer neighbours around the centre
  (the neighbour nearest to the other two), or the centre itself (the neighbours' centroid);
- **tetrahedron** (k = 3, 3-D): the two apexes of the regular tetrahedron on the triangle of
  the three neighbours, on either side of its plane.

A fish first tries the spots its k nearest give; for a triangle it then tries those its nearest
neighbour gives with each other of its nearest few (:data:`CANDIDATE_NEIGHBOURS`) that already
stands about a spacing from it (:data:`EDGE_SLACK`). Inside a lattice of triangles the two
nearest of a fish's six equidistant neighbours need not be adjacent, and their spots then lie
on other fish; an adjacent pair's spot is where it already is.

Unlike the study's code (which built triangle spots for a triangle of side 2l and passed the
first neighbour twice), the spots here are at distance l from the neighbours they complete.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numpy.typing import NDArray

from fishswarm.formations.groups import group_errors, ideal_local_shape

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

LOCAL_SHAPES = {"triangle": 2, "trigonal-planar": 3, "tetrahedron": 3}
"""Every local shape and how many nearest neighbours it is made with (k)."""

CANDIDATE_NEIGHBOURS = {"triangle": 4, "trigonal-planar": 3, "tetrahedron": 3}
"""Of how many nearest neighbours a fish builds candidate spots. Measured (batch engine, 15
fish, spacing 0.25 m, tolerance 0.0625 m, 2 Hz, flags, 30 s, seeds 0–19): a triangle's
fish reached 90 % joined in 18 of 20 runs with 4, 12 with 3, 18 with 6 (but 85 % joined
at 30 s on average against 91 %), 11 with the two nearest only. For trigonal-planar stars
4 changed nothing (0 % joined at 30 s, seeds 0–9); tetrahedra did worse (25 % against 33 %)."""
EDGE_SLACK = 0.5
"""Neighbours other than the k nearest offer spots only when they already make part of the
shape to within this fraction of the spacing (for a triangle: stand l ± l/2 apart)."""

_TINY = 1e-9
_GROUP_RANK = 1e6


def nearest_neighbors(
    neighbors: FloatArray, mask: BoolArray, k: int
) -> tuple[FloatArray, BoolArray]:
    """Each fish's k nearest visible neighbours, nearest first.

    Args:
        neighbors: (B, K, 3) visible neighbours in the body frame, m.
        mask: (B, K) which rows are real.
        k: how many.

    Returns:
        (B, k, 3) positions (zero where a fish sees fewer than k) and (B, k) which are real.
    """
    count = neighbors.shape[0]
    if neighbors.shape[1] == 0:
        return np.zeros((count, k, 3)), np.zeros((count, k), dtype=np.bool_)
    distance = np.where(mask, np.einsum("bkd,bkd->bk", neighbors, neighbors), np.inf)
    order = np.argsort(distance, axis=1, kind="stable")[:, :k]
    rows = np.arange(count)[:, None]
    chosen = neighbors[rows, order]
    real = mask[rows, order]
    if chosen.shape[1] < k:
        pad = k - chosen.shape[1]
        chosen = np.concatenate([chosen, np.zeros((count, pad, 3))], axis=1)
        real = np.concatenate([real, np.zeros((count, pad), dtype=np.bool_)], axis=1)
    chosen = np.where(real[..., None], chosen, 0.0)
    return chosen, real


def _horizontal_unit(vector: FloatArray) -> FloatArray:
    """(B, 3) horizontal unit vectors; +y where a vector has no horizontal part."""
    flat = vector.copy()
    flat[:, 2] = 0.0
    length = np.linalg.norm(flat, axis=1)
    fallback = np.tile([0.0, 1.0, 0.0], (vector.shape[0], 1))
    unit: FloatArray = np.where(
        (length > _TINY)[:, None], flat / np.maximum(length, _TINY)[:, None], fallback
    )
    return unit


def triangle_spots(first: FloatArray, second: FloatArray, *, spacing: float) -> FloatArray:
    """(B, 2, 3) the two apexes at distance ``spacing`` from both neighbours (or, when the
    neighbours are more than 2·spacing apart, their midpoint twice)."""
    middle = (first + second) / 2
    along = second - first
    along[:, 2] = 0.0
    half = np.linalg.norm(along, axis=1) / 2
    across = _horizontal_unit(np.stack([-along[:, 1], along[:, 0], np.zeros(len(along))], axis=1))
    height = np.sqrt(np.maximum(spacing**2 - half**2, 0.0))[:, None]
    return np.stack([middle + height * across, middle - height * across], axis=1)


def trigonal_planar_spots(
    first: FloatArray, second: FloatArray, third: FloatArray, *, spacing: float
) -> tuple[FloatArray, BoolArray]:
    """(B, 2, 3) the outer spot that completes a trigonal-planar shape around the centre
    neighbour, and the centre spot (the neighbours' centroid at their mean depth), with
    (B, 2) which applies: the outer spot when the neighbour nearest to the other two sees
    them more than 90° apart (it is a centre), the centre spot otherwise."""
    group = np.stack([first, second, third], axis=1)
    pairwise = np.linalg.norm(group[:, :, None, :] - group[:, None, :, :], axis=3)
    centre_index = np.argmin(pairwise.sum(axis=2), axis=1)
    rows = np.arange(group.shape[0])
    centre = group[rows, centre_index]
    outer_index = np.array([[1, 2], [0, 2], [0, 1]])[centre_index]
    outer = group[rows[:, None], outer_index]
    bisector = _horizontal_unit(outer[:, 0] - centre) + _horizontal_unit(outer[:, 1] - centre)
    direction = _horizontal_unit(-bisector)
    outer_spot = centre + spacing * direction
    outer_spot[:, 2] = group[:, :, 2].mean(axis=1)
    centre_spot = group.mean(axis=1)
    apart = np.einsum("bd,bd->b", outer[:, 0] - centre, outer[:, 1] - centre) < 0.0
    return np.stack([outer_spot, centre_spot], axis=1), np.stack([apart, ~apart], axis=1)


def tetrahedron_spots(
    first: FloatArray, second: FloatArray, third: FloatArray, *, spacing: float
) -> FloatArray:
    """(B, 2, 3) the apexes of the regular tetrahedron on the neighbours' triangle, above
    and below its plane, ``spacing``·√(2/3) from its centroid."""
    centroid = (first + second + third) / 3
    normal = np.cross(second - first, third - first)
    length = np.linalg.norm(normal, axis=1)
    # Neighbours in a line have no plane: stand the apex straight up and down.
    fallback = np.tile([0.0, 0.0, 1.0], (first.shape[0], 1))
    unit = np.where(
        (length > _TINY)[:, None], normal / np.maximum(length, _TINY)[:, None], fallback
    )
    height = spacing * math.sqrt(2.0 / 3.0)
    return np.stack([centroid + height * unit, centroid - height * unit], axis=1)


def _shape_spots(
    shape: str, parts: list[FloatArray], *, spacing: float
) -> tuple[FloatArray, BoolArray]:
    """(B, 2, 3) the spots completing ``shape`` with k neighbours (``parts``, each (B, 3))
    and (B, 2) which apply."""
    if shape == "triangle":
        return triangle_spots(parts[0], parts[1], spacing=spacing), np.ones(
            (parts[0].shape[0], 2), dtype=np.bool_
        )
    if shape == "trigonal-planar":
        return trigonal_planar_spots(parts[0], parts[1], parts[2], spacing=spacing)
    spots = tetrahedron_spots(parts[0], parts[1], parts[2], spacing=spacing)
    return spots, np.ones((parts[0].shape[0], 2), dtype=np.bool_)


def _partial_error(parts: list[FloatArray], shape: str, *, spacing: float) -> FloatArray:
    """(B,) how far k neighbours are from making k points of the shape (the fish's point
    left out, whichever it is), m: the largest distance of one from its place."""
    ideal = ideal_local_shape(shape, spacing=spacing)
    group = np.stack(parts, axis=1)
    best = np.full(group.shape[0], np.inf)
    for left in range(ideal.shape[0]):
        rest = np.delete(ideal, left, axis=0)
        best = np.minimum(best, group_errors(group, rest)[1])
    return best


def local_spots(
    shape: str,
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    spacing: float,
    among: int | None = None,
) -> tuple[FloatArray, BoolArray, FloatArray]:
    """The candidate spots of B fish for a local shape, and the order a fish tries them in.

    Args:
        shape: one of :data:`LOCAL_SHAPES`.
        neighbors: (B, K, 3) visible neighbours in the body frame, m.
        mask: (B, K) which rows are real.
        spacing: the shape's edge, m.
        among: of how many nearest neighbours the spots are built
            (:data:`CANDIDATE_NEIGHBOURS` by default; at least k).

    Returns:
        (B, S, 3) spots in the body frame, (B, S) which exist, and (B, S) the order to try
        them in (lower first): first the (up to) two spots the k nearest give
        (:func:`nearest_neighbors`: they are the shape, not rivals for its spots), then
        those of groups of the nearest neighbour and others of the ``among`` nearest that
        already make part of the shape (:data:`EDGE_SLACK`), each group's spots nearest
        first (one group alone keeps the order its spots are drawn in). A fish that sees
        fewer than k neighbours has none.
    """
    k = LOCAL_SHAPES.get(shape)
    if k is None:
        raise ValueError(f"local shape must be one of {', '.join(LOCAL_SHAPES)}, got {shape!r}")
    among = max(k, CANDIDATE_NEIGHBOURS[shape] if among is None else among)
    near, real = nearest_neighbors(neighbors, mask, among)
    nearest = tuple(range(k))
    groups = [nearest] + [
        g for g in itertools.combinations(range(among), k) if g[0] == 0 and g != nearest
    ]
    spots: list[FloatArray] = []
    valid: list[BoolArray] = []
    preference: list[FloatArray] = []
    for index, group in enumerate(groups):
        parts = [near[:, n] for n in group]
        exists = np.logical_and.reduce([real[:, n] for n in group])
        if group != nearest:
            exists &= _partial_error(parts, shape, spacing=spacing) <= EDGE_SLACK * spacing / 2
        found, applies = _shape_spots(shape, parts, spacing=spacing)
        if len(groups) > 1:
            # Each group's spots nearest first, so that a spot's index names the same spot
            # from one decision to the next among many groups (a fish that nears its spot
            # keeps its index: 18 of 20 triangle runs at 90 % joined against 13 with the
            # spots in their drawn order). A single group keeps the drawn order, as before:
            # sorting changed nothing for stars and tetrahedra but their trajectories.
            distance = np.where(applies, np.linalg.norm(found, axis=2), np.inf)
            order = np.argsort(distance, axis=1, kind="stable")
            found = np.take_along_axis(found, order[..., None], axis=1)
            applies = np.take_along_axis(applies, order, axis=1)
        spots.append(found)
        valid.append(applies & exists[:, None])
        # Spots of an earlier group first; within a group, the nearer first (a group's
        # rank, a million spacings, outweighs any distance a fish can see).
        preference.append(index * _GROUP_RANK * spacing + np.linalg.norm(found, axis=2))
    return (
        np.concatenate(spots, axis=1),
        np.concatenate(valid, axis=1),
        np.concatenate(preference, axis=1),
    )
