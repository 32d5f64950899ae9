"""Compiled distances for the swarm metrics of large schools: the mean over all pairs, the
mean over sampled pairs, and each fish's nearest other fish.

The observer measures every snapshot in a thread of the launcher's process, beside the
world's ticks and the fish workers; on two cores its work is the world's and the fish's
loss. So these kernels run on one core each, release the GIL and take no lock (the world's
parallel kernels in :mod:`fishswarm.sim.kernels` take theirs, and would wait for them).
Each returns what the numpy or scipy reference in :mod:`fishswarm.study.metrics` returns:
the same distances bit for bit on x86-64 (the same arithmetic in the same order; where a C
compiler fuses multiply-adds, as on aarch64, scipy's may differ in the last bit), and for
the mean over all pairs the same mean within rounding. numba is imported when a kernel is first
asked for.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

FloatArray = NDArray[np.float64]

FISH_PER_COLUMN = 2.0
"""How many fish the nearest-neighbour search's columns hold on average: a fish's nearest
other is then most often in its own column or the eight around it."""
CROWDED_COLUMN = 64
"""A column holding more fish than this sends the nearest-neighbour search to scipy's k-d
tree: the columns are sized from the school's whole footprint, so one straggler far off (or
fish stacked in one place) leaves the rest in a few columns, where the search would compare
every fish with every other (10 000 fish and one straggler: 80 ms against the tree's 10)."""
COLUMNS_PER_FISH = 64
"""The search gives up for the k-d tree once it has looked into this many columns a fish on
average (a fish looks into 9 or 25 in a school spread over a tank): fish stacked over one
another, columns much narrower than the distances between them, would otherwise search
ring after ring (10 000 fish stacked with 1 nm of sideways jitter: 360 ms)."""


def mean_pairwise_distance(position: FloatArray) -> float:
    """The mean distance over all pairs of ``position`` (N, 3), m: scipy's
    ``pdist(position).mean()`` within rounding.

    Vectorised on one core: spread over both (as it was) it took the fish's core for as
    long again as it saved (at 1 000 fish 0.9 ms of wall time and 1.8 of CPU, against 0.74
    on one core)."""
    count = position.shape[0]
    if count < 2:
        return 0.0
    x, y, z = np.ascontiguousarray(position.T, dtype=np.float64)
    pairs = count * (count - 1) / 2
    return float(_pairwise_total()(x, y, z) / pairs)


def pair_distances(
    position: FloatArray, first: NDArray[np.intp], second: NDArray[np.intp]
) -> FloatArray:
    """The distances (P,) of the pairs of fish ``first[p]``, ``second[p]`` of ``position``
    (N, 3), m: ``np.sqrt(((position[first] - position[second]) ** 2).sum(axis=1))`` bit for
    bit, without its (P, 3) temporaries (at 10 000 fish and 250 000 pairs, 0.9 against
    1.8 ms).

    Raises:
        ValueError: ``first`` and ``second`` are not integer lists of one length.
        IndexError: a pair names a fish that is not there.
    """
    count = position.shape[0]
    for indices in (first, second):
        if indices.ndim != 1 or indices.shape != first.shape or indices.dtype.kind not in "iu":
            raise ValueError(
                f"pairs are two integer lists of one length, got {indices.dtype} "
                f"{first.shape} and {second.shape}"
            )
    for indices in (first, second):
        if indices.size and (int(indices.min()) < 0 or int(indices.max()) >= count):
            raise IndexError(f"pairs name fish outside 0…{count - 1}")
    x, y, z = np.ascontiguousarray(position.T, dtype=np.float64)
    distance = np.empty(first.shape[0])
    _pairs()(
        x,
        y,
        z,
        np.ascontiguousarray(first, dtype=np.intp),
        np.ascontiguousarray(second, dtype=np.intp),
        distance,
    )
    return distance


def nearest_distances(position: FloatArray) -> FloatArray:
    """Each fish's distance (N,) to its nearest other fish in ``position`` (N, 3), m: the
    second column of ``cKDTree(position).query(position, k=2)``, bit for bit (N ≥ 2).

    Fish are filed into square columns in the horizontal plane, about
    :data:`FISH_PER_COLUMN` to a column; each fish searches rings of columns around its own,
    outwards, until the next ring lies farther than the nearest fish found (at 10 000 fish
    over a tank 2 ms against scipy's 8). A school the columns cannot split
    (:data:`CROWDED_COLUMN`, :data:`COLUMNS_PER_FISH`) goes to scipy's k-d tree, with the
    same result.

    Raises:
        ValueError: fewer than two fish, or a position that is not finite.
    """
    count = position.shape[0]
    if count < 2:
        raise ValueError(f"a nearest neighbour needs two fish or more, got {count}")
    points = np.ascontiguousarray(position, dtype=np.float64)
    if not np.isfinite(points).all():
        raise ValueError("positions must be finite")
    low = points[:, :2].min(axis=0)
    extent = points[:, :2].max(axis=0) - low
    span = float(extent.max())
    # Columns of about FISH_PER_COLUMN fish over the school's footprint; fish on a line have
    # none, and then about one fish a column along it. Never more columns than ~2.5 fish.
    area = float(extent[0] * extent[1])
    side = max(math.sqrt(FISH_PER_COLUMN * area / count), span / count, 1e-12)
    columns = int(extent[0] // side) + 1
    rows = int(extent[1] // side) + 1
    nearest = np.empty(count)
    if not _nearest()(points, float(low[0]), float(low[1]), side, columns, rows, nearest):
        tree_distance: FloatArray = cKDTree(points).query(points, k=2)[0]
        return np.ascontiguousarray(tree_distance[:, 1])
    return nearest


@functools.cache
def _pairwise_total() -> Callable[..., float]:
    """The summed distance over all pairs, on one core (compiled on first use, cached)."""
    import numba

    # Reassociation lets the inner sum run eight pairs at a time (AVX-512) or four; the
    # order is then the compiler's, fixed for a machine, so a run stays deterministic.
    @numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
    def total_all(x: Any, y: Any, z: Any) -> float:
        count = x.shape[0]
        total = 0.0
        for fish in range(count - 1):
            fx, fy, fz = x[fish], y[fish], z[fish]
            row = 0.0
            for other in range(fish + 1, count):
                dx = x[other] - fx
                dy = y[other] - fy
                dz = z[other] - fz
                row += math.sqrt(dx * dx + dy * dy + dz * dz)
            total += row
        return total

    return total_all


@functools.cache
def _pairs() -> Callable[..., None]:
    """The distances of listed pairs, on one core (compiled on first use, cached)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def pairs_all(x: Any, y: Any, z: Any, first: Any, second: Any, distance: Any) -> None:
        for pair in range(first.shape[0]):
            one, other = first[pair], second[pair]
            dx = x[one] - x[other]
            dy = y[one] - y[other]
            dz = z[one] - z[other]
            distance[pair] = math.sqrt(dx * dx + dy * dy + dz * dz)

    return pairs_all


@functools.cache
def _nearest() -> Callable[..., bool]:
    """The nearest-neighbour search over rings of columns, on one core (compiled on first
    use, cached)."""
    import numba

    @numba.njit(cache=True, nogil=True)
    def nearest_all(
        points: Any,
        low_x: float,
        low_y: float,
        side: float,
        columns: int,
        rows: int,
        nearest: Any,
    ) -> bool:
        count = points.shape[0]
        # File the fish column by column (a counting sort): the fish of column b are the
        # slots start[b] to start[b + 1] of `filed`, read together.
        column_of = np.empty(count, dtype=np.int64)
        row_of = np.empty(count, dtype=np.int64)
        start = np.zeros(columns * rows + 1, dtype=np.int64)
        for fish in range(count):
            column = min(int((points[fish, 0] - low_x) / side), columns - 1)
            row = min(int((points[fish, 1] - low_y) / side), rows - 1)
            column_of[fish], row_of[fish] = column, row
            start[row * columns + column + 1] += 1
        if start.max() > CROWDED_COLUMN:
            return False  # nothing searched: the caller asks the k-d tree
        for bucket in range(columns * rows):
            start[bucket + 1] += start[bucket]
        filled = start[:-1].copy()
        filed = np.empty((count, 3))
        slot_of = np.empty(count, dtype=np.int64)
        for fish in range(count):
            bucket = row_of[fish] * columns + column_of[fish]
            slot = filled[bucket]
            filled[bucket] += 1
            filed[slot, 0], filed[slot, 1], filed[slot, 2] = (
                points[fish, 0],
                points[fish, 1],
                points[fish, 2],
            )
            slot_of[fish] = slot
        widest = max(columns, rows)
        budget = COLUMNS_PER_FISH * count
        for fish in range(count):
            home_column, home_row, own = column_of[fish], row_of[fish], slot_of[fish]
            squared = math.inf
            ring = 0
            while ring <= widest:
                # The columns exactly `ring` columns away (Chebyshev) from the fish's own.
                for row in range(max(home_row - ring, 0), min(home_row + ring + 1, rows)):
                    edge = row == home_row - ring or row == home_row + ring
                    step = 1 if edge else 2 * ring
                    column = home_column - ring
                    while column <= home_column + ring:
                        if 0 <= column < columns:
                            budget -= 1
                            bucket = row * columns + column
                            for other in range(start[bucket], start[bucket + 1]):
                                if other == own:
                                    continue
                                dx = points[fish, 0] - filed[other, 0]
                                dy = points[fish, 1] - filed[other, 1]
                                dz = points[fish, 2] - filed[other, 2]
                                gap = dx * dx + dy * dy + dz * dz
                                if gap < squared:
                                    squared = gap
                        column += step
                # Fish in the next ring are at least `ring` whole columns away (less a
                # hair: filing a fish into its column rounds).
                reach = ring * side * (1.0 - 1e-9)
                if squared <= reach * reach:
                    break
                if budget < 0:
                    return False  # the columns are too narrow for this school
                ring += 1
            nearest[fish] = math.sqrt(squared)
        return True

    return nearest_all
