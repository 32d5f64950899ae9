"""Random streams: one generator per (seed, role, member), derived with ``SeedSequence``.

A fish's draws never depend on how many others there are or in which process they run.
"""

from __future__ import annotations

import enum

import numpy as np


class Stream(enum.IntEnum):
    """Roles that own a random stream."""

    SPAWN = 1
    VISION = 2
    CHANNEL = 3
    JITTER = 4
    LIGHT = 5
    """The channel's losses of the robots' lights it shows simulated fish."""


def stream(seed: int, role: Stream, member: int) -> np.random.Generator:
    """The random generator of ``member`` in ``role`` for master ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(int(role), member)))
