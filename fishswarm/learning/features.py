"""What a classifier sees of one fish's track, per time step.

Inputs, in any combination (SPEC.md §4): ``speed``; ``angular-speed``; ``nearest``, the
distance to the nearest schoolmate (not in the study: a swarm-level view of spacing that
needs no learned radius); ``counts``, the numbers of schoolmates within fixed radii
(:data:`COUNT_RADII`; not in the study either); ``neighbors``, the number of schoolmates
within a radius the classifier learns; ``neighbors2``, the numbers within two learned radii.
Inputs are scaled to about [0, 1]: speed by the speed cap, angular speed by π, the nearest
distance by the communication range (capped at 1), counts by the number of schoolmates.

A sample is one fish's track in one trial; a trial of N fish gives N samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.arena import Arena

FloatArray = NDArray[np.float64]

INPUTS = ("speed", "angular-speed", "nearest", "counts", "neighbors", "neighbors2")

FIXED_INPUTS = ("speed", "angular-speed", "nearest", "counts")
"""Inputs that do not depend on the classifier (no learned radius)."""

COUNT_RADII = (15.0, 30.0, 60.0)
"""The radii of the ``counts`` input, arena units: inside, about and beyond the spacing the
ideal fish keep (about 35). Learned radii stay near where they start (≈ 150 from the middle
of their range, counting almost the whole school), so classifiers that learn theirs judge
by speed alone; fixed ones see spacing from the first generation (docs/learning.md)."""


def check_inputs(inputs: tuple[str, ...]) -> tuple[str, ...]:
    """Validate a choice of classifier inputs.

    The order is kept; no name may repeat, nor may ``neighbors`` and ``neighbors2`` go
    together."""
    unknown = [name for name in inputs if name not in INPUTS]
    if unknown or not inputs or len(set(inputs)) != len(inputs):
        raise ValueError(
            f"classifier inputs must be distinct names from {', '.join(INPUTS)}, got {inputs}"
        )
    if "neighbors" in inputs and "neighbors2" in inputs:
        raise ValueError("choose neighbors (one radius) or neighbors2 (two radii), not both")
    return inputs


def radii_count(inputs: tuple[str, ...]) -> int:
    """How many radii a classifier with these inputs learns."""
    return 2 if "neighbors2" in inputs else 1 if "neighbors" in inputs else 0


def feature_count(inputs: tuple[str, ...]) -> int:
    """How many numbers per step a classifier with these inputs sees."""
    fixed = sum(
        len(COUNT_RADII) if name == "counts" else 1 for name in inputs if name in FIXED_INPUTS
    )
    return fixed + radii_count(inputs)


@dataclass(frozen=True)
class Samples:
    """The part of S samples that does not depend on the classifier.

    Attributes:
        fixed: (S, T, K) speed, angular speed, nearest distance and fixed-radius counts as
            chosen, scaled (K may be 0).
        mate_distance: (S, T, N − 1) distances to the schoolmates at each step.
    """

    fixed: FloatArray
    mate_distance: FloatArray


def samples_from(tracks: FloatArray, inputs: tuple[str, ...], *, arena: Arena) -> Samples:
    """Turn trials into samples.

    Args:
        tracks: (M, T + 1, N, 2) from :func:`fishswarm.learning.arena.simulate`.
        inputs: classifier inputs.
        arena: the arena.

    Returns:
        M·N samples (trial-major) with T steps each.
    """
    models, frames, count, _ = tracks.shape
    steps = np.diff(tracks, axis=1)  # (M, T, N, 2)
    later = tracks[:, 1:]  # positions after each step
    difference = later[:, :, None, :, :] - later[:, :, :, None, :]
    distance = np.sqrt(np.einsum("mtijd,mtijd->mtij", difference, difference))
    others = ~np.eye(count, dtype=bool)
    mates = distance[..., others].reshape(models, frames - 1, count, count - 1)
    columns = []
    if "speed" in inputs:
        speed = np.sqrt(np.einsum("mtnd,mtnd->mtn", steps, steps)) / arena.period
        columns.append(speed / arena.speed_cap)
    if "angular-speed" in inputs:
        heading = np.arctan2(steps[..., 1], steps[..., 0])
        turn = np.zeros_like(heading)
        turn[:, 1:] = np.abs(np.angle(np.exp(1j * np.diff(heading, axis=1))))
        columns.append(turn / np.pi)
    if "nearest" in inputs:
        columns.append(np.minimum(mates.min(axis=-1) / arena.communication_range, 1.0))
    if "counts" in inputs:
        columns.extend((mates < radius).sum(axis=-1) / (count - 1) for radius in COUNT_RADII)
    fixed = np.stack(columns, axis=-1) if columns else np.zeros((models, frames - 1, count, 0))
    fixed = fixed.transpose(0, 2, 1, 3).reshape(models * count, frames - 1, -1)
    mate_distance = mates.transpose(0, 2, 1, 3).reshape(models * count, frames - 1, count - 1)
    return Samples(np.ascontiguousarray(fixed), np.ascontiguousarray(mate_distance))


def neighbor_counts(samples: Samples, radii: FloatArray, *, chunk: int = 8) -> FloatArray:
    """Scaled schoolmate counts within each classifier's radii.

    Args:
        samples: the samples.
        radii: (C, R) radii of C classifiers.
        chunk: classifiers compared at once (bounds the memory used).

    Returns:
        (C, S, T, R) counts / (N − 1).
    """
    count, radius_count = radii.shape
    mates = samples.mate_distance
    result = np.empty((count, *mates.shape[:2], radius_count))
    for start in range(0, count, chunk):
        block = radii[start : start + chunk]
        within = mates[None, :, :, None, :] < block[:, None, None, :, None]
        result[start : start + chunk] = within.sum(axis=-1)
    scaled: FloatArray = result / mates.shape[-1]
    return scaled
