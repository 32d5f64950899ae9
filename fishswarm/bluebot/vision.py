"""What each BlueBot sees: range, blind spot and occlusion, for a whole swarm at once.

SPEC.md §1.2. Given the positions and yaws of N fish, :func:`visible` decides which of the
others each fish sees, and :func:`perceive` returns those neighbours as body-frame positions
padded into a (N, K, 3) array with a (N, K) mask. Cosines are clamped into [−1, 1] and
coincident fish are handled: nothing divides by a zero distance.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import BLIND_WIDTH, SPHERE_RADIUS, VISUAL_RANGE

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Vision:
    """Parameters of the vision model.

    Attributes:
        visual_range: neighbours farther than this are not seen, m (default 3).
        blind_width: width of the blind strip behind the body, m (0.05 for a BlueBot; 0 sees
            everything; ≥ the tank diagonal leaves a 180° forward field of view).
        sphere_radius: radius of the blocking sphere of every robot, m (0.065 for a BlueBot;
            0 means no occlusion).
        noise: standard deviation of the position noise per metre of distance (0 = none).
        manhattan: a neighbour is in range when |dx| + |dy| + |dz| ≤ ``visual_range``, as in
            the study's code (SPEC §8), instead of its straight-line distance (links between
            fish only: landmarks are seen within the straight-line range).
    """

    visual_range: float = VISUAL_RANGE
    blind_width: float = BLIND_WIDTH
    sphere_radius: float = SPHERE_RADIUS
    noise: float = 0.0
    manhattan: bool = False

    def __post_init__(self) -> None:
        for name in ("visual_range", "blind_width", "sphere_radius", "noise"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"vision {name} must be a finite non-negative number, got {value}")

    def exact(self) -> Vision:
        """This vision without its position noise: who sees whom, and where they truly are."""
        return dataclasses.replace(self, noise=0.0)


def to_body(vectors: FloatArray, yaw: FloatArray) -> FloatArray:
    """Rotate tank-frame vectors into each fish's body frame.

    Args:
        vectors: (B, ..., 3) tank-frame vectors, one group per fish.
        yaw: (B,) yaw of each fish, rad.

    Returns:
        (B, ..., 3) the same vectors in the body frames (x forward, y right, z down).
    """
    extra = (1,) * (vectors.ndim - 2)
    cos = np.cos(yaw).reshape((-1, *extra))
    sin = np.sin(yaw).reshape((-1, *extra))
    out = np.empty_like(vectors)
    out[..., 0] = cos * vectors[..., 0] + sin * vectors[..., 1]
    out[..., 1] = -sin * vectors[..., 0] + cos * vectors[..., 1]
    out[..., 2] = vectors[..., 2]
    return out


def in_blind_spot(relative: FloatArray, yaw: FloatArray, *, blind_width: float) -> BoolArray:
    """Whether each relative position lies in the blind strip behind its fish.

    Args:
        relative: (B, K, 3) tank-frame positions of others relative to each fish, m.
        yaw: (B,) yaw of each fish, rad.
        blind_width: width w of the strip, m.

    Returns:
        (B, K) True where the other lies behind (angle to the heading > π/2 in the horizontal
        plane) and less than w/2 from the heading line.
    """
    heading_x = np.cos(yaw)[:, None]
    heading_y = np.sin(yaw)[:, None]
    along = heading_x * relative[..., 0] + heading_y * relative[..., 1]
    lateral = heading_x * relative[..., 1] - heading_y * relative[..., 0]
    hidden: BoolArray = (along < 0.0) & (np.abs(lateral) < blind_width / 2)
    return hidden


OCCLUSION_BLOCK = 2**25
"""The most cosines (fish × candidates²) occlusion holds at once: 256 MB of them."""


def _occlusion(
    directions: FloatArray, distance: FloatArray, candidate: BoolArray, *, sphere_radius: float
) -> BoolArray:
    """Walk candidates from near to far; hide one behind a nearer visible blocking sphere.

    Args:
        directions: (B, K, 3) unit vectors to the candidates (zero for coincident ones),
            sorted by distance along K.
        distance: (B, K) distances, ascending along K.
        candidate: (B, K) which entries are real candidates.
        sphere_radius: blocking sphere radius r, m.

    Returns:
        (B, K) which candidates are visible.
    """
    visible = candidate.copy()
    count, width = candidate.shape
    if sphere_radius <= 0 or width < 2:
        return visible
    block = max(1, OCCLUSION_BLOCK // (width * width))
    if count > block:
        # Fish by fish in blocks: every fish of a crowded tank sees every other, and the
        # cosines of all at once would not fit in memory (60 GB at 2 000 fish). Each fish's
        # cosines are its own product, so the blocks give the same bits as one batch.
        for start in range(0, count, block):
            rows = slice(start, start + block)
            visible[rows] = _occlusion(
                directions[rows], distance[rows], candidate[rows], sphere_radius=sphere_radius
            )
        return visible
    # Cosines are only compared, never fed to arccos, so rounding past ±1 is harmless.
    cosine = directions @ directions.transpose(0, 2, 1)
    # A blocker at distance a hides whatever lies within atan(r/a) of its direction, that is
    # where cos(angle) > cos(atan(r/a)) = a/√(a² + r²) (comparing cosines avoids arccos). A
    # blocker at distance 0 sits on the observer and has no direction: it hides nothing
    # (its threshold 0 is not exceeded, its direction vector being zero).
    with np.errstate(invalid="ignore"):
        limit = distance / np.sqrt(distance**2 + sphere_radius**2)
    limit[(distance == 0) | ~np.isfinite(distance)] = 1.0
    for k in range(1, candidate.shape[1]):
        blocked = visible[:, :k] & (cosine[:, k, :k] > limit[:, :k])
        visible[:, k] &= ~blocked.any(axis=1)
    return visible


class Stacked(NamedTuple):
    """The seen rows of B fish stacked fish after fish, as a perception batch carries them.

    Attributes:
        counts: (B,) how many rows are each fish's.
        rows: (sum of counts, 3) the rows, fish after fish, each fish's in its padded order.
    """

    counts: NDArray[np.int64]
    rows: FloatArray


@dataclass(frozen=True)
class Perceived:
    """Neighbours seen by each of B fish, padded to K.

    Attributes:
        neighbors: (B, K, 3) body-frame positions, m; rows beyond a fish's count are zero.
        mask: (B, K) which rows are real.
        index: (B, K) index of the seen fish in the input arrays (−1 in padding); known to the
            simulator only, never sent to a fish.
        stacked: the rows of ``neighbors`` that ``mask`` marks, stacked, when the one who
            computed them had them at hand (the compiled vision); None: not made.
    """

    neighbors: FloatArray
    mask: BoolArray
    index: NDArray[np.intp]
    stacked: Stacked | None = dataclasses.field(default=None, repr=False, compare=False)

    @functools.cached_property
    def counts(self) -> NDArray[np.int64]:
        """(B,) how many neighbours each fish sees."""
        if self.stacked is not None:  # counted as they were stacked (0.3 ms at 10 000 fish)
            return self.stacked.counts
        counts: NDArray[np.int64] = self.mask.sum(axis=1).astype(np.int64)
        return counts

    def of(self, fish: int) -> FloatArray:
        """(k, 3) the neighbours fish ``fish`` (a batch index) sees."""
        rows: FloatArray = self.neighbors[fish, self.mask[fish]]
        return rows


KD_TREE_MIN_FISH = 200
"""From this many fish on, neighbours in range are found with a KD-tree instead of all pairs."""


def _in_range(position: FloatArray, visual_range: float) -> tuple[NDArray[np.intp], FloatArray]:
    """Every fish's others within range, nearest first, padded.

    Returns:
        index (N, K) of the others (−1 in padding) and their distances (N, K) (inf in padding).
    """
    count = position.shape[0]
    if count >= KD_TREE_MIN_FISH:
        # Imported here: a robot's own vision never needs it, and a Pi Zero has no scipy.
        from scipy.spatial import cKDTree

        tree = cKDTree(position)
        k = min(count, 64)
        while True:
            # The tree keeps only distances strictly below its bound; a neighbour exactly at
            # the range is in range, as in the all-pairs branch.
            bound = np.nextafter(visual_range, np.inf)
            distance, index = tree.query(position, k=k, distance_upper_bound=bound)
            if k == count or not np.isfinite(distance[:, -1]).any():
                break
            k = min(count, 2 * k)
        index = np.where(np.isfinite(distance), index, -1)
        # Column 0 is normally the fish itself; with coincident fish it may be another one.
        own = index == np.arange(count)[:, None]
        distance = np.where(own, np.inf, distance)
        index = np.where(own, -1, index)
        # Nearest first, ties by index (as the all-pairs branch orders them): the tree
        # returns tied neighbours in an order of its own.
        order = np.lexsort((np.where(index < 0, count, index), distance), axis=1)
        distance = np.take_along_axis(distance, order, axis=1)
        index = np.take_along_axis(index, order, axis=1)
    else:
        relative = position[None, :, :] - position[:, None, :]
        all_distance = np.sqrt(np.einsum("ijd,ijd->ij", relative, relative))
        np.fill_diagonal(all_distance, np.inf)
        all_distance[all_distance > visual_range] = np.inf
        index = np.argsort(all_distance, axis=1, kind="stable")
        distance = np.take_along_axis(all_distance, index, axis=1)
        index = np.where(np.isfinite(distance), index, -1)
    width = int(np.isfinite(distance).sum(axis=1).max(initial=0))
    return index[:, :width], distance[:, :width]


Sifted = tuple[BoolArray, NDArray[np.intp], FloatArray, FloatArray]
"""What :func:`sift` returns: seen (N, K'), the seen fish's indices (N, K'), their tank-frame
positions relative to each fish (N, K', 3, m) and their distances (N, K', m), visible ones
first and near to far; K' the most any fish sees. Rows past a fish's count are not defined."""


class VisionKernels(Protocol):
    """Another implementation of the three costly steps of :func:`perceive`."""

    def in_range(
        self, position: FloatArray, visual_range: float
    ) -> tuple[NDArray[np.intp], FloatArray]:
        """Every fish's others within range, nearest first: index (N, K) (−1 in padding)
        and distance (N, K) (inf in padding)."""
        ...

    def sift(
        self,
        position: FloatArray,
        yaw: FloatArray,
        index: NDArray[np.intp],
        distance: FloatArray,
        *,
        vision: Vision,
    ) -> Sifted:
        """As :func:`sift`."""
        ...

    def body_frame(
        self, relative: FloatArray, yaw: FloatArray, seen: BoolArray
    ) -> tuple[FloatArray, Stacked]:
        """The rows ``seen`` of ``relative`` (B, K, 3) rotated into each fish's body frame
        (:func:`to_body`), zero elsewhere; and the same rotated rows stacked."""
        ...


def sift(
    position: FloatArray,
    yaw: FloatArray,
    index: NDArray[np.intp],
    distance: FloatArray,
    *,
    vision: Vision,
) -> Sifted:
    """Which of the fish in range each fish sees: Manhattan links (if asked), blind spot and
    occlusion, compacted near to far.

    Args:
        position: (N, 3) tank-frame positions, m.
        yaw: (N,) yaws, rad.
        index: (N, K) the others in range of each fish, nearest first (−1 in padding).
        distance: (N, K) their distances, m (inf in padding).
        vision: the vision parameters.
    """
    candidate = index >= 0
    safe_index = np.where(candidate, index, 0)
    relative = position[safe_index] - position[:, None, :]
    if vision.manhattan:  # never farther than the straight line: a subset of those in range
        candidate &= np.abs(relative).sum(axis=2) <= vision.visual_range
    if vision.blind_width > 0:
        candidate &= ~in_blind_spot(relative, yaw, blind_width=vision.blind_width)
    distance = np.where(candidate, distance, np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        directions = np.where(
            (distance > 0)[..., None] & candidate[..., None], relative / distance[..., None], 0.0
        )
    seen = _occlusion(directions, distance, candidate, sphere_radius=vision.sphere_radius)
    # Compact the visible ones to the front, keeping near-to-far order.
    compact = np.argsort(~seen, axis=1, kind="stable")
    seen = np.take_along_axis(seen, compact, axis=1)
    keep = int(seen.sum(axis=1).max(initial=0))
    seen = seen[:, :keep]
    compact = compact[:, :keep]
    chosen = np.take_along_axis(safe_index, compact, axis=1)
    relative_seen = np.take_along_axis(relative, compact[..., None], axis=1)
    distance_seen = np.take_along_axis(distance, compact, axis=1)
    return seen, chosen, relative_seen, distance_seen


def perceive(
    position: FloatArray,
    yaw: FloatArray,
    *,
    vision: Vision,
    rngs: Sequence[np.random.Generator] | None = None,
    kernels: VisionKernels | None = None,
) -> Perceived:
    """Compute what every fish sees of the others.

    Args:
        position: (N, 3) tank-frame positions, m.
        yaw: (N,) yaws, rad.
        vision: the vision parameters.
        rngs: one generator per fish for the position noise (needed when ``vision.noise``
            > 0; fish i's noise comes from ``rngs[i]`` only, so results do not depend on the
            other fish's draws).
        kernels: other implementations of the range search, :func:`sift` and the rotation
            into the body frames (the simulator's compiled ones for large swarms); None:
            this module's.

    Returns:
        The visible neighbours of each fish, nearest first, in its body frame.
    """
    count = position.shape[0]
    if kernels is None:
        index, distance = _in_range(position, vision.visual_range)
        sifted = sift(position, yaw, index, distance, vision=vision)
    else:
        index, distance = kernels.in_range(position, vision.visual_range)
        sifted = kernels.sift(position, yaw, index, distance, vision=vision)
    seen, chosen, relative_seen, distance_seen = sifted
    if vision.noise > 0:
        if rngs is None or len(rngs) != count:
            raise ValueError("vision noise needs one random generator per fish")
        for fish in range(count):
            rows = int(seen[fish].sum())
            scale = vision.noise * distance_seen[fish, :rows, None]
            relative_seen[fish, :rows] += rngs[fish].normal(0.0, 1.0, (rows, 3)) * scale
    stacked = None
    if kernels is None:
        body = to_body(relative_seen, yaw)
        body[~seen] = 0.0
    else:
        body, stacked = kernels.body_frame(relative_seen, yaw, seen)
    return Perceived(body, seen, np.where(seen, chosen, -1), stacked)


def perceive_landmarks(
    position: FloatArray, yaw: FloatArray, landmarks: FloatArray, *, vision: Vision
) -> Perceived:
    """Which fixed landmarks (e.g. an orbit centre) each fish sees, in its body frame.

    Landmarks are seen within range and outside the blind spot; they do not occlude and are
    not occluded (they are posts that stick out above the school).

    Args:
        position: (N, 3) fish positions, m.
        yaw: (N,) fish yaws, rad.
        landmarks: (L, 3) landmark positions in the tank frame, m.
        vision: the vision parameters.
    """
    count = position.shape[0]
    if landmarks.shape[0] == 0:
        # Most scenarios have none: no sines and cosines of every fish's yaw for nothing
        # (0.4 ms a tick at 10 000 fish).
        return Perceived(
            np.zeros((count, 0, 3)),
            np.zeros((count, 0), dtype=np.bool_),
            np.zeros((count, 0), dtype=np.intp),
        )
    relative = (
        np.broadcast_to(landmarks[None, :, :], (count, *landmarks.shape)) - position[:, None, :]
    )
    distance = np.linalg.norm(relative, axis=2)
    seen = distance <= vision.visual_range
    if vision.blind_width > 0:
        seen &= ~in_blind_spot(relative, yaw, blind_width=vision.blind_width)
    body = to_body(np.ascontiguousarray(relative), yaw)
    body[~seen] = 0.0
    index = np.where(seen, np.arange(landmarks.shape[0])[None, :], -1)
    return Perceived(body, seen, index)
