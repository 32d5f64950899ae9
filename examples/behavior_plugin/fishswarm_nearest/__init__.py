"""Nearest-neighbour keeping: each fish holds its nearest visible neighbour at a distance.

An example of a fishswarm behaviour in a package of its own (docs/behaviors.md). A fish
farther than ``target_distance`` from the nearest fish it sees swims towards it, a nearer one
swims away from it, and a fish that sees none swims straight on. Schools of such fish break
into chains and small clusters, spaced about ``target_distance`` apart.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fishswarm.behaviors.core import (
    Behavior,
    FloatArray,
    Inbox,
    NoMemory,
    Perception,
    Steering,
    no_memory,
    steady,
)
from fishswarm.bluebot.parameters import BODY_LENGTH

DEFAULT_DISTANCE = 2 * BODY_LENGTH
"""The distance kept from the nearest neighbour unless a scenario's target_distance says, m."""

CRUISE = np.array([4 * BODY_LENGTH, 0.0, 0.0])
"""Where a fish that sees nobody heads, in its body frame, m: straight on."""


@dataclass(frozen=True)
class NearestParams:
    """What nearest-neighbour keeping depends on.

    Attributes:
        distance: the distance kept from the nearest visible neighbour, m.
    """

    distance: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.distance) and self.distance > 0):
            raise ValueError(f"target_distance must be a positive length, got {self.distance!r}")


def nearest_params(settings: Mapping[str, Any]) -> NearestParams:
    """The distance kept from a scenario's ``target_distance``, 2 body lengths by default."""
    given = settings.get("target_distance")
    return NearestParams(DEFAULT_DISTANCE if given is None else float(given))


def steer_nearest(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: NearestParams
) -> tuple[NoMemory, Steering]:
    """Steer B fish to hold their nearest visible neighbour at ``params.distance``.

    Args:
        memory: nothing (this behaviour remembers nothing).
        perception: ``neighbors`` (B, K, 3) in each fish's body frame, m, with
            ``neighbor_mask`` (B, K) saying which rows are real.
        inbox: not read.
        params: the distance kept.

    Returns:
        The memory, and for each fish a target (B, 3) in its body frame, m: along the line
        to its nearest neighbour, as long as the gap to close (towards it when too far,
        away when too near); :data:`CRUISE` for a fish that sees nobody.
    """
    count = perception.count
    offsets = perception.neighbors
    target: FloatArray = np.tile(CRUISE, (count, 1))
    if offsets.shape[1] == 0:
        return memory, steady(target)
    distance = np.where(perception.neighbor_mask, np.linalg.norm(offsets, axis=2), np.inf)
    nearest = np.argmin(distance, axis=1)
    rows = np.arange(count)
    gap = distance[rows, nearest]
    seen = np.isfinite(gap)
    # A neighbour exactly where the fish is gives no direction: it then keeps its course.
    apart = seen & (gap > 0)
    direction = offsets[rows[apart], nearest[apart]] / gap[apart, None]
    target[apart] = direction * (gap[apart] - params.distance)[:, None]
    return memory, steady(target)


NEAREST = Behavior(
    "nearest",
    "keep the nearest visible neighbour at target_distance (an example package's)",
    steer_nearest,
    no_memory,
    nearest_params,
    spawn_radius=5 * BODY_LENGTH,
)
"""The behaviour, as the entry point ``fishswarm.behaviors: nearest`` names it."""
