"""Lattices of local shapes: places where every fish completes its shape with its neighbours.

A school in which each fish makes a star with its nearest neighbours (SPEC §5: trigonal
planar, k = 3) is not something fish reach by chasing spots next to neighbours that chase
spots of their own (docs/formations.md measures it: 0–20 % joined). It is a lattice the
school must agree on — and the formation flags let it agree on one leader and orientation,
as for a global map. This module makes that lattice's map.

On a triangular lattice of side ``spacing`` a fish completes a star with its nearest
neighbours (judged as :func:`fishswarm.formations.groups.completion` does, with a tolerance
below a quarter of the spacing) in exactly two ways:

- as a *centre*: three of its six lattice neighbours are taken, 120° apart;
- as an *arm*: it has one taken neighbour, which is the centre of a star of which the fish
  is an arm (the arm's two siblings are then its next nearest, √3 spacings away, and no
  other fish is nearer).

A fish with two taken neighbours or more and no three of them 120° apart completes none.
:func:`star_sites` grows a school on the lattice one place at a time, each time taking the
place that completes the most stars, nearest the middle; for 15 fish every one completes a
star (a hexagon about a centre fish, an arm out of each corner, one arm grown into a star).
:func:`star_map` turns the places into a map like the global ones: the leader is the fish
that can lead with the least way to the others, and the map is turned so that it stands
furthest ahead of the rest.

Tetrahedra need no growing: in close packing every fish has three mutually adjacent
neighbours, so the tetrahedral pyramid of the global maps (:func:`close_packing`) is their
lattice. Numpy only: it runs on the robot.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.dynamics import rotate_to_tank
from fishswarm.formations.maps import check_size, target_map

FloatArray = NDArray[np.float64]

Site = tuple[int, int]
"""A lattice place: steps along the lattice's two axes, 60° apart."""

_DIRECTIONS: tuple[Site, ...] = ((1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1))
"""The six neighbours of a place, in angular order, 60° apart, from 0°."""
_STARS = (frozenset({0, 2, 4}), frozenset({1, 3, 5}))
"""Three directions 120° apart: the arms of a star."""
_TURNS = 3600
"""Directions tried when turning the map (every 0.1°)."""
_WEIGHED = 48
"""How many free places, nearest the middle, growth weighs at each step."""
_DIGITS = 9
"""Lengths are compared rounded to this many decimals: ties of a symmetric school are
broken by order, not by the last bits of a sum, which may differ between machines (each
robot makes its own map and must make the same one)."""


def _step(site: Site, direction: int) -> Site:
    da, db = _DIRECTIONS[direction]
    return site[0] + da, site[1] + db


def _position(site: Site) -> tuple[float, float]:
    """Where a place is, in spacings."""
    return site[0] + site[1] / 2, site[1] * math.sqrt(3) / 2


def _taken_directions(site: Site, taken: set[Site]) -> frozenset[int]:
    return frozenset(d for d in range(6) if _step(site, d) in taken)


def completes_star(site: Site, taken: set[Site]) -> bool:
    """Whether a fish at ``site`` completes a star with the fish at the ``taken`` places
    (``site`` among them): as a centre, or as an arm of its one neighbour's star."""
    around = _taken_directions(site, taken)
    if any(star <= around for star in _STARS):
        return True
    if len(around) != 1:
        return False
    (toward,) = around
    centre = _step(site, toward)
    back = (toward + 3) % 6  # the fish itself, seen from the centre
    arms = _taken_directions(centre, taken)
    return any(back in star and star <= arms for star in _STARS)


def _near(site: Site) -> list[Site]:
    """The places within two steps of ``site``, itself included: those whose stars a fish
    at ``site`` can make or spoil."""
    return [
        (site[0] + a, site[1] + b) for a in range(-2, 3) for b in range(-2, 3) if abs(a + b) <= 2
    ]


def _worth(site: Site, taken: set[Site]) -> float:
    """What a fish at ``site`` adds to the school: 1 if it completes a star; a tenth if it
    does not yet but its taken neighbours are part of a star's arms (it may still become a
    centre) — without that foresight growth one place at a time never starts a star, whose
    first three places complete nothing."""
    if completes_star(site, taken):
        return 1.0
    around = _taken_directions(site, taken)
    return 0.1 if any(around <= star for star in _STARS) else 0.0


