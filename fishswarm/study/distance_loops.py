"""The compiled loops behind :mod:`fishswarm.study.distance_kernels`: the distances over
all pairs or listed pairs, and the nearest-neighbour search over columns of fish.

Each runs on one core, releases the GIL and takes no lock (see distance_kernels for why).
They are module-level functions, so that the loop that runs them all in one call can call
the others and still be cached on disk: numba keys its cache on a closure's contents, and
a compiled function held in a closure pickles differently in every process. This module
imports numba; only :mod:`fishswarm.study.distance_kernels` imports it, on first use.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

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


# Reassociation lets the inner sum run eight pairs at a time (AVX-512) or four; the
# order is then the compiler's, fixed for a machine, so a run stays deterministic.
@numba.njit(cache=True, nogil=True, fastmath={"reassoc"})
def total_all(x: Any, y: Any, z: Any) -> float:
    """The summed distance over all pairs of the fish at ``x``, ``y``, ``z`` (N,), m."""
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


@numba.njit(cache=True, nogil=True)
def pairs_all(x: Any, y: Any, z: Any, first: Any, second: Any, distance: Any) -> bool:
    """Each listed pair's distance into ``distance`` (P,), m; False, with ``distance``
    unfinished, at the first pair that names a fish outside ``x`` (checked here, as each
    pair is read, rather than by four passes of numpy over the lists: 0.2 ms of the
    observer's 2.5 at 10 000 fish)."""
    count = x.shape[0]
    for pair in range(first.shape[0]):
        one, other = first[pair], second[pair]
        if one < 0 or one >= count or other < 0 or other >= count:
            return False
        dx = x[one] - x[other]
        dy = y[one] - y[other]
        dz = z[one] - z[other]
        distance[pair] = math.sqrt(dx * dx + dy * dy + dz * dz)
    return True


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
    """Each fish's distance to its nearest other into ``nearest`` (N,), m, searching rings of
    columns (of ``side``, from the corner ``low_x``, ``low_y``; ``columns`` × ``rows``)
    outwards from its own; False, with ``nearest`` unfinished, when the columns cannot
    split the school (:data:`CROWDED_COLUMN`, :data:`COLUMNS_PER_FISH`)."""
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
    # Fish column by column: neighbouring fish search the same columns one after another,
    # which stay in the cache (10 000 fish: 1.2 against 1.5 ms in their given order).
    by_slot = np.empty(count, dtype=np.int64)
    for fish in range(count):
        by_slot[slot_of[fish]] = fish
    for own in range(count):
        fish = by_slot[own]
        home_column, home_row = column_of[fish], row_of[fish]
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
                            dx = filed[own, 0] - filed[other, 0]
                            dy = filed[own, 1] - filed[other, 1]
                            dz = filed[own, 2] - filed[other, 2]
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


@numba.njit(cache=True, nogil=True)
def pairs_and_nearest(
    x: Any,
    y: Any,
    z: Any,
    every_pair: bool,
    first: Any,
    second: Any,
    distance: Any,
    points: Any,
    low_x: float,
    low_y: float,
    side: float,
    columns: int,
    rows: int,
    nearest: Any,
) -> tuple[float, bool, bool]:
    """The summed distance over all pairs (``every_pair``; else 0, and the listed pairs'
    distances into ``distance``), whether the listed pairs all name fish there (else
    nothing more is done), and whether the nearest-neighbour search filled ``nearest`` (see
    :func:`nearest_all`)."""
    total = 0.0
    if every_pair:
        total = total_all(x, y, z)
    elif not pairs_all(x, y, z, first, second, distance):
        return total, False, False
    return total, True, nearest_all(points, low_x, low_y, side, columns, rows, nearest)
