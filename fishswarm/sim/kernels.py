"""Compiled kernels for large swarms: the BlueBot's Euler integration and the vision
model's range search, sifting and rotation into the body frames, fish by fish.

The numpy references (:func:`fishswarm.bluebot.dynamics.step`,
:func:`fishswarm.bluebot.vision.sift`) work on the whole swarm at once; at thousands of fish
the hundred substeps of a period and the (N, K, K) occlusion cosines cost more than anything
else the world does. Here the same arithmetic runs as one compiled loop per fish, fish in
parallel on the available cores (numba). The operations are those of the references, in
their order, so velocities agree bit for bit; angles go through the C library's sine and
cosine, which may differ from numpy's in the last bit (tested equal within 1e-12, and the
same fish seen on random swarms).

The kernels release the GIL: the world's steps, computed in a worker thread, run beside the
actors' own work. (The observer's distance kernels are in
:mod:`fishswarm.study.distance_kernels`, on one core each.) numba is optional
(``pip install -e '.[fast]'``) and imported only when a kernel is
first asked for: the robot's import path never reaches this module, and a simulator without
numba runs the numpy reference.
"""

from __future__ import annotations

import functools
import importlib.util
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.dynamics import State, period_inputs
from fishswarm.bluebot.parameters import BlueBot, Tank
from fishswarm.bluebot.vision import Sifted, Stacked, Vision

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CompiledVision:
    """The compiled range search and sifting, for
    :func:`fishswarm.bluebot.vision.perceive`'s ``kernels``."""

    def in_range(
        self, position: FloatArray, visual_range: float
    ) -> tuple[NDArray[np.intp], FloatArray]:
        """See :func:`in_range`."""
        return in_range(position, visual_range)

    def sift(
        self,
        position: FloatArray,
        yaw: FloatArray,
        index: NDArray[np.intp],
        distance: FloatArray,
        *,
        vision: Vision,
    ) -> Sifted:
        """See :func:`sift`."""
        return sift(position, yaw, index, distance, vision=vision)

    def body_frame(
        self, relative: FloatArray, yaw: FloatArray, seen: NDArray[np.bool_]
    ) -> tuple[FloatArray, Stacked]:
        """See :func:`body_frame`."""
        return body_frame(relative, yaw, seen)


SIFT_CHUNK = 64
"""Fish sifted one after another by one thread, sharing its scratch arrays."""

INSERTION_MAX = 64
"""The range search keeps a fish's others in order as it finds them up to this many in
range; a fish with more (a school in a tank too small for it: 2 000 fish in the study's
tank have all the others in range) has them sorted once found, instead of moving each
past the nearer ones found after it (0.6 s a tick at 2 000 fish)."""

COMPILED_MIN_FISH = 200
"""From this many fish on, a scenario's world integrates and sees with the compiled kernels,
and the swarm metrics take their compiled distances (below, loading the kernels takes longer
than they save; small swarms stay on the numpy and scipy references)."""

_LOCK = threading.Lock()
"""One kernel at a time per process: two threads may each call one (the world's event loop
and its worker thread, or two worlds), and numba's simplest threading layer must not start
two parallel regions at once."""


def available() -> bool:
    """Whether numba is installed (the kernels can run)."""
    return importlib.util.find_spec("numba") is not None


def compiles(fish: int) -> bool:
    """Whether a swarm of ``fish`` runs on compiled kernels — its world's, its fish's
    decisions, its metrics: from :data:`COMPILED_MIN_FISH` on, when numba is installed."""
    return fish >= COMPILED_MIN_FISH and available()


def step(state: State, fins: FloatArray, *, duration: float, robot: BlueBot, tank: Tank) -> State:
    """:func:`fishswarm.bluebot.dynamics.step`, compiled: the same arguments and result.

    Raises:
        ValueError: a negative or infinite duration.
    """
    acceleration, drag, dt, velocity = period_inputs(state, fins, duration=duration, robot=robot)
    position = np.ascontiguousarray(state.position, dtype=np.float64).copy()
    yaw = np.ascontiguousarray(state.yaw, dtype=np.float64).copy()
    _call(
        _integrate(),
        position,
        yaw,
        velocity,
        acceleration,
        drag,
        dt,
        np.asarray(tank.size, dtype=np.float64),
        robot.speed_dependent_drag,
        robot.drag_x_backward / robot.drag_x,
        robot.speed_reference,
        robot.yaw_before_update,
    )
    return State(position, yaw, velocity[:, :3].copy(), velocity[:, 3].copy())


def _call(kernel: Callable[..., None], *arguments: Any) -> None:
    """Run a compiled kernel, one at a time in this process."""
    with _LOCK:
        kernel(*arguments)


