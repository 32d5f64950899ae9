"""How good a formation is, from the fish's true positions (metrics that need no eyes).

- the study's fish fitness F = C + min D (SPEC §5), and the school's, its sum;
- the RMS position error after the best rigid alignment of the school to the target and the
  best assignment of fish to slots (rotation by Kabsch/Procrustes, assignment by the
  Hungarian method, alternated from several starting turns), and the fraction of fish then
  within a tolerance of their slot ("joined");
- for a local shape, how well each fish completes it with its nearest neighbours
  (:mod:`fishswarm.formations.groups`), and the sides of the completed shapes;
- the deviation energy of an α-lattice (Olfati-Saber 2006): mean squared deviation of the
  distances between neighbours (pairs closer than 1.2 spacings) from the spacing;
- collisions: pairs closer than one body length.

Base station only (scipy): nothing a robot runs imports this module.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import orthogonal_procrustes
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist, pdist

from fishswarm.bluebot.parameters import BODY_LENGTH
from fishswarm.formations.groups import (
    NEAREST_CONSIDERED,
    Completion,
    completion,
    ideal_local_shape,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

LATTICE_RANGE = 1.2
"""Pairs closer than this many spacings are neighbours in the α-lattice energy."""


def fish_fitness(
    position: FloatArray, targets: FloatArray, *, tolerance: float, crowding_radius: float
) -> FloatArray:
    """The study's fitness F = C + min D of each of N fish (lower is better).

    C = tolerance × the number of other fish within ``crowding_radius`` (two fish on one
    spot are penalised); D = the distance to the nearest free target (no other fish within
    ``tolerance`` of it), or ``tolerance`` when none is free.

    Args:
        position: (N, 3) the fish, m.
        targets: (T, 3) the targets, m (a global map's slots, placed in the tank).
        tolerance: m.
        crowding_radius: m.

    Returns:
        (N,) F of each fish, m.
    """
    apart = cdist(position, position)
    np.fill_diagonal(apart, np.inf)
    crowding = tolerance * (apart < crowding_radius).sum(axis=1)
    reach = cdist(position, targets)  # (N, T)
    count = position.shape[0]
    # A target is free for fish i when no *other* fish is within tolerance of it.
    near = reach < tolerance
    others_near = near.sum(axis=0)[None, :] - near
    free = others_near == 0
    nearest_free = (
        np.where(free, reach, np.inf).min(axis=1) if targets.size else np.full(count, np.inf)
    )
    distance = np.where(np.isfinite(nearest_free), nearest_free, tolerance)
    result: FloatArray = crowding + distance
    return result


def _kabsch(moving: FloatArray, fixed: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotation R and translation t with moving @ R + t closest to ``fixed`` (no mirror)."""
    moving_centre, fixed_centre = moving.mean(axis=0), fixed.mean(axis=0)
    rotation, _ = orthogonal_procrustes(moving - moving_centre, fixed - fixed_centre)
    if np.linalg.det(rotation) < 0:  # a mirror image is not the same formation
        u, _, vt = np.linalg.svd((moving - moving_centre).T @ (fixed - fixed_centre))
        flip = np.diag([1.0, 1.0, -1.0])
        rotation = u @ flip @ vt
    return rotation, fixed_centre - moving_centre @ rotation


@dataclass(frozen=True)
class Alignment:
    """A target shape moved onto a school by the best rigid motion and assignment.

    Attributes:
        slots: (S, 3) where each of the target's S slots lands (in the target's order), in
            the school's frame, m.
        slot_of: (N,) the slot each fish is assigned to (an index into the target's rows;
            −1 for a fish left without one when there are more fish than slots).
        gaps: (N,) each fish's distance from its slot, m (infinite without one).
    """

    slots: FloatArray
    slot_of: IntArray
    gaps: FloatArray

    @property
    def rms(self) -> float:
        """The RMS distance of the fish that have a slot from their slots, m."""
        placed = self.gaps[self.slot_of >= 0]
        return float(np.sqrt(np.mean(placed**2))) if placed.size else 0.0

    def joined(self, tolerance: float) -> BoolArray:
        """(N,) which fish are within ``tolerance`` of their slot (never one without)."""
        result: BoolArray = self.gaps <= tolerance
        return result


def align(position: FloatArray, target: FloatArray, *, starts: int = 12) -> Alignment:
    """The best rigid motion (no mirror) and assignment of S slots to N ≥ S fish.

    The alignment is iterated (assign by the Hungarian method, then turn and shift by
    Kabsch) from ``starts`` turns about the vertical; the smallest RMS distance wins. With
    more fish than slots (a fish that joined a school whose map was made for fewer), the
    slots go to the S fish that fit them best and the others have none; the extra fish pull
    a start centred on the whole school off the shape, so the alignment also starts from
    the target's two farthest slots laid onto pairs of fish as far apart.

    Args:
        position: (N, 3) the fish, m.
        target: (S, 3) the target shape in any frame, m.
        starts: starting turns about the vertical tried.

    Raises:
        ValueError: fewer fish than slots, or no slot.
    """
    count, places = position.shape[0], target.shape[0]
    if places == 0 or count < places:
        raise ValueError(
            f"{count} fish against a target of {places} slots: a target needs a slot, "
            "and a fish for each"
        )
    if count == 1:
        return Alignment(position.copy(), np.zeros(1, dtype=np.int64), np.zeros(1))
    best: Alignment | None = None
    centred = target - target.mean(axis=0)
    placed = [
        _turned(centred, turn) + position.mean(axis=0)
        for turn in np.linspace(0.0, 2 * math.pi, starts, endpoint=False)
    ]
    if count > places:
        placed += _pair_starts(position, target)
    for moved in placed:
        candidate = _refined(position, moved)
        if best is None or candidate.rms < best.rms:
            best = candidate
    assert best is not None
    return best


PAIR_STARTS = 6
"""Most pairs of fish :func:`align` lays the target's two farthest slots onto (those nearest
the slots' distance apart), when there are more fish than slots."""


def _turned(points: FloatArray, turn: float) -> FloatArray:
    """``points`` turned by ``turn`` rad about the vertical (anticlockwise seen from above)."""
    c, s = math.cos(turn), math.sin(turn)
    turned: FloatArray = points @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return turned


def _pair_starts(position: FloatArray, target: FloatArray) -> list[FloatArray]:
    """Starting placements of ``target`` that lay its two farthest slots, a and b, onto a
    pair of fish (p, q) about as far apart: turned about the vertical so that a→b points
    along p→q seen from above, and shifted so that the two midpoints meet. The pairs tried
    are the :data:`PAIR_STARTS` (each way round) whose distance is nearest a–b's."""
    between = cdist(target, target)
    a, b = np.unravel_index(int(np.argmax(between)), between.shape)
    apart = cdist(position, position)
    first, second = np.triu_indices(position.shape[0], k=1)
    misfit = np.abs(apart[first, second] - between[a, b])
    chosen = np.argsort(misfit, kind="stable")[:PAIR_STARTS]
    slot_way = target[b] - target[a]
    slot_angle = math.atan2(slot_way[1], slot_way[0])
    slot_middle = (target[a] + target[b]) / 2
    placed = []
    for p, q in zip(first[chosen].tolist(), second[chosen].tolist(), strict=True):
        for start, end in ((p, q), (q, p)):
            fish_way = position[end] - position[start]
            turn = math.atan2(fish_way[1], fish_way[0]) - slot_angle
            middle = (position[start] + position[end]) / 2
            placed.append(_turned(target - slot_middle, turn) + middle)
    return placed


def _refined(position: FloatArray, moved: FloatArray) -> Alignment:
    """From the slots placed at ``moved``: assign fish to slots by the Hungarian method and
    move the slots onto their fish by Kabsch, until the slots stay put (at most 20 times)."""
    for _ in range(20):
        rows, columns = linear_sum_assignment(cdist(position, moved))
        rotation, shift = _kabsch(moved[columns], position[rows])
        aligned = moved @ rotation + shift
        if np.allclose(aligned, moved, atol=1e-12):
            break
        moved = aligned
    rows, columns = linear_sum_assignment(cdist(position, moved))
    slot_of = np.full(position.shape[0], -1, dtype=np.int64)
    slot_of[rows] = columns
    gaps = np.full(position.shape[0], np.inf)
    gaps[rows] = np.linalg.norm(position[rows] - moved[columns], axis=1)
    return Alignment(moved, slot_of, gaps)


def shape_error(
    position: FloatArray, target: FloatArray, *, tolerance: float, starts: int = 12
) -> tuple[float, float]:
    """RMS distance of N fish from S ≤ N slots after the best rigid motion and assignment
    (:func:`align`; over the fish that have a slot), and the fraction of the N fish then
    within ``tolerance`` of their slot.

    Args:
        position: (N, 3) the fish, m.
        target: (S, 3) the target shape in any frame, m.
        tolerance: a fish this close to its slot has joined, m.
        starts: starting turns about the vertical tried.
    """
    return shape_summary(align(position, target, starts=starts), tolerance)


def local_shape_errors(
    position: FloatArray, shape: str, *, spacing: float, tolerance: float
) -> Completion:
    """How well each of N fish completes its local shape where it is
    (:func:`fishswarm.formations.groups.completion`): (N,) the largest and the RMS distance
    of its best group from the ideal shape, m, and (N, k) the fish it makes that group with
    (NaN and −1 for all when there are no more than k fish). Each fish is judged with its
    nearest few (a k-d tree finds them), so a school of thousands costs thousands of small
    fits, not a table of every pair."""
    count = position.shape[0]
    if count <= ideal_local_shape(shape, spacing=spacing).shape[0] - 1:
        k = ideal_local_shape(shape, spacing=spacing).shape[0] - 1
        return Completion(
            np.full(count, math.nan), np.full(count, math.nan), np.full((count, k), -1)
        )
    wanted = min(NEAREST_CONSIDERED[shape] + 2, count)  # itself, its candidates, one left out
    _, nearest = cKDTree(position).query(position, k=wanted)
    others = position[nearest[:, 1:]]
    mask = np.ones(others.shape[:2], dtype=np.bool_)
    fit = completion(
        position[:, None, :], others, mask, shape, spacing=spacing, tolerance=tolerance
    )
    members = np.take_along_axis(nearest[:, 1:], np.maximum(fit.members[:, 0], 0), axis=1)
    return Completion(
        fit.largest[:, 0], fit.rms[:, 0], np.where(fit.members[:, 0] >= 0, members, -1)
    )


def shape_edges(
    fit: Completion, tolerance: float, *, position: FloatArray, spacing: float
) -> NDArray[np.intp]:
    """(E, 2) the bonds of completed local shapes (each pair once, the lower index first):
    the edges a picture draws. A bond joins two fish of a completed shape that stand about a
    spacing apart — every pair of a triangle or a tetrahedron, the centre and each arm of a
    star, not two arms (√3 spacings apart): pairs nearer than halfway between the two,
    (1 + √3)/2 spacings.

    Args:
        fit: how each fish completes its shape (:func:`local_shape_errors`).
        tolerance: m.
        position: (N, 3) the fish, m.
        spacing: the shape's edge, m.
    """
    joined = np.flatnonzero(fit.joined(tolerance))
    if joined.size == 0 or fit.members.shape[1] == 0:
        return np.zeros((0, 2), dtype=np.intp)
    groups = np.concatenate([joined[:, None], fit.members[joined]], axis=1)
    pairs = np.array(list(itertools.combinations(range(groups.shape[1]), 2)), dtype=np.intp)
    edges = np.sort(groups[:, pairs].reshape(-1, 2), axis=1)
    length = np.linalg.norm(position[edges[:, 0]] - position[edges[:, 1]], axis=1)
    bonds = edges[length < spacing * (1 + math.sqrt(3)) / 2]
    unique: NDArray[np.intp] = np.unique(bonds, axis=0).reshape(-1, 2)
    return unique


def local_shape_error(
    position: FloatArray, shape: str, *, spacing: float, tolerance: float
) -> tuple[float, float]:
    """How well every fish completes its local shape with its nearest neighbours: the mean
    over fish of their best group's RMS distance from the ideal shape (:func:`local_shape_errors`),
    m, and the fraction of fish whose group lies within ``tolerance`` point by point."""
    fit = local_shape_errors(position, shape, spacing=spacing, tolerance=tolerance)
    return shape_summary(fit, tolerance)


def shape_summary(fit: Alignment | Completion, tolerance: float) -> tuple[float, float]:
    """A school's fit to its formation in two numbers: the RMS error, m (a global map's
    alignment, :func:`align`, over the fish that have a slot; for a local shape,
    :func:`local_shape_errors`, the mean of the fish's RMS errors), and the fraction of
    fish that have joined (of all of them: a fish without a slot has not)."""
    if isinstance(fit, Alignment):
        return fit.rms, float(np.mean(fit.joined(tolerance)))
    if fit.rms.size == 0 or np.isnan(fit.rms).all():
        return math.nan, 0.0
    return float(np.mean(fit.rms)), float(np.mean(fit.joined(tolerance)))


def deviation_energy(position: FloatArray, *, spacing: float) -> float:
    """Olfati-Saber's α-lattice deviation energy, normalised by spacing²: the mean squared
    relative deviation of neighbour distances (pairs within 1.2 spacings) from the spacing;
    0 for a perfect lattice; 1 when no pair is near (nobody has a neighbour)."""
    distances = pdist(position)
    near = distances < LATTICE_RANGE * spacing
    if not near.any():
        return 1.0
    return float(np.mean(((distances[near] - spacing) / spacing) ** 2))


def collisions(position: FloatArray, *, distance: float = BODY_LENGTH) -> int:
    """Pairs of fish closer than ``distance`` (one body length by default)."""
    return int((pdist(position) < distance).sum()) if position.shape[0] > 1 else 0
