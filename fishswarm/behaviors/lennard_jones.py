"""Lennard-Jones aggregation and dispersion (SPEC.md §2).

The potential V(r) = ε[(r_t/r)¹² − 2(r_t/r)⁶] has its minimum at the target distance r_t.
Each visible neighbour contributes −dV/dr along its direction: away from it when closer than
r_t, towards it beyond. Contributions are averaged. Distances are capped at r_t + 1 body
length in the force, so that far fish do not dominate.

The result is a target vector in the body frame that the controller reads as a
displacement in metres (the homing controller's caudal gain grows with its length). With
ε = 1 m² (the default) a fish swims briskly until it is close to the target distance; the
smaller ε = r_t²/72, for which −dV/dr ≈ r_t − r near the minimum, leaves aggregating fish
almost still (measured with the batch engine, 25 fish, 15 s, 3 seeds: mean pairwise distance
−1 % with r_t²/72, −12 % with 100·r_t²/72, −42 % with ε = 1 m²; dispersion +212 % in all).

The study's code (SPEC §8) multiplied the force by the *unnormalised* relative position, so a
neighbour pulls or pushes in proportion to its distance too, with γ·ε = 100·100 in
millimetres; :data:`STUDY_GAIN` is that scale in metres, and ``study_form`` switches to it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

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
from fishswarm.bluebot.parameters import BODY_LENGTH, Tank

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

AGGREGATION_DISTANCE = 2 * BODY_LENGTH
"""Target distance of aggregation, m (2 body lengths = 0.26 m)."""

MIN_DISTANCE = 1e-3
"""Distances below this count as this in the force, m: coincident fish stay finite."""


DEFAULT_EPSILON = 1.0
"""Depth of the potential ε, m²."""

STUDY_GAIN = 100 * 100 * 1e-3
"""The study code's γ·ε = 100·100 with distances in mm, in metres: its target vector
−γε/r·(12(r_t/r)¹² − 12(r_t/r)⁶)·Δp is in mm with every length in mm; in metres the same
vector is this gain /r·(…)·Δp with r and Δp in metres (the bracket has no unit)."""

STUDY_FORM_SWITCH = "lennard-jones"
"""The study-code switch (a scenario's ``study_code``) that selects the study's form."""

RUNNING_SUM_LOOP_MIN = 128
"""From this many fish in a batch the neighbours' contributions are summed in a loop over
the neighbour axis (same order, same bits) instead of numpy's running sum along it. The
whole decision, measured: 5 000 fish with 50 neighbour rows 9.8 → 8.2 ms, 200 fish with 30
0.42 → 0.28 ms; at 100 fish the running sum is still quicker (0.10 against 0.13 ms)."""

BLOCK_FISH = 1024
"""Fish decided at a time in a larger batch: a block's (fish × neighbours) arrays stay in a
core's cache where the whole batch's would not (the same bits; measured, Lennard-Jones
alone, 46 neighbour rows: 10 000 fish 14.7 → 10.2 ms, 5 000 fish 6.3 → 4.9 ms; blocks of
512 or 2 048 fish do less well)."""

STUDY_MIN_DISTANCE = 1e-6
"""The study code clipped distances below 0.001 mm, in metres."""


class TargetVectors(Protocol):
    """The target vectors of :func:`lennard_jones` computed another way — bit for bit the
    same — e.g. the simulator's compiled loop for large schools
    (:func:`fishswarm.sim.decision_kernels.lennard_jones_target_vectors`)."""

    def __call__(
        self,
        neighbors: FloatArray,
        mask: BoolArray,
        *,
        target_distance: float,
        epsilon: float,
        cap: float,
        floor: float,
        study_form: bool,
    ) -> FloatArray: ...


def lennard_jones_force(
    distance: FloatArray, *, target_distance: float, epsilon: float
) -> FloatArray:
    """−dV/dr: positive pushes apart, negative pulls together.

    Args:
        distance: any shape, m (already capped by the caller if wanted).
        target_distance: r_t, m.
        epsilon: ε, m².

    Returns:
        Same shape as ``distance``, m.
    """
    ratio2 = (target_distance / distance) ** 2
    ratio6 = ratio2 * ratio2 * ratio2
    result: FloatArray = 12.0 * epsilon / distance * (ratio6 * ratio6 - ratio6)
    return result


def lennard_jones(
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    target_distance: float,
    epsilon: float = DEFAULT_EPSILON,
    cap: float = BODY_LENGTH,
    study_form: bool = False,
    compiled: TargetVectors | None = None,
) -> FloatArray:
    """Desired motion of B fish from the neighbours they see.

    Args:
        neighbors: (B, K, 3) body-frame positions of the visible neighbours, m.
        mask: (B, K) which rows are real.
        target_distance: r_t, m: 0.26 (2 body lengths) aggregates, the tank diagonal disperses.
        epsilon: ε, m².
        cap: distances are capped at r_t + cap in the force, m.
        study_form: the study code's form: each force times the neighbour's relative
            position instead of its direction, with ε replaced by :data:`STUDY_GAIN` (m) and
            distances clipped below at :data:`STUDY_MIN_DISTANCE`.
        compiled: computes the same vectors (with ε already the study's gain in its form,
            and the floor of the distances); None: numpy.

    Returns:
        (B, 3) target vector in the body frame, m; zero for a fish that sees nobody.
    """
    if target_distance <= 0:
        raise ValueError(f"target_distance must be positive, got {target_distance}")
    fish = neighbors.shape[0]
    if fish == 0 or neighbors.shape[1] == 0:
        return np.zeros((fish, 3))
    # The form's constants, once for either path.
    gain = STUDY_GAIN if study_form else epsilon
    floor = STUDY_MIN_DISTANCE if study_form else MIN_DISTANCE
    if compiled is not None:
        return compiled(
            neighbors,
            mask,
            target_distance=target_distance,
            epsilon=gain,
            cap=cap,
            floor=floor,
            study_form=study_form,
        )
    blocks = [slice(start, start + BLOCK_FISH) for start in range(0, fish, BLOCK_FISH)]
    results = [
        _lennard_jones_block(
            neighbors[block],
            mask[block],
            target_distance=target_distance,
            epsilon=gain,
            cap=cap,
            floor=floor,
            study_form=study_form,
            loop=fish >= RUNNING_SUM_LOOP_MIN,  # the whole batch's choice, in every block
        )
        for block in blocks
    ]
    return results[0] if len(results) == 1 else np.concatenate(results)


def _lennard_jones_block(
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    target_distance: float,
    epsilon: float,
    cap: float,
    floor: float,
    study_form: bool,
    loop: bool,
) -> FloatArray:
    """:func:`lennard_jones` of a block of fish (``loop``: sum neighbour by neighbour), with
    ε already the study's gain in its form."""
    # The squares added column by column, in the order a reduction over the last axis adds
    # them (the same bits), but 6× faster at thousands of fish: numpy reduces an axis of
    # three slowly. Ufuncs called directly: at the batch of one a fish actor decides with,
    # numpy's Python wrappers cost as much as the arithmetic.
    square = neighbors * neighbors
    distance = np.sqrt(square[..., 0] + square[..., 1] + square[..., 2])
    capped = np.minimum(np.maximum(distance, floor), target_distance + cap)
    magnitude = lennard_jones_force(capped, target_distance=target_distance, epsilon=epsilon)
    # Repulsion (positive) points away from the neighbour: −magnitude along its unit vector
    # (the study's form: along the relative position itself). A coincident neighbour
    # (distance 0) has no direction and contributes nothing.
    real = mask & (distance > 0)
    length = 1.0 if study_form else np.where(real, distance, 1.0)
    scale = -magnitude / length * real
    count = np.add.reduce(mask, axis=1)
    # A running sum adds in neighbour order, so padding (zeros at the end) never changes a
    # result: a fish alone (batch of one) and the same fish in a padded batch agree exactly.
    # + 0.0 turns the −0.0 of a fish that sees nobody in a padded batch into +0.0, the
    # zero a fish deciding alone gets: atan2(−0, −0) is −180°, and the fish would turn.
    if not loop:
        total = np.add.accumulate(neighbors * scale[..., None], axis=1)[:, -1] + 0.0
    else:
        # The same sum, neighbour by neighbour: for thousands of fish a loop over the
        # neighbour axis is three times as fast as numpy's running sum along a middle
        # axis, and needs no (B, K, 3) array of contributions.
        total = neighbors[:, 0] * scale[:, :1]
        for column in range(1, neighbors.shape[1]):
            total += neighbors[:, column] * scale[:, column, None]
        total += 0.0
    result: FloatArray = total / np.maximum(count, 1)[:, None]
    return result


@dataclass(frozen=True)
class LennardJonesParams:
    """Parameters of Lennard-Jones aggregation and dispersion.

    Attributes:
        target_distance: r_t, m.
        epsilon: ε, m².
        study_form: the study code's force form (:func:`lennard_jones`).
        compiled: the same vectors computed another way (:func:`lennard_jones`), e.g. a
            simulator's for a large school; None: numpy.
    """

    target_distance: float
    epsilon: float = DEFAULT_EPSILON
    study_form: bool = False
    compiled: TargetVectors | None = None

    def __post_init__(self) -> None:
        if not self.target_distance > 0:
            raise ValueError(f"target_distance must be positive, got {self.target_distance}")


def steer_lennard_jones(
    memory: NoMemory, perception: Perception, inbox: Inbox, *, params: LennardJonesParams
) -> tuple[NoMemory, Steering]:
    """Lennard-Jones steering: towards the potential's minimum among the visible neighbours."""
    target = lennard_jones(
        perception.neighbors,
        perception.neighbor_mask,
        target_distance=params.target_distance,
        epsilon=params.epsilon,
        study_form=params.study_form,
        compiled=params.compiled,
    )
    return memory, steady(target)


def aggregation_params(settings: Mapping[str, Any]) -> LennardJonesParams:
    """r_t from the settings, 2 body lengths by default."""
    given = settings.get("target_distance")
    return LennardJonesParams(
        AGGREGATION_DISTANCE if given is None else float(given),
        study_form=_study_form(settings),
    )


def dispersion_params(settings: Mapping[str, Any]) -> LennardJonesParams:
    """r_t from the settings, the tank diagonal by default."""
    given = settings.get("target_distance")
    diagonal = Tank(tuple(settings["tank"])).diagonal
    return LennardJonesParams(
        diagonal if given is None else float(given), study_form=_study_form(settings)
    )


def _study_form(settings: Mapping[str, Any]) -> bool:
    return STUDY_FORM_SWITCH in settings.get("study_code", ())


AGGREGATION = Behavior(
    "aggregation",
    "Lennard-Jones towards neighbours at 2 body lengths (target_distance)",
    steer_lennard_jones,
    no_memory,
    aggregation_params,
    spawn_radius=10 * BODY_LENGTH,
)
DISPERSION = Behavior(
    "dispersion",
    "Lennard-Jones with the target distance at the tank diagonal: spread out",
    steer_lennard_jones,
    no_memory,
    dispersion_params,
    spawn_radius=2 * BODY_LENGTH,
)
