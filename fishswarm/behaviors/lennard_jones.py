"""Lennard-Jones aggregation and dispersion (SPEC.md §2).

The potential V(r) = ε[(r_t/r)¹² − 2(r_t/r)⁶] has its minimum at the target distance r_t.
Each visible neighbour contributes −dV/dr along its direction: away from it when closer than
r_t, towards it beyond. Contributions are averaged. Distances are capped at r_t + 1 body
length in the force, so that far fish do not dominate.

With the default ε = r_t²/72 the force linearises to the spacing error near equilibrium
(−dV/dr ≈ −(r − r_t)), so the result reads as a displacement in metres: how far and where a
fish wants to move.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import BODY_LENGTH

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

AGGREGATION_DISTANCE = 2 * BODY_LENGTH
"""Target distance of aggregation, m (2 body lengths = 0.26 m)."""

MIN_DISTANCE = 1e-3
"""Distances below this count as this in the force, m: coincident fish stay finite."""


def default_epsilon(target_distance: float) -> float:
    """ε = r_t²/72, which makes −dV/dr ≈ r_t − r near the minimum (units m²)."""
    return target_distance**2 / 72.0


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
    ratio6 = (target_distance / distance) ** 6
    result: FloatArray = 12.0 * epsilon / distance * (ratio6 * ratio6 - ratio6)
    return result


def lennard_jones(
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    target_distance: float,
    epsilon: float | None = None,
    cap: float = BODY_LENGTH,
) -> FloatArray:
    """Desired motion of B fish from the neighbours they see.

    Args:
        neighbors: (B, K, 3) body-frame positions of the visible neighbours, m.
        mask: (B, K) which rows are real.
        target_distance: r_t, m: 0.26 (2 body lengths) aggregates, the tank diagonal disperses.
        epsilon: ε in m²; defaults to :func:`default_epsilon`.
        cap: distances are capped at r_t + cap in the force, m.

    Returns:
        (B, 3) target vector in the body frame, m; zero for a fish that sees nobody.
    """
    if target_distance <= 0:
        raise ValueError(f"target_distance must be positive, got {target_distance}")
    eps = default_epsilon(target_distance) if epsilon is None else epsilon
    distance = np.linalg.norm(neighbors, axis=2)
    capped = np.clip(distance, MIN_DISTANCE, target_distance + cap)
    magnitude = lennard_jones_force(capped, target_distance=target_distance, epsilon=eps)
    safe = np.where(distance > 0, distance, 1.0)
    direction = np.where((distance > 0)[..., None], neighbors / safe[..., None], 0.0)
    # Repulsion (positive) points away from the neighbour: −magnitude along its direction.
    contribution = -magnitude[..., None] * direction * mask[..., None]
    count = mask.sum(axis=1)
    # Summed in neighbour order so that padding (zeros at the end) never changes a result:
    # a fish alone (batch of one) and the same fish in a padded swarm batch agree exactly.
    total = np.zeros((neighbors.shape[0], 3))
    for k in range(neighbors.shape[1]):
        total += contribution[:, k]
    result: FloatArray = np.where(count[:, None] > 0, total / np.maximum(count, 1)[:, None], 0.0)
    return result