@functools.cache
def _integrate() -> Callable[..., None]:
    """The compiled integration loop (compiled on first use, cached on disk)."""
    import numba

    @numba.njit(parallel=True, cache=True, nogil=True)
    def integrate(
        position: Any,
        yaw: Any,
        velocity: Any,
        acceleration: Any,
        drag: Any,
        dt: Any,
        upper: Any,
        speed_dependent: bool,
        backward: float,
        speed_reference: float,
        yaw_before_update: bool,
    ) -> None:
        for fish in numba.prange(position.shape[0]):
            heading = yaw[fish]
            for n in range(dt.shape[0]):
                before = velocity[fish, 3]
                forward = velocity[fish, 0]
                fast = abs(forward) / speed_reference
                for axis in range(4):
                    coefficient = drag[axis]
                    if speed_dependent:
                        if axis == 0 and not forward > 0:
                            coefficient = coefficient * backward
                        elif axis == 1:
                            coefficient = coefficient * (1 + 4 * fast)
                        elif axis == 3:
                            coefficient = coefficient * (1 + 9 * fast)
                    value = velocity[fish, axis]
                    change = coefficient * value * abs(value)
                    velocity[fish, axis] = value + (acceleration[fish, axis] - change) * dt[n]
                rate = before if yaw_before_update else velocity[fish, 3]
                heading = heading + rate * dt[n]
                cos, sin = math.cos(heading), math.sin(heading)
                surge, sway = velocity[fish, 0], velocity[fish, 1]
                moves = (
                    (cos * surge - sin * sway) * dt[n],
                    (sin * surge + cos * sway) * dt[n],
                    velocity[fish, 2] * dt[n],
                )
                for axis in range(3):
                    moved = position[fish, axis] + moves[axis]
                    position[fish, axis] = min(max(moved, 0.0), upper[axis])
            yaw[fish] = (heading + math.pi) % (2 * math.pi) - math.pi

    return integrate


def in_range(position: FloatArray, visual_range: float) -> tuple[NDArray[np.intp], FloatArray]:
    """Every fish's others within ``visual_range``, nearest first (ties by index), padded:
    index (N, K) (−1 in padding) and distance (N, K) (inf in padding).

    Fish are sorted into square columns of the visual range's side in the horizontal plane
    (the tank is shallower than the range), and each fish looks only into its own column
    and the eight around it.
    """
    count = position.shape[0]
    points = np.ascontiguousarray(position, dtype=np.float64)
    if count == 0:
        return np.zeros((0, 0), dtype=np.intp), np.zeros((0, 0))
    # Column by column: numpy reduces a (N, 2) view along its long axis ten times slower
    # (0.3 ms a tick at 10 000 fish); a minimum and a maximum are exact either way.
    low = np.array([points[:, 0].min(), points[:, 1].min()])
    span = max(float(points[:, 0].max() - low[0]), float(points[:, 1].max() - low[1]))
    # Columns at least a visual range wide (a little more: rounding in the division must not
    # put two fish exactly one range apart two columns apart), and never more of them than
    # fish (a tiny range on a large tank would ask for billions).
    side = max(visual_range * (1 + 1e-9), span / math.ceil(math.sqrt(count)), 1e-9)
    cell = np.floor((points[:, :2] - low) / side).astype(np.int64)
    columns = int(cell[:, 0].max()) + 1
    rows = int(cell[:, 1].max()) + 1
    key = cell[:, 1] * columns + cell[:, 0]
    order = np.argsort(key, kind="stable").astype(np.intp)
    start = np.searchsorted(key[order], np.arange(columns * rows + 1)).astype(np.intp)
    grid = (points, visual_range, cell, columns, rows, order, start)
    # Twice through the columns: first how many each fish has in range (the padded width),
    # then who they are.
    found = np.zeros(count, dtype=np.int64)
    none = np.zeros((count, 0), dtype=np.intp)
    _call(_scan_in_range(), *grid, found, none, np.zeros((count, 0)))
    width = int(found.max(initial=0))
    index = np.full((count, width), -1, dtype=np.intp)
    distance = np.full((count, width), np.inf)
    _call(_scan_in_range(), *grid, found, index, distance)
    return index, distance


