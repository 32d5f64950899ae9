"""Target maps: where each of N fish belongs in a formation, relative to its leader.

A map is an (N, 3) array of slots in the *formation frame*: x points along the intended
orientation (forward), y to the right, z down, metres, and slot 0 — the leader's — at the
origin. Slots are in rank order: the leader first, then row by row backwards, each row from
the middle outwards (left before right at equal distance), so a fish of rank r belongs in
slot r (SPEC §5).

The study's maps are flat: rows that follow the Fibonacci sequence (1, 1, 2, 3, 5, 8, …) or
the natural numbers (a pyramid, whose totals are the triangular numbers 1, 3, 6, 10, 15).
Unlike the study's code, whose rows were l apart but whose fish in a row stood 1 unit apart
whatever l was, every map here keeps its nearest neighbours exactly ``spacing`` apart: the
pyramid is a triangular lattice (rows l·√3/2 apart). The 3-D maps are the study's named next
step: a tetrahedral pyramid (layers of 1, 3, 6, 10 in close packing), a diamond (a string of
octahedra: 1, 4, 1, 4, …), a phalanx (a wall abreast, facing forward) and a column (single
file).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Iterator

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MAX_FISH = 10_000
"""Most slots a map is made for."""


def _rows(sizes: Iterator[int], count: int, *, spacing: float, row_gap: float) -> FloatArray:
    """Rows of the given sizes behind each other (x = −row · row_gap), centred on y = 0,
    fish ``spacing`` apart in a row; the last row is cut to ``count``."""
    slots: list[tuple[float, float, float]] = []
    for row, size in enumerate(sizes):
        lateral = _middle_out(size)
        for y in lateral[: count - len(slots)]:
            slots.append((-row * row_gap, y * spacing, 0.0))
        if len(slots) == count:
            break
    return np.array(slots, dtype=np.float64).reshape(-1, 3)


def _middle_out(size: int) -> list[float]:
    """Lateral positions of ``size`` fish one unit apart, centred, from the middle
    outwards, left (−y) before right at equal distance."""
    positions = [j - (size - 1) / 2 for j in range(size)]
    return sorted(positions, key=lambda y: (abs(y), y))


def _fibonacci_sizes() -> Iterator[int]:
    previous, current = 0, 1
    while True:
        yield current
        previous, current = current, previous + current


def _natural_sizes() -> Iterator[int]:
    size = 1
    while True:
        yield size
        size += 1


def fibonacci(count: int, *, spacing: float) -> FloatArray:
    """The study's Fibonacci map: rows of 1, 1, 2, 3, 5, 8, … fish, ``spacing`` apart both
    ways."""
    return _rows(_fibonacci_sizes(), count, spacing=spacing, row_gap=spacing)


def pyramid(count: int, *, spacing: float) -> FloatArray:
    """The study's triangle map (a pyramid seen from above): rows of 1, 2, 3, … fish on a
    triangular lattice of side ``spacing``."""
    return _rows(_natural_sizes(), count, spacing=spacing, row_gap=spacing * math.sqrt(3) / 2)


def column(count: int, *, spacing: float) -> FloatArray:
    """Single file: each fish ``spacing`` behind the one ahead."""
    return _rows(itertools.repeat(1), count, spacing=spacing, row_gap=spacing)


def tetrahedron(count: int, *, spacing: float) -> FloatArray:
    """A tetrahedral pyramid: the leader at the apex, then layers of 3, 6, 10, … fish behind
    it, each a triangle in the y–z plane, in close packing (every nearest pair ``spacing``
    apart; layers ``spacing``·√(2/3) apart)."""
    layer_gap = spacing * math.sqrt(2.0 / 3.0)
    # Lattice directions of a layer: a triangle with one edge along y, pointing up (−z).
    u = np.array([0.0, 1.0, 0.0])
    v = np.array([0.0, 0.5, -math.sqrt(3) / 2])
    slots: list[FloatArray] = []
    layer = 0
    while len(slots) < count:
        points = [a * u + b * v for a in range(layer + 1) for b in range(layer + 1 - a)]
        centre = layer * (u + v) / 3
        placed = [(p - centre) * spacing + np.array([-layer * layer_gap, 0.0, 0.0]) for p in points]
        placed.sort(key=lambda p: (round(float(np.hypot(p[1], p[2])), 9), p[1], p[2]))
        slots += placed[: count - len(slots)]
        layer += 1
    return np.array(slots, dtype=np.float64).reshape(-1, 3)


def diamond(count: int, *, spacing: float) -> FloatArray:
    """A string of octahedra along the axis: 1, 4, 1, 4, … fish; each square stands in the
    y–z plane, its corners ``spacing`` apart, every edge of the octahedra ``spacing`` long."""
    step = spacing / math.sqrt(2)
    square = [(0.0, -step, 0.0), (0.0, step, 0.0), (0.0, 0.0, -step), (0.0, 0.0, step)]
    slots: list[tuple[float, float, float]] = []
    layer = 0
    while len(slots) < count:
        x = -layer * step
        layer_slots = (
            [(x, 0.0, 0.0)] if layer % 2 == 0 else [(x + s[0], s[1], s[2]) for s in square]
        )
        slots += layer_slots[: count - len(slots)]
        layer += 1
    return np.array(slots, dtype=np.float64).reshape(-1, 3)


def phalanx(count: int, *, spacing: float) -> FloatArray:
    """A wall abreast facing forward: a square grid in the y–z plane, ``spacing`` apart, as
    wide as it is high (the smallest square that holds the fish), filled from the middle
    outwards; more than a square's worth go into ranks behind."""
    side = max(1, math.ceil(math.sqrt(count)))
    grid = [(y, z) for y in _middle_out(side) for z in _middle_out(side)]
    grid.sort(key=lambda p: (p[0] ** 2 + p[1] ** 2, p[1], p[0]))
    slots = []
    for index in range(count):
        rank, place = divmod(index, len(grid))
        y, z = grid[place]
        slots.append((-rank * spacing, y * spacing, z * spacing))
    return np.array(slots, dtype=np.float64).reshape(-1, 3)


