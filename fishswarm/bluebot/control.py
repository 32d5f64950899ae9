"""Controllers: a desired motion → fin gains, for a batch of fish (SPEC.md §1.3).

A behaviour says where a fish wants to go as a target vector in its body frame (x forward,
y right, z down, m). A controller turns that into the four fin gains (caudal, dorsal,
pectoral left, pectoral right) in [0, 1]. Controllers with memory take their state in and
return the new one, so they stay pure functions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import BODY_LENGTH, BlueBot

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

CONTROLLERS = ("homing", "pid")


def heading_error_deg(target: FloatArray) -> FloatArray:
    """(B,) bearing of each target in degrees, positive to the right, in (−180, 180]."""
    return np.degrees(np.arctan2(target[:, 1], target[:, 0]))


def homing(
    target: FloatArray,
    *,
    dorsal_on: BoolArray,
    caudal_cap: float = 1.0,
    pitch_band_deg: float = 1.0,
    heading_band_deg: float = 20.0,
    body_length: float = BODY_LENGTH,
    right_when_ahead: bool = False,
) -> tuple[FloatArray, BoolArray]:
    """The research code's homing controller.

    Depth is bang-bang on the pitch of the target with a ±1° band (dorsal on when the target
    is more than 1° below, off when more than 1° above, unchanged in between). Heading: a
    target to the right drives the left pectoral at min(1, 0.6 + |h|/180°), mirrored for the
    left. The caudal fin runs only when |h| < 20°, at min(cap, 0.1 + planar distance /
    (8 body lengths)). A target dead ahead, or none (a zero vector), drives no pectoral fin; with
    ``right_when_ahead`` it drives the right pectoral at 0.6 as in the study's code (its
    "left" branch took every bearing ≤ 0, SPEC §8), which turns the fish to its left.

    Args:
        target: (B, 3) target vectors in the body frame, m.
        dorsal_on: (B,) dorsal state from the previous period.
        caudal_cap: upper limit of the caudal gain.
        pitch_band_deg: half-width of the depth dead band, degrees.
        heading_band_deg: the caudal fin runs only within this bearing, degrees.
        body_length: body length for the caudal gain, m.
        right_when_ahead: the study code's branch for bearings of exactly 0.

    Returns:
        fins (B, 4) and the new dorsal state (B,).
    """
    planar = np.hypot(target[:, 0], target[:, 1])
    pitch_deg = np.degrees(np.arctan2(target[:, 2], planar))
    dorsal = (pitch_deg > pitch_band_deg) | (dorsal_on & (pitch_deg >= -pitch_band_deg))
    heading_deg = heading_error_deg(target)
    magnitude = np.abs(heading_deg)
    turn = np.minimum(1.0, 0.6 + magnitude / 180.0)
    fins = np.zeros((target.shape[0], 4))
    fins[:, 0] = np.minimum(caudal_cap, 0.1 + planar / (8 * body_length)) * (
        magnitude < heading_band_deg
    )
    fins[:, 1] = dorsal
    fins[:, 2] = turn * (heading_deg > 0)
    fins[:, 3] = turn * (~(heading_deg > 0) if right_when_ahead else (heading_deg < 0))
    return fins, dorsal


@dataclass(frozen=True)
class PidGains:
    """Gains of the three loops of :func:`pid`: (proportional, integral, derivative).

    Errors are in m (depth), rad (heading) and m (planar distance to go).
    """

    depth: tuple[float, float, float] = (4.0, 0.2, 2.0)
    heading: tuple[float, float, float] = (1.5, 0.0, 0.3)
    speed: tuple[float, float, float] = (2.0, 0.0, 0.0)
    integral_limit: float = 1.0


@dataclass(frozen=True)
class PidState:
    """Memory of :func:`pid` for B fish: (B, 3) integrals and previous errors (depth,
    heading, distance)."""

    integral: FloatArray
    previous_error: FloatArray

    @classmethod
    def zeros(cls, count: int) -> PidState:
        """A fresh state for ``count`` fish."""
        return cls(np.zeros((count, 3)), np.full((count, 3), np.nan))


def pid(
    target: FloatArray,
    *,
    state: PidState,
    period: float | FloatArray,
    gains: PidGains = PidGains(),
    robot: BlueBot = BlueBot(),
) -> tuple[FloatArray, PidState]:
    """Three independent PID loops: depth → dorsal, heading → pectorals, speed → caudal.

    The depth loop adds a feed-forward that cancels buoyancy (dorsal = buoyancy / dorsal
    force when the depth error is zero). The speed loop drives the caudal fin from the planar
    distance still to go and is scaled by cos(heading error) so a fish turns before it
    swims. Derivatives start at zero on the first period.

    Args:
        target: (B, 3) target vectors in the body frame, m.
        state: the loops' memory.
        period: time since each fish's last decision, s: one number or (B,).
        gains: loop gains.
        robot: the robot (for the buoyancy feed-forward).

    Returns:
        fins (B, 4) and the new state.
    """
    step = np.broadcast_to(np.asarray(period, dtype=np.float64), target.shape[:1])[:, None]
    if not (step > 0).all():
        raise ValueError(f"period must be positive, got {period}")
    planar = np.hypot(target[:, 0], target[:, 1])
    error = np.stack([target[:, 2], np.arctan2(target[:, 1], target[:, 0]), planar], axis=1)
    integral = np.clip(state.integral + error * step, -gains.integral_limit, gains.integral_limit)
    derivative = np.where(
        np.isnan(state.previous_error), 0.0, (error - state.previous_error) / step
    )
    k = np.array([gains.depth, gains.heading, gains.speed])
    output = k[:, 0] * error + k[:, 1] * integral + k[:, 2] * derivative
    fins = np.zeros((target.shape[0], 4))
    fins[:, 0] = output[:, 2] * np.clip(np.cos(error[:, 1]), 0.0, 1.0)
    fins[:, 1] = robot.buoyancy / robot.dorsal_force + output[:, 0]
    fins[:, 2] = np.maximum(output[:, 1], 0.0)
    fins[:, 3] = np.maximum(-output[:, 1], 0.0)
    return np.clip(fins, 0.0, 1.0), PidState(integral, error)


def stop_fins(count: int) -> FloatArray:
    """(count, 4) all fins off: what a fish does when it loses its perceptions."""
    return np.zeros((count, 4))


def pitch_deg(target: FloatArray) -> FloatArray:
    """(B,) pitch of each target in degrees, positive below (z down)."""
    return np.degrees(np.arctan2(target[:, 2], np.hypot(target[:, 0], target[:, 1])))
