"""A learned replica fish as a behaviour of BlueBots (SPEC.md §4, used in the tank).

The replica network was learned in the study's abstract 2-D arena (side 300, speeds capped
at 9 per step). A BlueBot uses it by mapping its tank onto that arena: ``scale`` metres per
arena unit (the study's tank, 1.78 m across, makes σ = 40 units ≈ 0.24 m, about the
aggregation distance). Each visible neighbour's planar body-frame position goes through the
network exactly as in the arena; the summed, capped velocity times one control period is the
planar desired motion. Depth is held at the depth of the first perception.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import Behavior, Inbox, Perception, Steering, steady
from fishswarm.bluebot.parameters import BODY_LENGTH, Tank
from fishswarm.learning.arena import Arena, arena_from, cap_speed, replica_contributions
from fishswarm.learning.networks import REPLICA_SIZE
from fishswarm.learning.replica_file import load_replica

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

STUDY_SCALE = Tank().size[0] / Arena().side
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
    contribution = replica_contributions(
        weights[None, :], relative[None], within[None], arena=arena
    )[0]
    # Summed in neighbour order (running sum) so padding never changes a fish's result.
    # + 0.0: a padded batch's −0.0 becomes the +0.0 of a fish alone (see lennard_jones).
    total = (
        np.cumsum(contribution, axis=1)[:, -1] + 0.0
        if neighbors.shape[1]
        else np.zeros((neighbors.shape[0], 2))
    )
    velocity = cap_speed(total, cap=arena.speed_cap)
    motion: FloatArray = velocity * period * scale
    return motion


@dataclass(frozen=True)
class ReplicaParams:
    """Parameters of a learned replica on BlueBots.

    Attributes:
        weights: the replica network's 21 weights.
        scale: metres per arena unit.
        period: the arena step the replica was learned with, as a control period, s.
        arena: the arena it was learned in (range, speed cap, input scale).
    """

    weights: tuple[float, ...]
    scale: float = STUDY_SCALE
    period: float = 1.0
    arena: Arena = Arena()

    def __post_init__(self) -> None:
        if len(self.weights) != REPLICA_SIZE:
            raise ValueError(
                f"the replica behaviour needs the {REPLICA_SIZE} weights of a learned replica"
            )


@dataclass(frozen=True)
class ReplicaMemory:
    """What replica fish remember: the depth each holds, m (NaN before the first decision)."""

    hold_depth: FloatArray


def fresh_replica_memory(count: int) -> ReplicaMemory:
    """Replica fish that hold no depth yet."""
    return ReplicaMemory(np.full(count, np.nan))


def replica_params(settings: Mapping[str, Any]) -> ReplicaParams:
    """The weights of the model file named by the ``model`` setting.

    Raises:
        ValueError: no model is named, or the file is not a learned replica.
    """
    model = settings.get("model")
    if model is None:
        raise ValueError(
            "the replica behavior needs a learned model: --model runs/learn/best_replica.npz "
            "(make one with 'fishswarm learn')"
        )
    weights, learned = load_replica(Path(model))
    return ReplicaParams(
        tuple(float(w) for w in weights),
        period=float(settings.get("control_period", 1.0)),
        arena=arena_from(learned.get("arena", {})),
    )


def steer_replica(
    memory: ReplicaMemory, perception: Perception, inbox: Inbox, *, params: ReplicaParams
) -> tuple[ReplicaMemory, Steering]:
    """The replica's planar motion, holding the depth of the first perception."""
    depth = perception.depth
    hold = np.where(np.isnan(memory.hold_depth), depth, memory.hold_depth)
    planar = replica_motion(
        perception.neighbors,
        perception.neighbor_mask,
        weights=np.asarray(params.weights),
        scale=params.scale,
        period=params.period,
        arena=params.arena,
    )
    target = np.concatenate([planar, (hold - depth)[:, None]], axis=1)
    return ReplicaMemory(hold), steady(target)


REPLICA = Behavior(
    "replica",
    "a replica learned by 'fishswarm learn' (needs model); depth held",
    steer_replica,
    fresh_replica_memory,
    replica_params,
    spawn_radius=10 * BODY_LENGTH,
)
