"""Orbiting: circle a visible centre (orbit, milling) or each other (waltz). SPEC §2.

All fish orbit the same way round, the centre on their left (body frame: x forward, y right,
z down); plotted with x right and y up (the study's plots) that is clockwise, and in our
views from above (y down the page) anticlockwise. A fish picks a heading by
zone — planar distance to the centre against the orbit radius R, and whether the centre lies
ahead (within ±90°) or behind:

========================  =====================================================
zone                      heading (bearing of the centre b, positive to the right)
========================  =====================================================
outside, centre ahead     the tangent point on the near side: b + asin(R/d)
outside, centre behind    the same tangent point: the fish turns back onto the
                          circle the short way round
inside, centre ahead      away from the centre: b + 90° + 90°·(R − d)/R
inside, centre behind     along the tangent, veering out: b + 90° + 90°·(R − d)/R
========================  =====================================================

The study's phases fall out of these zones: far away the tangent point lies almost on the
line to the centre, so the fish homes in; near the circle it turns onto the tangent
(transition); on the circle (d = R) every zone gives b + 90°: straight along the tangent.
The target's planar length is R, which sets the homing controller's cruise speed; its
vertical part holds the centre's depth. Before the centre is seen a fish swims straight on.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import (
    Behavior,
    Inbox,
    NoMemory,
    Perception,
    Steering,
    no_memory,
    steady,
)
from fishswarm.behaviors.lennard_jones import lennard_jones
from fishswarm.bluebot.parameters import BODY_LENGTH

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

ORBIT_RADIUS = 0.45
"""Default orbit radius R, m (SPEC: 0.4–0.5 m)."""

MILLING_SPACING = 2 * BODY_LENGTH
"""Neighbours closer than this push a milling fish away, m."""


def orbit(centre: FloatArray, seen: BoolArray, *, radius: float) -> FloatArray:
    """Desired motion of B fish orbiting a centre each sees.

    Args:
        centre: (B, 3) body-frame position of each fish's centre, m.
        seen: (B,) whether the fish sees its centre; a fish that does not swims straight on.
        radius: orbit radius R, m.

    Returns:
        (B, 3) target vectors in the body frame, m.
    """
    if radius <= 0:
        raise ValueError(f"radius must be positive, got {radius}")
    planar = np.hypot(centre[:, 0], centre[:, 1])
    bearing = np.arctan2(centre[:, 1], centre[:, 0])
    outside = planar >= radius
    with np.errstate(divide="ignore", invalid="ignore"):
        tangent_point = bearing + np.arcsin(np.minimum(1.0, radius / planar))
    veer_out = bearing + np.pi / 2 + np.pi / 2 * (radius - planar) / radius
    heading = np.where(outside, tangent_point, veer_out)
    heading = np.where(seen, heading, 0.0)
    target = np.empty_like(centre)
    target[:, 0] = radius * np.cos(heading)
    target[:, 1] = radius * np.sin(heading)
    target[:, 2] = np.where(seen, centre[:, 2], 0.0)
    return target


def nearest(neighbors: FloatArray, mask: BoolArray) -> tuple[FloatArray, BoolArray]:
    """Each fish's nearest visible neighbour (B, 3), and whether it sees any (B,)."""
    if neighbors.shape[1] == 0:
        return np.zeros((neighbors.shape[0], 3)), np.zeros(neighbors.shape[0], dtype=np.bool_)
    distance = np.where(mask, np.einsum("bkd,bkd->bk", neighbors, neighbors), np.inf)
    closest = np.argmin(distance, axis=1)
    rows = np.arange(neighbors.shape[0])
    seen: BoolArray = np.logical_or.reduce(mask, axis=1)
    partner: FloatArray = neighbors[rows, closest]
    return partner, seen


def waltz(neighbors: FloatArray, mask: BoolArray, *, radius: float) -> FloatArray:
    """Desired motion of fish that orbit their nearest neighbour at distance ``radius``.

    Each fish orbits its partner at distance ``radius``, keeping it on its left; as both do,
    they turn around their barycentre, with no fixed centre. (Orbiting the midpoint at half
    the distance instead was measured less stable at 1 Hz: separations up to 1.45 m at
    0.3 m, against 0.92 m.)

    Args:
        neighbors: (B, K, 3) visible neighbours in body frames, m.
        mask: (B, K) which rows are real.
        radius: distance to keep from the partner, m.
    """
    partner, seen = nearest(neighbors, mask)
    return orbit(partner, seen, radius=radius)