MAPS: dict[str, Callable[..., FloatArray]] = {
    "fibonacci": fibonacci,
    "pyramid": pyramid,
    "column": column,
    "tetrahedral-pyramid": tetrahedron,
    "diamond": diamond,
    "phalanx": phalanx,
}
"""Every global map by name."""

THREE_D = ("tetrahedral-pyramid", "diamond", "phalanx")
"""The maps that use depth."""


def check_size(count: int, spacing: float, *, what: str = "a map") -> None:
    """Refuse a map for a count out of [1, MAX_FISH] or a spacing that is not a positive
    length (``what``: the map, as the message names it).

    Raises:
        ValueError: with what is wrong.
    """
    if not 1 <= count <= MAX_FISH:
        raise ValueError(f"{what} is for 1 to {MAX_FISH} fish, got {count}")
    if not spacing > 0 or not math.isfinite(spacing):
        raise ValueError(f"spacing must be a positive length, got {spacing}")


@functools.lru_cache(maxsize=64)
def target_map(name: str, count: int, *, spacing: float) -> FloatArray:
    """The map ``name`` for ``count`` fish, ``spacing`` m between nearest slots (read-only,
    made once per name, count and spacing: fish ask for it at every decision).

    Raises:
        ValueError: an unknown map, a count out of [1, MAX_FISH] or a spacing not positive.
    """
    make = MAPS.get(name)
    if make is None:
        raise ValueError(f"formation map must be one of {', '.join(MAPS)}, got {name!r}")
    check_size(count, spacing)
    made: FloatArray = make(count, spacing=spacing)
    slots: FloatArray = made - made[0]  # the leader's slot at the origin
    slots.setflags(write=False)
    return slots
