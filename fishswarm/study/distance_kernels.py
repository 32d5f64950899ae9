"""Compiled distances for the swarm metrics of large schools: the mean over all pairs, the
mean over sampled pairs, and each fish's nearest other fish.

The observer measures every snapshot in a thread of the launcher's process, beside the
world's ticks and the fish workers; on two cores its work is the world's and the fish's
loss. So these kernels run on one core each, release the GIL and take no lock (the world's
parallel kernels in :mod:`fishswarm.sim.kernels` take theirs, and would wait for them).
Each returns what the numpy or scipy reference in :mod:`fishswarm.study.metrics` returns:
the same distances bit for bit on x86-64 (the same arithmetic in the same order; where a C
compiler fuses multiply-adds, as on aarch64, scipy's may differ in the last bit), and for
the mean over all pairs the same mean within rounding. The loops themselves are in
:mod:`fishswarm.study.distance_loops`, which imports numba: it is imported when a kernel is
first asked for.
"""

from __future__ import annotations

import functools
import math
from types import ModuleType

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

FloatArray = NDArray[np.float64]

FISH_PER_COLUMN = 2.0
"""How many fish the nearest-neighbour search's columns hold on average: a fish's nearest
other is then most often in its own column or the eight around it."""


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
    return float(_loops().total_all(x, y, z) / pairs)


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
    first, second = _pair_lists(first, second)
    x, y, z = np.ascontiguousarray(position.T, dtype=np.float64)
    distance = np.empty(first.shape[0])
    if not _loops().pairs_all(x, y, z, first, second, distance):
        raise _outside(position.shape[0])
    return distance


def _pair_lists(
    first: NDArray[np.intp], second: NDArray[np.intp]
) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The pair lists as the kernels take them, after checking that they are two integer
    lists of one length (the kernels check, as they read them, that they name fish there).
    """
    for indices in (first, second):
        if indices.ndim != 1 or indices.shape != first.shape or indices.dtype.kind not in "iu":
            raise ValueError(
                f"pairs are two integer lists of one length, got {indices.dtype} "
                f"{first.shape} and {second.shape}"
            )
    return (
        np.ascontiguousarray(first, dtype=np.intp),
        np.ascontiguousarray(second, dtype=np.intp),
    )


def _outside(count: int) -> IndexError:
    """The error for pairs that name a fish outside the ``count`` there."""
    return IndexError(f"pairs name fish outside 0…{count - 1}")


def nearest_distances(position: FloatArray) -> FloatArray:
    """Each fish's distance (N,) to its nearest other fish in ``position`` (N, 3), m: the
    second column of ``cKDTree(position).query(position, k=2)``, bit for bit (N ≥ 2).

    Fish are filed into square columns in the horizontal plane, about
    :data:`FISH_PER_COLUMN` to a column; each fish searches rings of columns around its own,
    outwards, until the next ring lies farther than the nearest fish found (at 10 000 fish
    over a tank 2 ms against scipy's 8). A school the columns cannot split
    (:data:`~fishswarm.study.distance_loops.CROWDED_COLUMN`,
    :data:`~fishswarm.study.distance_loops.COLUMNS_PER_FISH`) goes to scipy's k-d tree, with the
    same result.

    Raises:
        ValueError: fewer than two fish, or a position that is not finite.
    """
    points, columns = _columns_of(position)
    nearest = np.empty(points.shape[0])
    if not _loops().nearest_all(points, *columns, nearest):
        return _tree_nearest(points)
    return nearest


def school_distances(
    position: FloatArray,
    pairs: tuple[NDArray[np.intp], NDArray[np.intp]] | None = None,
) -> tuple[float, FloatArray]:
    """The mean distance between the fish of ``position`` (N, 3), N ≥ 2 — over all pairs,
    or over the listed ``pairs`` (two index lists) — and each fish's distance (N,) to its
    nearest other, m: what :func:`mean_pairwise_distance` (or the mean of
    :func:`pair_distances`) and :func:`nearest_distances` return, bit for bit.

    Both in one compiled call that holds no GIL. The observer measures in a thread beside
    the fish's decisions, and every return to Python between two kernels waits for the GIL
    that the event loop holds: at 1 000 fish, three calls stretched a millisecond's work
    over 1.3–1.8 ms, into the world's next physics.

    Raises:
        ValueError: fewer than two fish, a position that is not finite, or pairs that are
            not two integer lists of one length.
        IndexError: a pair names a fish that is not there.
    """
    points, columns = _columns_of(position)
    count = points.shape[0]
    if pairs is None:
        first = second = np.zeros(0, dtype=np.intp)
    else:
        first, second = _pair_lists(*pairs)
    x, y, z = np.ascontiguousarray(points.T)
    distance = np.empty(first.shape[0])
    nearest = np.empty(count)
    total, named, found = _loops().pairs_and_nearest(
        x, y, z, pairs is None, first, second, distance, points, *columns, nearest
    )
    if not named:
        raise _outside(count)
    mean = total / (count * (count - 1) / 2) if pairs is None else float(distance.mean())
    return mean, nearest if found else _tree_nearest(points)


def _columns_of(position: FloatArray) -> tuple[FloatArray, tuple[float, float, float, int, int]]:
    """The positions as the nearest-neighbour search takes them, and its columns: the
    lower corner (x, y) of the school's footprint, a column's side, columns and rows.

    Raises:
        ValueError: fewer than two fish, or a position that is not finite.
    """
    count = position.shape[0]
    if count < 2:
        raise ValueError(f"a nearest neighbour needs two fish or more, got {count}")
    points = np.ascontiguousarray(position, dtype=np.float64)
    if not np.isfinite(points).all():
        raise ValueError("positions must be finite")
    # Column by column, as the world's range search does (ten times faster than along the
    # long axis of a (N, 2) view; exact either way).
    low = np.array([points[:, 0].min(), points[:, 1].min()])
    extent = np.array([points[:, 0].max(), points[:, 1].max()]) - low
    span = float(extent.max())
    # Columns of about FISH_PER_COLUMN fish over the school's footprint; fish on a line have
    # none, and then about one fish a column along it. Never more columns than ~2.5 fish.
    area = float(extent[0] * extent[1])
    side = max(math.sqrt(FISH_PER_COLUMN * area / count), span / count, 1e-12)
    columns = int(extent[0] // side) + 1
    rows = int(extent[1] // side) + 1
    return points, (float(low[0]), float(low[1]), side, columns, rows)


def _tree_nearest(points: FloatArray) -> FloatArray:
    """Each fish's nearest other from scipy's k-d tree, for schools the columns cannot
    split."""
    tree_distance: FloatArray = cKDTree(points).query(points, k=2)[0]
    return np.ascontiguousarray(tree_distance[:, 1])


@functools.cache
def _loops() -> ModuleType:
    """The compiled loops (numba is imported, and the loops loaded or compiled, on the
    first call)."""
    from fishswarm.study import distance_loops

    return distance_loops