def sift(
    position: FloatArray,
    yaw: FloatArray,
    index: NDArray[np.intp],
    distance: FloatArray,
    vision: Vision,
) -> Sifted:
    """:func:`fishswarm.bluebot.vision.sift`, compiled: the same arguments and result."""
    count, width = index.shape
    seen = np.zeros((count, width), dtype=np.bool_)
    chosen = np.full((count, width), -1, dtype=np.intp)
    relative = np.zeros((count, width, 3))
    reach = np.zeros((count, width))
    visible = np.zeros(count, dtype=np.int64)
    _call(
        _sift(),
        np.ascontiguousarray(position, dtype=np.float64),
        np.ascontiguousarray(yaw, dtype=np.float64),
        np.ascontiguousarray(index, dtype=np.intp),
        np.ascontiguousarray(distance, dtype=np.float64),
        vision.visual_range,
        vision.manhattan,
        vision.blind_width,
        vision.sphere_radius,
        seen,
        chosen,
        relative,
        reach,
        visible,
    )
    keep = int(visible.max(initial=0))
    return seen[:, :keep], chosen[:, :keep], relative[:, :keep], reach[:, :keep]


def body_frame(
    relative: FloatArray, yaw: FloatArray, seen: NDArray[np.bool_]
) -> tuple[FloatArray, Stacked]:
    """:func:`fishswarm.bluebot.vision.to_body` of the rows ``seen`` of ``relative``
    (B, K, 3), zero elsewhere, compiled: one sine and cosine per fish, no (B, K) temporaries
    (at 10 000 fish the numpy rotation and masking took 14 ms a tick, a sixth of it).

    Returns:
        The rotated rows, padded (B, K, 3); and the same rows stacked fish after fish with
        each fish's count, written in the same pass (read-only): what the world's perception
        batches carry, which stacking and counting afterwards took 1 ms a tick at 10 000 fish.

    Raises:
        ValueError: the shapes do not agree.
    """
    if relative.ndim != 3 or seen.shape != relative.shape[:2] or yaw.shape != seen.shape[:1]:
        # The loops index by these shapes and do not check: a mismatch would write past rows.
        raise ValueError(
            f"body_frame needs relative (B, K, 3), seen (B, K) and yaw (B,), got "
            f"{relative.shape}, {seen.shape} and {yaw.shape}"
        )
    relative = np.ascontiguousarray(relative, dtype=np.float64)
    seen = np.ascontiguousarray(seen, dtype=np.bool_)
    counts = np.zeros(relative.shape[0], dtype=np.int64)
    starts = np.zeros(relative.shape[0] + 1, dtype=np.intp)
    _call(_count(), seen, counts)
    np.cumsum(counts, out=starts[1:])
    body = np.zeros(relative.shape)
    rows = np.empty((int(starts[-1]), 3))
    _call(
        _rotate(), relative, np.ascontiguousarray(yaw, dtype=np.float64), seen, starts, body, rows
    )
    counts.setflags(write=False)
    rows.setflags(write=False)
    return body, Stacked(counts, rows)


@functools.cache
def _count() -> Callable[..., None]:
    """The compiled count of each fish's seen rows (compiled on first use, cached on disk)."""
    import numba

    @numba.njit(parallel=True, cache=True, nogil=True)
    def count_all(seen: Any, counts: Any) -> None:
        for fish in numba.prange(seen.shape[0]):
            total = 0
            for k in range(seen.shape[1]):
                total += seen[fish, k]
            counts[fish] = total

    return count_all


@functools.cache
def _rotate() -> Callable[..., None]:
    """The compiled rotation into the body frames (compiled on first use, cached on disk)."""
    import numba

    @numba.njit(parallel=True, cache=True, nogil=True)
    def rotate_all(relative: Any, yaw: Any, seen: Any, starts: Any, body: Any, rows: Any) -> None:
        for fish in numba.prange(relative.shape[0]):
            # The reference's arithmetic, in its order: x' = cos·x + sin·y, y' = −sin·x + cos·y.
            cos, sin = math.cos(yaw[fish]), math.sin(yaw[fish])
            row = starts[fish]
            for k in range(relative.shape[1]):
                if seen[fish, k]:
                    x, y = relative[fish, k, 0], relative[fish, k, 1]
                    body[fish, k, 0] = rows[row, 0] = cos * x + sin * y
                    body[fish, k, 1] = rows[row, 1] = -sin * x + cos * y
                    body[fish, k, 2] = rows[row, 2] = relative[fish, k, 2]
                    row += 1

    return rotate_all


