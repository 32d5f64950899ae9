"""A learned replica fish as a behaviour of BlueBots (SPEC.md §4, used in the tank).

The replica network was learned in the study's abstract 2-D arena (side 300, speeds capped
at 9 per step). A BlueBot uses it by mapping its tank onto that arena: ``scale`` metres per
arena unit (the study's tank, 1.78 m across, makes σ = 40 units ≈ 0.24 m, about the
aggregation distance). Each visible neighbour's planar body-frame position goes through the
network exactly as in the arena; the summed, capped velocity times one control period is the
planar desired motion. Depth is held at the depth of the first perception.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.arena import Arena, cap_speed
from fishswarm.learning.networks import replica_outputs

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

STUDY_SCALE = 1.78 / 300.0
"""Metres per arena unit when the study's tank stands for the arena."""


def replica_motion(
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    weights: FloatArray,
    scale: float = STUDY_SCALE,
    period: float = 1.0,
    arena: Arena = Arena(),
) -> FloatArray:
    """Planar desired motion of B fish from a learned replica.

    Args:
        neighbors: (B, K, 3) visible neighbours in body frames, m.
        mask: (B, K) which rows are real.
        weights: (21,) the replica network.
        scale: metres per arena unit.
        period: control period, s (the arena steps once per period).
        arena: the arena the replica was learned in (range and speed cap).

    Returns:
        (B, 2) desired displacement in the body frame (x forward, y right), m.
    """
    relative = neighbors[:, :, :2] / scale
    distance = np.sqrt(np.einsum("bkd,bkd->bk", relative, relative))
    within = mask & (distance <= arena.communication_range)
    outputs = replica_outputs(weights[None, :], relative[None] / arena.communication_range)[0]
    direction = 2.0 * outputs[..., :2] - 1.0
    speed = outputs[..., 2] * arena.speed_cap
    contribution = direction * (speed * within)[..., None]
    # Summed in neighbour order (running sum) so padding never changes a fish's result.
    total = (
        np.cumsum(contribution, axis=1)[:, -1]
        if neighbors.shape[1]
        else np.zeros((neighbors.shape[0], 2))
    )
    velocity = cap_speed(total, arena.speed_cap)
    motion: FloatArray = velocity * period * scale
    return motion
