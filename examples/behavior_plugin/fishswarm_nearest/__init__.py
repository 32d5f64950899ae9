"""Nearest-neighbour keeping: each fish holds its nearest visible neighbour at a distance.

An example of a fishswarm behaviour in a package of its own (docs/behaviors.md). A fish
farther than ``distance`` from the nearest fish it sees swims towards it, a nearer one swims
away from it, and a fish that sees none swims straight on, ``cruise`` ahead. Schools of such
fish break into chains and small clusters, spaced about ``distance`` apart. Both are the
behaviour's own settings: ``--behavior-setting distance=0.3`` on the command line,
``behavior_settings = { distance = 0.3 }`` in a scenario file, or swept by an experiment.
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

SETTINGS = {"distance": 2 * BODY_LENGTH, "cruise": 4 * BODY_LENGTH}
"""The behaviour's own settings and their defaults, m: the distance kept from the nearest
visible neighbour (2 body lengths), and how far ahead a fish that sees nobody aims (4)."""


@dataclass(frozen=True)
class NearestParams:
    """What nearest-neighbour keeping depends on.

    Attributes:
        distance: the distance kept from the nearest visible neighbour, m.
        cruise: how far straight ahead a fish that sees nobody aims, m.
    """

    distance: float
    cruise: float

    def __post_init__(self) -> None:
        for name in ("distance", "cruise"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive length in m, got {value!r}")


def nearest_params(settings: Mapping[str, Any]) -> NearestParams:
    """The parameters from a scenario's settings: the behaviour's own, defaults filled in."""
    own = settings["behavior_settings"]
    return NearestParams(float(own["distance"]), float(own["cruise"]))


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
        away when too near); ``params.cruise`` straight ahead for a fish that sees nobody.
    """
    count = perception.count
    offsets = perception.neighbors
    target: FloatArray = np.zeros((count, 3))
    target[:, 0] = params.cruise
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
    "keep the nearest visible neighbour at a distance (an example package's)",
    steer_nearest,
    no_memory,
    nearest_params,
    spawn_radius=5 * BODY_LENGTH,
    settings=SETTINGS,
)
"""The behaviour, as the entry point ``fishswarm.behaviors: nearest`` names it."""
