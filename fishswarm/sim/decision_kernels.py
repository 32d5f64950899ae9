"""Compiled decisions for large simulated schools: the Lennard-Jones target vectors as one
loop (numba).

:func:`fishswarm.behaviors.lennard_jones.lennard_jones` builds (fish × neighbours) arrays of
distances, forces and contributions and sums them column by column; at thousands of fish
that is the largest part of a decision (10 000 fish with 46 neighbour rows: 10.9 ms). Here
each fish's neighbours are summed in one pass with nothing stored between (3.2 ms). The
operations are the numpy path's, in its order and without contraction into fused
multiply-adds (numba's default), so the results agree bit for bit: which path a batch takes
never shows in a trajectory, and a fish deciding alone equals the same fish in a school.

The simulator hands this loop to the fish of a swarm of
:data:`~fishswarm.sim.kernels.COMPILED_MIN_FISH` fish or more (:func:`with_compiled_decisions`:
the batch engine, the launcher's fish workers, ``fishswarm fish``); a robot's fish keeps the
numpy path. numba is optional (``pip install -e '.[fast]'``) and imported only when
the loop is first asked for; the robot's import path never reaches this module.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import FishParams
from fishswarm.behaviors.lennard_jones import LennardJonesParams
from fishswarm.sim import kernels

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def with_compiled_decisions(params: FishParams, fish: int) -> FishParams:
    """The fish's parameters for a simulated swarm of ``fish``: Lennard-Jones steering with
    the compiled loop from :data:`~fishswarm.sim.kernels.COMPILED_MIN_FISH` fish on when numba
    is installed (below, loading numba costs a process more than the loop saves); anything
    else as it is."""
    steering = params.steering
    if not isinstance(steering, LennardJonesParams) or not kernels.compiles(fish):
        return params
    compiled = dataclasses.replace(steering, compiled=lennard_jones_target_vectors)
    return dataclasses.replace(params, steering=compiled)


def prepare(params: FishParams) -> None:
    """Load the compiled loop now if ``params`` use it (from numba's cache, or compiled):
    a fish worker does so before it reports ready, so that its first decision does not
    stall its event loop for the half second numba takes to load."""
    steering = params.steering
    if isinstance(steering, LennardJonesParams) and steering.compiled is not None:
        steering.compiled(
            np.zeros((1, 1, 3)),
            np.zeros((1, 1), dtype=np.bool_),
            target_distance=steering.target_distance,
            epsilon=steering.epsilon,
            cap=1.0,
            floor=1.0,
            study_form=steering.study_form,
        )


def lennard_jones_target_vectors(
    neighbors: FloatArray,
    mask: BoolArray,
    *,
    target_distance: float,
    epsilon: float,
    cap: float,
    floor: float,
    study_form: bool,
) -> FloatArray:
    """Lennard-Jones target vectors of B fish, compiled
    (a :class:`~fishswarm.behaviors.lennard_jones.TargetVectors`).

    Args:
        neighbors: (B, K, 3) body-frame positions of the visible neighbours, m.
        mask: (B, K) which rows are real.
        target_distance: r_t, m.
        epsilon: ε in the force (the study's gain in its form), m².
        cap: distances are capped at r_t + cap in the force, m.
        floor: distances below this count as this in the force, m.
        study_form: each force times the neighbour's relative position instead of its
            direction.

    Returns:
        (B, 3) the mean contribution of each fish's neighbours, m (zero without any):
        bit for bit :func:`fishswarm.behaviors.lennard_jones.lennard_jones`.
    """
    if neighbors.ndim != 3 or neighbors.shape[2] != 3 or mask.shape != neighbors.shape[:2]:
        raise ValueError(
            f"neighbors must be (B, K, 3) and mask (B, K), got {neighbors.shape} and {mask.shape}"
        )
    result = np.empty((neighbors.shape[0], 3))
    # Writeable C arrays of one dtype each: one compiled signature for every caller (a fish
    # deciding alone hands in a read-only view, which numba would compile anew for).
    _loop()(
        np.require(neighbors, np.float64, ("C", "W")),
        np.require(mask, np.bool_, ("C", "W")),
        float(target_distance),
        float(epsilon),
        float(cap),
        float(floor),
        bool(study_form),
        result,
    )
    return result


@functools.cache
def _loop() -> Callable[..., None]:
    """The compiled loop over fish and their neighbours (compiled on first use, cached on
    disk)."""
    import numba

    # One core, the GIL released: a fish worker's Zenoh callbacks run beside it, and the
    # world's parallel kernels keep the other core. numpy's error model: a division by zero
    # gives inf or nan as numpy's does, rather than raising.
    @numba.njit(cache=True, nogil=True, error_model="numpy")
    def loop(
        neighbors: Any,
        mask: Any,
        target_distance: float,
        epsilon: float,
        cap: float,
        floor: float,
        study_form: bool,
        result: Any,
    ) -> None:  # pragma: no cover - compiled; its tests compare it with the numpy path
        fish, rows = mask.shape
        ceiling = target_distance + cap
        for i in range(fish):
            total_x = 0.0
            total_y = 0.0
            total_z = 0.0
            count = 0
            for j in range(rows):
                x = neighbors[i, j, 0]
                y = neighbors[i, j, 1]
                z = neighbors[i, j, 2]
                distance = np.sqrt(x * x + y * y + z * z)
                capped = min(max(distance, floor), ceiling)
                ratio = target_distance / capped
                ratio2 = ratio * ratio
                ratio6 = ratio2 * ratio2 * ratio2
                magnitude = 12.0 * epsilon / capped * (ratio6 * ratio6 - ratio6)
                real = mask[i, j] and distance > 0
                length = 1.0 if study_form or not real else distance
                scale = -magnitude / length * (1.0 if real else 0.0)
                # The numpy path starts from the first contribution rather than from 0.0:
                # the two differ at most in the sign of a zero, which + 0.0 below settles.
                total_x += x * scale
                total_y += y * scale
                total_z += z * scale
                count += mask[i, j]
            seen = max(count, 1)
            result[i, 0] = (total_x + 0.0) / seen
            result[i, 1] = (total_y + 0.0) / seen
            result[i, 2] = (total_z + 0.0) / seen

    return loop
