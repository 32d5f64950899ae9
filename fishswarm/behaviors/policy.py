"""A fish's whole decision: behaviour → desired motion → controller → fin gains.

Pure and batched: the fish actor calls it with a batch of one, the batch engine with the
whole swarm. The per-fish memory (controller state) goes in and comes out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.lennard_jones import lennard_jones
from fishswarm.behaviors.orbit import ORBIT_RADIUS, milling, orbit, waltz
from fishswarm.behaviors.replica import STUDY_SCALE, replica_motion
from fishswarm.bluebot.control import PidState, homing, pid

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Policy:
    """What a fish does.

    Attributes:
        behavior: ``dispersion`` or ``aggregation`` (both Lennard-Jones), ``orbit`` and
            ``milling`` (circle the landmark seen first), ``waltz`` (circle the nearest
            neighbour), or ``replica`` (a learned replica network; depth held).
        target_distance: Lennard-Jones r_t, m.
        controller: ``homing`` or ``pid``.
        control_period: s (for the pid loops, and the replica's step).
        caudal_cap: largest caudal gain of the homing controller.
        replica_weights: the replica network's 21 weights (``replica`` only).
        replica_scale: metres per arena unit (``replica`` only).
        orbit_radius: R of ``orbit`` and ``milling``, the partner distance of ``waltz``, m.
    """

    behavior: str
    target_distance: float
    controller: str = "homing"
    control_period: float = 1.0
    caudal_cap: float = 1.0
    replica_weights: tuple[float, ...] | None = None
    replica_scale: float = STUDY_SCALE
    orbit_radius: float = ORBIT_RADIUS

    def __post_init__(self) -> None:
        if self.behavior == "replica" and (
            self.replica_weights is None or len(self.replica_weights) != 21
        ):
            raise ValueError("the replica behaviour needs the 21 weights of a learned replica")


@dataclass(frozen=True)
class Memory:
    """What B fish remember between periods."""

    dorsal_on: BoolArray
    pid: PidState
    hold_depth: FloatArray

    @classmethod
    def fresh(cls, count: int) -> Memory:
        """Memory of ``count`` fish that have not acted yet."""
        return cls(np.zeros(count, dtype=np.bool_), PidState.zeros(count), np.full(count, np.nan))

    def take(self, index: NDArray[np.intp]) -> Memory:
        """The memory of the fish at ``index``."""
        return Memory(
            self.dorsal_on[index],
            PidState(self.pid.integral[index], self.pid.previous_error[index]),
            self.hold_depth[index],
        )

    def replaced(self, index: NDArray[np.intp], rows: Memory) -> Memory:
        """A copy in which the fish at ``index`` remember ``rows`` instead."""
        dorsal_on = self.dorsal_on.copy()
        integral = self.pid.integral.copy()
        previous_error = self.pid.previous_error.copy()
        hold_depth = self.hold_depth.copy()
        dorsal_on[index] = rows.dorsal_on
        integral[index] = rows.pid.integral
        previous_error[index] = rows.pid.previous_error
        hold_depth[index] = rows.hold_depth
        return Memory(dorsal_on, PidState(integral, previous_error), hold_depth)


def pad_neighbors(counts: NDArray[np.int64], stacked: FloatArray) -> tuple[FloatArray, BoolArray]:
    """Neighbours stacked fish after fish, as the padded batch the policy takes.

    Args:
        counts: (B,) how many neighbours each fish sees.
        stacked: (ΣK, 3) their body-frame positions, m, fish by fish.

    Returns:
        neighbors (B, K, 3) with K = max(counts), zero in the padding, and mask (B, K).
    """
    if counts.size == 1:  # one fish (a robot): nothing to pad
        return stacked[None], np.ones((1, stacked.shape[0]), dtype=np.bool_)
    width = int(counts.max()) if counts.size else 0
    mask: BoolArray = np.arange(width) < counts[:, None]
    neighbors = np.zeros((counts.size, width, 3))
    neighbors[mask] = stacked
    return neighbors, mask


def desired_motion(
    policy: Policy,
    neighbors: FloatArray,
    mask: BoolArray,
    depth: FloatArray,
    memory: Memory,
    landmarks: FloatArray | None = None,
    landmark_mask: BoolArray | None = None,
) -> tuple[FloatArray, Memory]:
    """(B, 3) body-frame target vector of B fish, m, and their memory after deciding."""
    if policy.behavior in ("dispersion", "aggregation"):
        target = lennard_jones(neighbors, mask, target_distance=policy.target_distance)
        return target, memory
    if policy.behavior == "waltz":
        return waltz(neighbors, mask, radius=policy.orbit_radius), memory
    if policy.behavior in ("orbit", "milling"):
        count = neighbors.shape[0]
        if landmarks is None or landmark_mask is None or landmarks.shape[1] == 0:
            centre, seen = np.zeros((count, 3)), np.zeros(count, dtype=np.bool_)
        else:
            centre, seen = landmarks[:, 0], landmark_mask[:, 0]
        if policy.behavior == "orbit":
            return orbit(centre, seen, radius=policy.orbit_radius), memory
        return milling(centre, seen, neighbors, mask, radius=policy.orbit_radius), memory
    assert policy.replica_weights is not None
    hold = np.where(np.isnan(memory.hold_depth), depth, memory.hold_depth)
    planar = replica_motion(
        neighbors,
        mask,
        weights=np.asarray(policy.replica_weights),
        scale=policy.replica_scale,
        period=policy.control_period,
    )
    target = np.concatenate([planar, (hold - depth)[:, None]], axis=1)
    return target, Memory(memory.dorsal_on, memory.pid, hold)


def act(
    policy: Policy,
    neighbors: FloatArray,
    mask: BoolArray,
    depth: FloatArray,
    memory: Memory,
    landmarks: FloatArray | None = None,
    landmark_mask: BoolArray | None = None,
) -> tuple[FloatArray, Memory]:
    """Fin gains of B fish for one control period.

    Args:
        policy: what the fish do.
        neighbors: (B, K, 3) visible neighbours in body frames, m.
        mask: (B, K) which neighbour rows are real.
        depth: (B,) each fish's own depth, m.
        memory: the fish's memory.
        landmarks: (B, L, 3) visible landmarks in body frames, m (the orbit centre first).
        landmark_mask: (B, L) which landmark rows are real.

    Returns:
        fins (B, 4) in [0, 1] (caudal, dorsal, pectoral left, pectoral right), new memory.
    """
    target, memory = desired_motion(
        policy, neighbors, mask, depth, memory, landmarks, landmark_mask
    )
    if policy.controller == "pid":
        fins, pid_state = pid(target, state=memory.pid, period=policy.control_period)
        return fins, Memory(memory.dorsal_on, pid_state, memory.hold_depth)
    fins, dorsal = homing(target, dorsal_on=memory.dorsal_on, caudal_cap=policy.caudal_cap)
    return fins, Memory(dorsal, memory.pid, memory.hold_depth)