def star_sites(count: int) -> list[Site]:
    """``count`` lattice places, grown one at a time from (0, 0): each time the free place
    next to the school that adds the most worth (:func:`_worth`: completed stars, and stars
    that may still be completed), the one nearest (0, 0) on a tie (then the lowest
    coordinates). Only the :data:`_WEIGHED` free places nearest (0, 0) are weighed."""
    taken: set[Site] = {(0, 0)}
    order: list[Site] = [(0, 0)]
    worth: dict[Site, float] = {(0, 0): _worth((0, 0), taken)}
    distance: dict[Site, float] = {}
    for site in (_step((0, 0), d) for d in range(6)):
        distance[site] = math.hypot(*_position(site))
    while len(order) < count:
        # Only the free places nearest the middle are weighed: it keeps the school round
        # and the growth of thousands of places quick.
        weighed = sorted((away, site) for site, away in distance.items())[:_WEIGHED]
        best: tuple[float, float, Site] | None = None
        for away, site in weighed:
            after = taken | {site}
            gain = sum(
                _worth(other, after) - worth.get(other, 0.0)
                for other in _near(site)
                if other in after
            )
            key = (-round(gain, _DIGITS), round(away, _DIGITS), site)
            if best is None or key < best:
                best = key
        assert best is not None
        chosen = best[2]
        taken.add(chosen)
        order.append(chosen)
        del distance[chosen]
        for site in (_step(chosen, d) for d in range(6)):
            if site not in taken and site not in distance:
                distance[site] = math.hypot(*_position(site))
        for other in _near(chosen):
            if other in taken:
                worth[other] = _worth(other, taken)
    return order


def _hull(points: FloatArray) -> NDArray[np.intp]:
    """The corners of the convex hull of points (N, 2), ascending (points on an edge
    between two corners left out): the points that can stand ahead of all others."""
    order = sorted(range(points.shape[0]), key=lambda i: (points[i, 0], points[i, 1]))
    rounded = np.round(points, _DIGITS)

    def turns_left(a: int, b: int, c: int) -> bool:
        ab, ac = rounded[b] - rounded[a], rounded[c] - rounded[a]
        return bool(ab[0] * ac[1] - ab[1] * ac[0] > 10.0**-_DIGITS)

    corners: list[int] = []
    for chain in (order, order[::-1]):  # the lower hull, then the upper
        start = len(corners)
        for index in chain:
            while len(corners) - start >= 2 and not turns_left(corners[-2], corners[-1], index):
                corners.pop()
            corners.append(index)
        corners.pop()  # each chain's last point starts the other
    return np.array(sorted(set(corners)), dtype=np.intp)


def _lead_and_turn(points: FloatArray) -> tuple[int, float]:
    """Which of the points (N, 2) leads and the angle (rad) to turn them by so that it is
    furthest ahead (+x) of the others: of the points that can be ahead of all others (the
    hull's corners), the one nearest the others on average (the first on a tie), turned to
    stand ahead by the widest margin (the first such direction from 0)."""
    if points.shape[0] < 3:
        return 0, 0.0 if points.shape[0] == 1 else math.atan2(*(points[0] - points[1])[::-1])
    can_lead = _hull(points)
    spread = np.linalg.norm(points[can_lead, None, :] - points[None, :, :], axis=2).mean(axis=1)
    leader = int(can_lead[np.argmin(np.round(spread, _DIGITS))])
    angles = np.linspace(0.0, 2 * math.pi, _TURNS, endpoint=False)
    forward = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (A, 2)
    others = np.delete(points - points[leader], leader, axis=0)
    margin = -(others @ forward.T).max(axis=0)  # (A,) how far ahead of the rest it stands
    return leader, float(-angles[int(np.argmax(np.round(margin, _DIGITS)))])


@functools.lru_cache(maxsize=16)
def star_map(count: int, *, spacing: float) -> FloatArray:
    """The star map for ``count`` fish, ``spacing`` m between lattice neighbours: (count, 3)
    places in the formation frame (x forward, y right, z down; m), the leader's at the origin
    and first, the others from the front backwards (decreasing x; then from the middle
    out, left first), like the global maps. Read-only, made once per count and spacing
    (about 1.5 s for 1 000 fish).

    Raises:
        ValueError: a count out of [1, :data:`~fishswarm.formations.maps.MAX_FISH`] or a
            spacing not positive.
    """
    check_size(count, spacing, what="a star map")
    points = np.array([_position(site) for site in star_sites(count)], dtype=np.float64)
    leader, angle = _lead_and_turn(points)
    flat = np.zeros((count, 3))
    flat[:, :2] = points - points[leader]
    placed = rotate_to_tank(flat, np.full(count, angle)) * spacing
    placed = np.round(placed, 12) + 0.0  # no −0.0, no rounding dust in the order
    rest = np.delete(np.arange(count), leader)
    rest = rest[np.lexsort((placed[rest, 1], np.abs(placed[rest, 1]), -placed[rest, 0]))]
    slots: FloatArray = placed[np.concatenate([[leader], rest])]
    slots.setflags(write=False)
    return slots


def close_packing(count: int, *, spacing: float) -> FloatArray:
    """The tetrahedra's map for ``count`` fish: the tetrahedral pyramid (layers of 1, 3, 6,
    10, … in close packing, :func:`fishswarm.formations.maps.tetrahedron`), on which every
    fish completes a regular tetrahedron with three of its nearest neighbours.

    Raises:
        ValueError: a count out of range or a spacing not positive.
    """
    return target_map("tetrahedral-pyramid", count, spacing=spacing)
