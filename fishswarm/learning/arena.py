"""The 2-D arena of the imposter-fish study, batched over models (SPEC.md §4).

Abstract units: an arena of side 300, 25 fish, 15 s at 1 Hz, speeds capped at 9. Arrays carry
a model axis M first and a fish axis N: positions are (M, N, 2). The ideal fish and every
replica model run in one batch; all of them start from the same positions in a generation
(common random numbers), so that differences come from behaviour, not luck.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.networks import replica_outputs

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

REPLICA_KINDS = ("study", "reciprocal", "isotropic")
"""How a replica's network can make a neighbour's contribution (see :class:`Arena`)."""

SPREADS = {"dispersion": 20.0, "aggregation": 100.0}
"""Side of the square the fish start in: 20 makes the school disperse, 100 aggregate."""


@dataclass(frozen=True)
class Arena:
    """The study's 2-D world and its ideal fish.

    Attributes:
        side: arena side (fish are kept inside [0, side]²).
        fish: fish per simulation.
        steps: time steps per trial (15 s at 1 Hz).
        period: time step.
        speed_cap: largest speed.
        gain: k of the ideal fish.
        spacing: σ, the distance ideal fish settle at.
        communication_range: neighbours farther than this are ignored.
        replica_input_scale: a replica network sees a neighbour's relative position divided
            by this. At 40 the distances fish keep (10 to 50) fall where the logistic units
            bend; at 100 (the communication range, this project's first choice) the
            replica's weights must grow 2.5 times as large for the same turn, and CMA-ES
            found no replica that disperses even when fitted to the ideal fish's spacing
            directly (57 % off, against 9 % at 40; docs/learning.md).
        replica: how a replica's network makes a neighbour's contribution (one of
            :data:`REPLICA_KINDS`). ``study``: the network sees the neighbour's relative
            position in the arena's axes and its answer is the push, as in the study.
            ``reciprocal``: the odd part of that, ½(f(r) − f(−r)), so that neighbours on
            opposite sides push opposite ways. ``isotropic``: the network sees the
            neighbour straight ahead at its distance, (|r|, 0), and its answer is turned
            back by the neighbour's bearing, so that the law is the same in every direction
            (as the ideal fish's is) and opposite neighbours push opposite ways. The study's
            replica can give every neighbour the same push (its output biases alone do), and
            a school of 25 then drifts as one at full speed: dispersion replicas learned
            that way swam as fast as the ideal fish while their spacing grew a tenth as fast
            (docs/learning.md). Learning runs use ``isotropic`` by default
            (:class:`~fishswarm.learning.coevolution.LearningSettings`); an Arena is the
            study's unless told.
    """

    side: float = 300.0
    fish: int = 25
    steps: int = 15
    period: float = 1.0
    speed_cap: float = 9.0
    gain: float = 0.003
    spacing: float = 40.0
    communication_range: float = 100.0
    replica_input_scale: float = 40.0
    replica: str = "study"

    def __post_init__(self) -> None:
        if self.replica not in REPLICA_KINDS:
            raise ValueError(
                f"replica must be one of {', '.join(REPLICA_KINDS)}, got {self.replica!r}"
            )


EARLIER_REPLICA_INPUT_SCALE = 100.0
"""The input scale of replicas learned before it was a setting (files that do not name it)."""


def arena_from(data: Mapping[str, Any]) -> Arena:
    """The arena a checkpoint or replica file names (its ``arena`` settings); a file from
    before ``replica_input_scale`` existed had replicas see positions over 100, one from
    before ``replica`` existed had the study's replica or, if it says
    ``replica_reciprocal``, the reciprocal one."""
    values = dict(data)
    values.setdefault("replica_input_scale", EARLIER_REPLICA_INPUT_SCALE)
    reciprocal = values.pop("replica_reciprocal", False)
    values.setdefault("replica", "reciprocal" if reciprocal else "study")
    return Arena(**values)


def initial_positions(
    rng: np.random.Generator, *, arena: Arena, spread: float, models: int
) -> FloatArray:
    """(models, N, 2) start positions, uniform in a square of side ``spread`` at the arena
    centre, the same for every model."""
    one = arena.side / 2 + rng.uniform(-spread / 2, spread / 2, (arena.fish, 2))
    return np.broadcast_to(one, (models, arena.fish, 2)).copy()


def neighbors(positions: FloatArray, *, arena: Arena) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Relative positions r_ij = p_j − p_i (M, N, N, 2), distances (M, N, N) and which j are
    neighbours of i (within range, not i itself) (M, N, N)."""
    relative = positions[:, None, :, :] - positions[:, :, None, :]
    distance = np.sqrt(np.einsum("mijd,mijd->mij", relative, relative))
    within = distance <= arena.communication_range
    count = positions.shape[1]
    within &= ~np.eye(count, dtype=np.bool_)[None]
    return relative, distance, within


def cap_speed(velocity: FloatArray, *, cap: float) -> FloatArray:
    """Scale velocities (…, 2) down to at most ``cap`` in length."""
    speed = np.sqrt(np.einsum("...d,...d->...", velocity, velocity))
    scale = np.minimum(1.0, cap / np.maximum(speed, 1e-12))
    capped: FloatArray = velocity * scale[..., None]
    return capped


def ideal_velocity(positions: FloatArray, *, arena: Arena) -> FloatArray:
    """The ideal fish: v_i = Σ_j k·sgn(|r_ij| − σ)(|r_ij| − σ)²·r̂_ij over neighbours in range.

    Args:
        positions: (M, N, 2).
        arena: the arena and the ideal fish's parameters.

    Returns:
        (M, N, 2) velocities, capped at the speed cap.
    """
    relative, distance, within = neighbors(positions, arena=arena)
    gap = distance - arena.spacing
    magnitude = arena.gain * np.sign(gap) * gap * gap
    unit = relative / np.where(distance > 0, distance, 1.0)[..., None]
    velocity = np.einsum("mij,mijd->mid", magnitude * within, unit)
    return cap_speed(velocity, cap=arena.speed_cap)


def replica_velocity(positions: FloatArray, weights: FloatArray, *, arena: Arena) -> FloatArray:
    """Replica fish: each neighbour's contribution comes from the model's network.

    The network sees the neighbour's relative position divided by the arena's
    ``replica_input_scale`` (in the neighbour's own frame with ``arena.replica``
    ``isotropic``) and returns a direction (x, y in (−1, 1)) and a speed (in (0, 1) × speed
    cap); a neighbour contributes speed × direction (see :func:`replica_contributions`).
    Contributions are summed and the sum is capped.

    Args:
        positions: (M, N, 2), one row of fish per model.
        weights: (M, 21) one replica network per model.
        arena: the arena.

    Returns:
        (M, N, 2) velocities.
    """
    relative, _, within = neighbors(positions, arena=arena)
    contribution = replica_contributions(weights, relative, within, arena=arena)
    return cap_speed(contribution.sum(axis=2), cap=arena.speed_cap)


def replica_contributions(
    weights: FloatArray, relative: FloatArray, within: BoolArray, *, arena: Arena
) -> FloatArray:
    """What each neighbour adds to a replica fish's velocity, before summing and capping.

    Args:
        weights: (M, 21) one replica network per model.
        relative: (M, ..., 2) neighbours' positions relative to the fish, arena units.
        within: (M, ...) which neighbours count (in range, and real).
        arena: the arena (input scale and speed cap).

    Returns:
        (M, ..., 2) speed × direction of each neighbour, zero where not ``within``: the
        network's answer f(r) for ``arena.replica`` ``study``; its odd part,
        ½(f(r) − f(−r)), for ``reciprocal``; for ``isotropic``, its answer for the
        neighbour seen straight ahead, f((|r|, 0)), turned by the neighbour's bearing.
    """
    if arena.replica == "isotropic":
        contribution = _turned_to_each_neighbour(weights, relative, arena)
    else:
        scaled = relative / arena.replica_input_scale
        contribution = _network_push(replica_outputs(weights, scaled), arena)
        if arena.replica == "reciprocal":
            contribution = 0.5 * (
                contribution - _network_push(replica_outputs(weights, -scaled), arena)
            )
    result: FloatArray = contribution * within[..., None]
    return result


def _turned_to_each_neighbour(
    weights: FloatArray, relative: FloatArray, arena: Arena
) -> FloatArray:
    """Pushes (M, ..., 2) of an isotropic replica: the network sees each neighbour on its
    x axis at the neighbour's distance, and its answer (along, across) is turned back so
    that "along" points at the neighbour and "across" a quarter turn anticlockwise of it.
    A neighbour at the fish's own position (distance 0) has no bearing and pushes not."""
    distance = np.sqrt(np.einsum("...d,...d->...", relative, relative))
    seen = np.stack([distance / arena.replica_input_scale, np.zeros_like(distance)], -1)
    push = _network_push(replica_outputs(weights, seen), arena)
    unit = relative / np.where(distance > 0, distance, np.inf)[..., None]
    across = np.stack([-unit[..., 1], unit[..., 0]], -1)
    turned: FloatArray = push[..., :1] * unit + push[..., 1:] * across
    return turned


def _network_push(outputs: FloatArray, arena: Arena) -> FloatArray:
    """Speed × direction from replica network outputs (..., 3)."""
    direction = 2.0 * outputs[..., :2] - 1.0
    push: FloatArray = direction * (outputs[..., 2] * arena.speed_cap)[..., None]
    return push


def simulate(
    velocity: Callable[[FloatArray], FloatArray], start: FloatArray, *, arena: Arena
) -> FloatArray:
    """Run a trial.

    Args:
        velocity: positions (M, N, 2) → velocities (M, N, 2).
        start: (M, N, 2) start positions.
        arena: the arena.

    Returns:
        (M, steps + 1, N, 2) tracks, the start included; fish stay inside the arena.
    """
    tracks = np.empty((start.shape[0], arena.steps + 1, *start.shape[1:]))
    tracks[:, 0] = start
    positions = start
    for step in range(arena.steps):
        positions = np.clip(positions + velocity(positions) * arena.period, 0.0, arena.side)
        tracks[:, step + 1] = positions
    return tracks


def spacing_and_speed(tracks: FloatArray, *, arena: Arena) -> tuple[FloatArray, FloatArray]:
    """Mean neighbour distance (M, steps + 1) and mean speed (M, steps) of tracks.

    The neighbour distance is the mean distance between a fish and the schoolmates within
    communication range, averaged over fish: ideal fish settle with it near σ (about 35 for
    σ = 40, from either start).
    """
    spacing = np.empty(tracks.shape[:2])
    for step in range(tracks.shape[1]):
        _, distance, within = neighbors(tracks[:, step], arena=arena)
        total = (distance * within).sum(axis=2)
        count = within.sum(axis=2)
        per_fish = total / np.maximum(count, 1)
        with_mates = (count > 0).sum(axis=1)
        # A school whose fish all lost sight of each other has no spacing: NaN, not a warning.
        spacing[:, step] = np.where(
            with_mates > 0, per_fish.sum(axis=1) / np.maximum(with_mates, 1), np.nan
        )
    steps = np.diff(tracks, axis=1)
    speed = np.sqrt(np.einsum("mtnd,mtnd->mtn", steps, steps)).mean(axis=2) / arena.period
    return spacing, speed