def milling(
    centre: FloatArray,
    seen: BoolArray,
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    radius: float,
    spacing: float = MILLING_SPACING,
) -> FloatArray:
    """Desired motion of fish orbiting one centre together, pushing off close neighbours.

    The orbit target plus a Lennard-Jones repulsion from neighbours closer than ``spacing``
    (repulsion only: farther neighbours are ignored), its length capped at R so that avoiding
    a collision can turn a fish but not send it across the tank.

    Args:
        centre: (B, 3) body-frame centre, m.
        seen: (B,) whether each fish sees the centre.
        neighbors: (B, K, 3) visible neighbours in body frames, m.
        mask: (B, K) which rows are real.
        radius: orbit radius R, m.
        spacing: neighbours closer than this repel, m.
    """
    close = mask & (np.einsum("bkd,bkd->bk", neighbors, neighbors) < spacing**2)
    push = lennard_jones(neighbors, close, target_distance=spacing)
    length = np.sqrt(np.einsum("bd,bd->b", push, push))
    scale = np.where(length > radius, radius / np.maximum(length, 1e-300), 1.0)
    result: FloatArray = orbit(centre, seen, radius=radius) + push * scale[:, None]
    return result


@dataclass(frozen=True)
class OrbitParams:
    """Parameters of orbit, milling and waltz.

    Attributes:
        radius: orbit radius R (orbit, milling) or the partner distance (waltz), m.
    """

    radius: float = ORBIT_RADIUS

    def __post_init__(self) -> None:
        if not self.radius > 0:
            raise ValueError(f"orbit radius must be positive, got {self.radius}")


def orbit_params(settings: Mapping[str, Any]) -> OrbitParams:
    """R from the ``orbit_radius`` setting."""
    return OrbitParams(float(settings.get("orbit_radius", ORBIT_RADIUS)))


def _centre(perception: Perception) -> tuple[FloatArray, BoolArray]:
    """The first visible landmark of each fish (its orbit centre), and whether it sees one."""
    if perception.landmarks.shape[1] == 0:
        count = perception.count
        return np.zeros((count, 3)), np.zeros(count, dtype=np.bool_)
    return perception.landmarks[:, 0], perception.landmark_mask[:, 0]


def steer_orbit(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: OrbitParams
) -> tuple[NoMemory, Steering]:
    """Circle the landmark seen first (:func:`orbit`)."""
    centre, seen = _centre(perception)
    return memory, steady(orbit(centre, seen, radius=params.radius))


def steer_milling(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: OrbitParams
) -> tuple[NoMemory, Steering]:
    """Circle the landmark together, pushing off close neighbours (:func:`milling`)."""
    centre, seen = _centre(perception)
    target = milling(
        centre, seen, perception.neighbors, perception.neighbor_mask, radius=params.radius
    )
    return memory, steady(target)


def steer_waltz(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: OrbitParams
) -> tuple[NoMemory, Steering]:
    """Circle the nearest neighbour (:func:`waltz`)."""
    target = waltz(perception.neighbors, perception.neighbor_mask, radius=params.radius)
    return memory, steady(target)


ORBIT = Behavior(
    "orbit",
    "circle the post (landmark) at radius orbit_radius",
    steer_orbit,
    no_memory,
    orbit_params,
    spawn_radius=10 * BODY_LENGTH,
    circles_landmark=True,
)
MILLING = Behavior(
    "milling",
    "circle the post together, pushing off close neighbours",
    steer_milling,
    no_memory,
    orbit_params,
    spawn_radius=10 * BODY_LENGTH,
    circles_landmark=True,
)
WALTZ = Behavior(
    "waltz",
    "circle the nearest neighbour at the partner distance orbit_radius",
    steer_waltz,
    no_memory,
    orbit_params,
    spawn_radius=10 * BODY_LENGTH,
)
