"""A fish's whole decision: behaviour → desired motion → controller → fin gains.

Pure and batched: the fish actor calls it with a batch of one, the batch engine with the
whole swarm. The per-fish memory (controller state) goes in and comes out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.lennard_jones import lennard_jones
from fishswarm.bluebot.control import PidState, homing, pid

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Policy:
    """What a fish does.

    Attributes:
        behavior: ``dispersion`` or ``aggregation`` (both Lennard-Jones).
        target_distance: Lennard-Jones r_t, m.
        controller: ``homing`` or ``pid``.
        control_period: s (for the pid loops).
        caudal_cap: largest caudal gain of the homing controller.
    """

    behavior: str
    target_distance: float
    controller: str = "homing"
    control_period: float = 1.0
    caudal_cap: float = 1.0


@dataclass(frozen=True)
class Memory:
    """What B fish remember between periods."""

    dorsal_on: BoolArray
    pid: PidState

    @classmethod
    def fresh(cls, count: int) -> Memory:
        """Memory of ``count`` fish that have not acted yet."""
        return cls(np.zeros(count, dtype=np.bool_), PidState.zeros(count))

    def take(self, index: NDArray[np.intp]) -> Memory:
        """The memory of the fish at ``index``."""
        return Memory(
            self.dorsal_on[index],
            PidState(self.pid.integral[index], self.pid.previous_error[index]),
        )

    def replaced(self, index: NDArray[np.intp], rows: Memory) -> Memory:
        """A copy in which the fish at ``index`` remember ``rows`` instead."""
        dorsal_on = self.dorsal_on.copy()
        integral = self.pid.integral.copy()
        previous_error = self.pid.previous_error.copy()
        dorsal_on[index] = rows.dorsal_on
        integral[index] = rows.pid.integral
        previous_error[index] = rows.pid.previous_error
        return Memory(dorsal_on, PidState(integral, previous_error))


def desired_motion(policy: Policy, neighbors: FloatArray, mask: BoolArray) -> FloatArray:
    """(B, 3) body-frame target vector of B fish, m."""
    return lennard_jones(neighbors, mask, target_distance=policy.target_distance)


def act(
    policy: Policy, neighbors: FloatArray, mask: BoolArray, memory: Memory
) -> tuple[FloatArray, Memory]:
    """Fin gains of B fish for one control period.

    Args:
        policy: what the fish do.
        neighbors: (B, K, 3) visible neighbours in body frames, m.
        mask: (B, K) which neighbour rows are real.
        memory: the fish's memory.

    Returns:
        fins (B, 4) in [0, 1] (caudal, dorsal, pectoral left, pectoral right), new memory.
    """
    target = desired_motion(policy, neighbors, mask)
    if policy.controller == "pid":
        fins, pid_state = pid(target, state=memory.pid, period=policy.control_period)
        return fins, Memory(memory.dorsal_on, pid_state)
    fins, dorsal = homing(target, dorsal_on=memory.dorsal_on, caudal_cap=policy.caudal_cap)
    return fins, Memory(dorsal, memory.pid)
