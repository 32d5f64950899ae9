"""How well a fish completes a local shape with its nearest neighbours, wherever it stands.

A fish completes its local shape (SPEC §5) when it and k of its nearest neighbours make the
shape: after the best rigid motion (no mirror) and matching of the points, every point lies
within the tolerance of its place in the ideal shape — as a fish of a global map lies within
the tolerance of its slot. "Nearest" admits ties: inside a lattice of triangles a fish has six
neighbours at one distance, and any two adjacent ones complete a triangle with it. So the k
may be any of its ``among`` nearest (:data:`NEAREST_CONSIDERED`), as long as no fish left out
is nearer to it than the farthest of them by more than the tolerance: a stranger closer than
the shape's own members spoils the shape.

The observer's metrics judge each fish where it stands (:func:`completion` takes any spots,
so a fish could judge the spots it might go to with the neighbours it sees; holding fish
where they complete a shape was measured and dropped, docs/formations.md). The fish's own
rule uses the fit (:func:`group_errors`) to tell whether neighbours already make part of a
shape. Numpy only: it runs on the robot.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

NEAREST_CONSIDERED = {"triangle": 6, "trigonal-planar": 6, "tetrahedron": 8}
"""How many of its nearest neighbours a fish's local shape may be made with: the ring of six
around a fish in a plane, eight in 3-D."""

_MATCHINGS: dict[str, tuple[tuple[int, ...], ...]] = {
    # Every order of an equilateral triangle's corners is a turn in space.
    "triangle": ((0, 1, 2),),
    # A star's arms trade places by turns too: only which point is the centre matters.
    "trigonal-planar": ((0, 1, 2, 3), (1, 0, 2, 3), (2, 1, 0, 3), (3, 1, 2, 0)),
    # A regular tetrahedron's even orders are turns; one odd order stands for the others.
    "tetrahedron": ((0, 1, 2, 3), (1, 0, 2, 3)),
}


def ideal_local_shape(shape: str, *, spacing: float) -> FloatArray:
    """(k + 1, 3) the points of a local shape: an equilateral triangle, a trigonal-planar
    star (centre and three arms at 120°), or a regular tetrahedron, edges (arms) ``spacing``.

    Raises:
        ValueError: an unknown shape.
    """
    if shape == "triangle":
        return spacing * np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, math.sqrt(3) / 2, 0]])
    if shape == "trigonal-planar":
        arms = [[math.cos(a), math.sin(a), 0.0] for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)]
        return spacing * np.array([[0.0, 0.0, 0.0], *arms])
    if shape == "tetrahedron":
        corners = [[1.0, 1, 1], [1.0, -1, -1], [-1.0, 1, -1], [-1.0, -1, 1]]
        return spacing / (2 * math.sqrt(2)) * np.array(corners)
    raise ValueError(f"no local shape {shape!r}")


def group_errors(
    groups: FloatArray,
    ideal: FloatArray,
    *,
    orders: tuple[tuple[int, ...], ...] | None = None,
) -> tuple[FloatArray, FloatArray]:
    """How far groups of P points (..., P, 3) are from an ideal shape (P, 3) after the best
    rigid motion (no mirror) and matching of points: (...) the RMS distance of the points
    from their places, and (...) the largest, m.

    Each matching in ``orders`` is tried (None: every order of the P points), each with the
    best rotation in closed form (Kabsch, a reflection turned into a rotation); the one with
    the smallest RMS distance wins.
    """
    lead = groups.shape[:-2]
    points = ideal.shape[0]
    flat = groups.reshape(-1, points, 3)
    centred = flat - flat.mean(axis=1, keepdims=True)
    shape = ideal - ideal.mean(axis=0)
    best = np.full(flat.shape[0], np.inf)
    largest = np.full(flat.shape[0], np.inf)
    flip = np.ones((flat.shape[0], 3))
    for order in itertools.permutations(range(points)) if orders is None else orders:
        target = shape[list(order)]
        u, _, vt = np.linalg.svd(np.einsum("gpd,pe->gde", centred, target))
        flip[:, 2] = np.sign(np.linalg.det(u @ vt))
        rotation = np.einsum("gij,gj,gjk->gik", u, flip, vt)  # centred @ rotation ≈ target
        gaps = np.linalg.norm(centred @ rotation - target[None], axis=2)
        rms = np.sqrt(np.mean(gaps**2, axis=1))
        better = rms < best
        best = np.where(better, rms, best)
        largest = np.where(better, gaps.max(axis=1), largest)
    return best.reshape(lead), largest.reshape(lead)


@dataclass(frozen=True)
class Completion:
    """How well fish (at candidate spots) complete a local shape, each (...) m: the largest
    distance of a point of its best group from its place in the ideal shape (inf: no group
    allowed), and that group's RMS distance; and (..., k) which of the other fish make that
    group with it (indices into them; −1: no group)."""

    largest: FloatArray
    rms: FloatArray
    members: NDArray[np.intp]

    def joined(self, tolerance: float) -> BoolArray:
        """Which complete the shape: every point of the group within ``tolerance``."""
        result: BoolArray = self.largest <= tolerance
        return result


def completion(
    spots: FloatArray,
    others: FloatArray,
    mask: BoolArray,
    shape: str,
    *,
    spacing: float,
    tolerance: float,
    among: int | None = None,
) -> Completion:
    """How well each of B fish would complete a local shape at each of S spots.

    Args:
        spots: (B, S, 3) where each fish stands or could stand, m.
        others: (B, K, 3) the other fish it knows of, in the same frame, m.
        mask: (B, K) which rows are real.
        shape: one of :data:`NEAREST_CONSIDERED`.
        spacing: the shape's edge, m.
        tolerance: m; a fish left out of a group may be this much nearer than its farthest
            member.
        among: of how many nearest the group's members are drawn (default per shape).

    Returns:
        (B, S) the best group's largest and RMS distances (the group with the smallest
        largest distance), and (B, S, k) its members among ``others``.
    """
    ideal = ideal_local_shape(shape, spacing=spacing)
    k = ideal.shape[0] - 1
    count, options = spots.shape[:2]
    among = max(k, NEAREST_CONSIDERED[shape] if among is None else among)
    among = max(min(among, others.shape[1]), k)
    gaps = np.linalg.norm(spots[:, :, None, :] - others[:, None, :, :], axis=3)
    gaps = np.where(mask[:, None, :], gaps, np.inf)
    if gaps.shape[2] < among + 1:  # fewer fish than wanted: pad with absent ones
        pad = np.full((count, options, among + 1 - gaps.shape[2]), np.inf)
        gaps = np.concatenate([gaps, pad], axis=2)
        others = np.concatenate([others, np.zeros((count, pad.shape[2], 3))], axis=1)
    order = np.argsort(gaps, axis=2, kind="stable")[:, :, : among + 1]
    distance = np.take_along_axis(gaps, order, axis=2)
    combos = np.array(list(itertools.combinations(range(among), k)), dtype=np.intp)
    # The nearest fish each group leaves out, and its farthest member, by rank.
    left_out = np.array([min(set(range(among + 1)) - set(c)) for c in combos], dtype=np.intp)
    farthest = combos.max(axis=1)
    allowed = np.isfinite(distance[:, :, farthest])
    allowed &= distance[:, :, left_out] >= distance[:, :, farthest] - tolerance  # (B, S, C)
    partners = np.take_along_axis(
        others[:, None, :, :], order[:, :, combos.reshape(-1), None], axis=2
    ).reshape(count, options, len(combos), k, 3)
    here = np.broadcast_to(spots[:, :, None, None, :], (count, options, len(combos), 1, 3))
    groups = np.concatenate([here, np.where(allowed[..., None, None], partners, 0.0)], axis=3)
    rms, largest = group_errors(groups, ideal, orders=_MATCHINGS.get(shape))
    largest = np.where(allowed, largest, np.inf)
    best = np.argmin(largest, axis=2)
    best_largest = np.take_along_axis(largest, best[..., None], axis=2)[..., 0]
    found = np.isfinite(best_largest)
    chosen = np.take_along_axis(order, combos[best].reshape(count, options, k), axis=2)
    return Completion(
        best_largest,
        np.where(found, np.take_along_axis(rms, best[..., None], axis=2)[..., 0], np.inf),
        np.where(found[..., None], chosen, -1),
    )