@functools.cache
def _sift() -> Callable[..., None]:
    """The compiled sifting loop (compiled on first use, cached on disk)."""
    import numba

    @numba.njit(parallel=True, cache=True, nogil=True)
    def sift_all(
        position: Any,
        yaw: Any,
        index: Any,
        distance: Any,
        visual_range: float,
        manhattan: bool,
        blind_width: float,
        sphere_radius: float,
        seen: Any,
        chosen: Any,
        relative: Any,
        reach: Any,
        visible: Any,
    ) -> None:
        width, count = index.shape[1], index.shape[0]
        chunks = (count + SIFT_CHUNK - 1) // SIFT_CHUNK
        for chunk in numba.prange(chunks):
            # Each kept neighbour's direction and its blocking threshold, near to far: one
            # scratch per chunk of fish (rows beyond a fish's kept ones are never read).
            directions = np.zeros((width, 3))
            limits = np.zeros(width)
            for fish in range(chunk * SIFT_CHUNK, min((chunk + 1) * SIFT_CHUNK, count)):
                heading_x, heading_y = np.cos(yaw[fish]), np.sin(yaw[fish])
                kept = 0
                for k in range(width):
                    other = index[fish, k]
                    if other < 0:
                        break
                    # The offset as three numbers, not an array: no allocation per neighbour.
                    ox = position[other, 0] - position[fish, 0]
                    oy = position[other, 1] - position[fish, 1]
                    oz = position[other, 2] - position[fish, 2]
                    if manhattan and abs(ox) + abs(oy) + abs(oz) > visual_range:
                        continue
                    if blind_width > 0:
                        along = heading_x * ox + heading_y * oy
                        lateral = heading_x * oy - heading_y * ox
                        if along < 0.0 and abs(lateral) < blind_width / 2:
                            continue
                    gap = distance[fish, k]
                    if gap > 0:
                        dx, dy, dz = ox / gap, oy / gap, oz / gap
                    else:
                        dx, dy, dz = 0.0, 0.0, 0.0
                    hidden = False
                    if sphere_radius > 0:
                        for m in range(kept):
                            cosine = (
                                dx * directions[m, 0]
                                + dy * directions[m, 1]
                                + dz * directions[m, 2]
                            )
                            if cosine > limits[m]:
                                hidden = True
                                break
                    if hidden:
                        continue
                    directions[kept, 0], directions[kept, 1], directions[kept, 2] = dx, dy, dz
                    limits[kept] = gap / math.sqrt(gap * gap + sphere_radius**2) if gap > 0 else 1.0
                    seen[fish, kept] = True
                    chosen[fish, kept] = other
                    relative[fish, kept, 0] = ox
                    relative[fish, kept, 1] = oy
                    relative[fish, kept, 2] = oz
                    reach[fish, kept] = gap
                    kept += 1
                visible[fish] = kept

    return sift_all


@functools.cache
def _scan_in_range() -> Callable[..., None]:
    """Each fish's others in range from the nine columns around it: their count, and with
    room in ``index`` (its width), who they are, nearest first (compiled on first use,
    cached on disk)."""
    import numba

    @numba.njit(parallel=True, cache=True, nogil=True)
    def scan_all(
        points: Any,
        reach: float,
        cell: Any,
        columns: int,
        rows: int,
        order: Any,
        start: Any,
        found: Any,
        index: Any,
        distance: Any,
    ) -> None:
        width = index.shape[1]
        for fish in numba.prange(points.shape[0]):
            # The first pass counted each fish's others: a crowded fish's are sorted once
            # they are all in (insertion would move each past the nearer ones found later).
            crowded = width > 0 and found[fish] > INSERTION_MAX
            total = 0
            for row in range(max(cell[fish, 1] - 1, 0), min(cell[fish, 1] + 2, rows)):
                for column in range(max(cell[fish, 0] - 1, 0), min(cell[fish, 0] + 2, columns)):
                    bucket = row * columns + column
                    for slot in range(start[bucket], start[bucket + 1]):
                        other = order[slot]
                        if other == fish:
                            continue
                        dx = points[other, 0] - points[fish, 0]
                        dy = points[other, 1] - points[fish, 1]
                        dz = points[other, 2] - points[fish, 2]
                        gap = math.sqrt(dx * dx + dy * dy + dz * dz)
                        if gap > reach:
                            continue
                        if crowded:
                            index[fish, total] = other
                            distance[fish, total] = gap
                        elif width:
                            # Insertion into the row kept nearest first, ties by index: the
                            # order of a stable sort by distance of the others in index order,
                            # without a buffer or a sort per fish.
                            place = total
                            while place > 0 and (
                                distance[fish, place - 1] > gap
                                or (
                                    distance[fish, place - 1] == gap
                                    and index[fish, place - 1] > other
                                )
                            ):
                                index[fish, place] = index[fish, place - 1]
                                distance[fish, place] = distance[fish, place - 1]
                                place -= 1
                            index[fish, place] = other
                            distance[fish, place] = gap
                        total += 1
            found[fish] = total
            if crowded:
                # By index, then stably by distance: nearest first, equal distances by
                # index, the order the insertion above gives (however many fish tie).
                by_index = np.argsort(index[fish, :total])
                others = index[fish, :total][by_index]
                gaps = distance[fish, :total][by_index]
                by_distance = np.argsort(gaps, kind="mergesort")
                distance[fish, :total] = gaps[by_distance]
                index[fish, :total] = others[by_distance]

    return scan_all
