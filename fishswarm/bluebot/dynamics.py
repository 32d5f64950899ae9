"""BlueBot rigid-body dynamics: fin gains → motion, for a batch of fish (SPEC.md §1.1).

State of a batch of B fish, all arrays with a leading batch axis:

- ``position`` (B, 3): tank frame, m, z down.
- ``yaw`` (B,): rad; 0 faces +x, positive turns towards +y (to the right, z down).
- ``body_velocity`` (B, 3): (v_x, v_y, v_z) in the body frame, m/s.
- ``yaw_rate`` (B,): rad/s.

The integrator is semi-implicit Euler: velocities are updated from the forces at the current
velocities, then yaw and position use the updated velocities. That is SPEC's order
("accelerations → integrate velocities and φ → rotate → integrate position") and stays stable
at the 0.01 s step for every fin setting. Positions are clipped into the tank after every
step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import BlueBot, Tank

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class State:
    """The dynamic state of B fish; see the module docstring for shapes and units."""

    position: FloatArray
    yaw: FloatArray
    body_velocity: FloatArray
    yaw_rate: FloatArray

    def tank_velocity(self) -> FloatArray:
        """(B, 3) velocity in the tank frame, m/s."""
        return rotate_to_tank(self.body_velocity, self.yaw)

    def take(self, index: NDArray[np.intp] | slice) -> State:
        """The sub-batch at ``index``."""
        return State(
            self.position[index], self.yaw[index], self.body_velocity[index], self.yaw_rate[index]
        )


def rest_state(position: FloatArray, yaw: FloatArray) -> State:
    """Fish at rest at ``position`` (B, 3) facing ``yaw`` (B,)."""
    count = position.shape[0]
    return State(
        np.array(position, dtype=np.float64),
        np.array(yaw, dtype=np.float64),
        np.zeros((count, 3)),
        np.zeros(count),
    )


def rotate_to_tank(body: FloatArray, yaw: FloatArray) -> FloatArray:
    """Rotate (B, 3) body-frame vectors into the tank frame by R_z(yaw)."""
    cos, sin = np.cos(yaw), np.sin(yaw)
    out = np.empty_like(body)
    out[:, 0] = cos * body[:, 0] - sin * body[:, 1]
    out[:, 1] = sin * body[:, 0] + cos * body[:, 1]
    out[:, 2] = body[:, 2]
    return out


def drag_coefficients(robot: BlueBot) -> tuple[FloatArray, float]:
    """Per-axis quadratic drag factors ½ρ·c·A/m (B-independent) and the yaw factor."""
    half_rho = 0.5 * robot.water_density
    linear = np.array(
        [
            half_rho * robot.drag_x * robot.area_x / robot.mass,
            half_rho * robot.drag_y * robot.area_y / robot.mass,
            half_rho * robot.drag_z * robot.area_z / robot.mass,
        ]
    )
    yaw = half_rho * robot.drag_yaw * robot.area_yaw * (robot.length / 6) ** 2 / robot.inertia
    return linear, yaw


def _drag_of_speed(robot: BlueBot) -> Callable[[FloatArray], FloatArray]:
    """The study's code's drag factors (B, 4) as a function of forward speed v_x (B,):
    backward drag when v_x ≤ 0, lateral and yaw drag growing with |v_x| (SPEC §8); the
    paper's factors scaled by how much each coefficient grows."""
    linear, yaw = drag_coefficients(robot)
    paper = np.append(linear, yaw)
    backward = robot.drag_x_backward / robot.drag_x

    def factors(forward: FloatArray) -> FloatArray:
        fast = np.abs(forward) / robot.speed_reference
        growth = np.ones((forward.size, 4))
        growth[:, 0] = np.where(forward > 0, 1.0, backward)
        growth[:, 1] = 1 + 4 * fast
        growth[:, 3] = 1 + 9 * fast
        result: FloatArray = growth * paper
        return result

    return factors


def substeps(duration: float, euler_step: float) -> FloatArray:
    """The Euler steps of a period, s: ``euler_step`` each, the last shortened to land
    exactly on ``duration`` (none for a period of 0)."""
    steps = math.ceil(duration / euler_step - 1e-9)
    dt = np.full(steps, euler_step)
    if steps:
        dt[-1] = duration - euler_step * (steps - 1)
    return dt


def period_inputs(
    state: State, fins: FloatArray, *, duration: float, robot: BlueBot
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """What integrating one period needs, checked: (B, 4) accelerations from the fins
    (clipped into [0, 1]; surge, sway, heave in m/s², yaw in rad/s²), (4,) drag factors in
    the same order, the substeps (s), and (B, 4) the velocities and yaw rate now.

    Raises:
        ValueError: a negative or infinite duration.
    """
    if duration < 0 or not math.isfinite(duration):
        raise ValueError(f"duration must be a finite non-negative time, got {duration}")
    fins = np.clip(np.asarray(fins, dtype=np.float64), 0.0, 1.0)
    force, torque = fin_forces(fins, robot=robot)
    drag, drag_yaw = drag_coefficients(robot)
    acceleration = np.concatenate([force / robot.mass, (torque / robot.inertia)[:, None]], axis=1)
    velocity = np.concatenate([state.body_velocity, state.yaw_rate[:, None]], axis=1)
    return acceleration, np.append(drag, drag_yaw), substeps(duration, robot.euler_step), velocity


def fin_forces(fins: FloatArray, *, robot: BlueBot) -> tuple[FloatArray, FloatArray]:
    """Thrust in the body frame and yaw torque from fin gains.

    Args:
        fins: (B, 4) gains in [0, 1]: caudal, dorsal, pectoral left, pectoral right.
        robot: the robot's parameters.

    Returns:
        force (B, 3) in N including buoyancy, torque (B,) in N·m.
    """
    caudal = fins[:, 0] * robot.caudal_force
    dorsal = fins[:, 1] * robot.dorsal_force
    left = fins[:, 2] * robot.pectoral_force
    right = fins[:, 3] * robot.pectoral_force
    cos, sin = math.cos(robot.pectoral_angle), math.sin(robot.pectoral_angle)
    force = np.empty((fins.shape[0], 3))
    force[:, 0] = caudal - sin * (left + right)
    force[:, 1] = cos * (left - right)
    force[:, 2] = dorsal - robot.buoyancy
    torque = robot.pectoral_arm * cos * (left - right)
    return force, torque


def step(
    state: State,
    fins: FloatArray,
    *,
    duration: float,
    robot: BlueBot,
    tank: Tank,
    flow: FloatArray | None = None,
    drag_scale: FloatArray | None = None,
) -> State:
    """Advance B fish by ``duration`` seconds with fins held constant (one control period).

    Args:
        state: the fish now.
        fins: (B, 4) gains in [0, 1] (caudal, dorsal, pectoral left, pectoral right), held for
            the whole period; values outside [0, 1] are clipped.
        duration: length of the period, s; integrated in Euler steps of ``robot.euler_step``
            (the last one shortened to land exactly on ``duration``).
        robot: the robot's parameters.
        tank: the tank; positions are clipped into it after every step.
        flow: (3,) the water's velocity in the tank frame, m/s (None: still water). Drag
            acts on a fish's motion through the water, so in a uniform flow the velocities
            evolve as in still water and the flow carries the fish: it adds flow·dt to
            every step's displacement (velocities stay relative to the water).
        drag_scale: (B,) a factor on each fish's surge drag for the period (below 1 for a
            fish sheltered in another's wake; None: 1).

    Returns:
        The new state (the input is not modified).
    """
    acceleration, drag_all, dt, velocity = period_inputs(
        state, fins, duration=duration, robot=robot
    )
    count, steps = velocity.shape[0], dt.size
    # Velocities and yaw rate evolve on their own (fins are held, drag depends only on them):
    # run that recursion first as one (B, 4) array, then integrate yaw and position with
    # running sums, which add in the same order as a step-by-step loop.
    history = np.empty((steps, count, 4))
    change = np.empty_like(velocity)
    magnitude = np.empty_like(velocity)
    varying = _drag_of_speed(robot) if robot.speed_dependent_drag else None
    scale = None
    if drag_scale is not None:
        scale = np.ones((count, 4))
        scale[:, 0] = drag_scale
    # In place, with the operations in the order of
    # velocity + (acceleration − drag·velocity·|velocity|)·dt, so results are the same bits.
    for n in range(steps):
        coefficients = drag_all if varying is None else varying(velocity[:, 0])
        if scale is not None:
            coefficients = coefficients * scale
        np.multiply(coefficients, velocity, out=change)
        np.multiply(change, np.abs(velocity, out=magnitude), out=change)
        np.subtract(acceleration, change, out=change)
        np.multiply(change, dt[n], out=change)
        velocity = np.add(velocity, change, out=history[n])
    if robot.yaw_before_update and steps:
        # The study's code turns by the rate the fish had before each substep's update.
        rates = np.concatenate([state.yaw_rate[None, :], history[:-1, :, 3]])
    else:
        rates = history[:, :, 3]
    yaw_path = np.cumsum(np.concatenate([state.yaw[None, :], rates * dt[:, None]]), axis=0)[1:]
    cos, sin = np.cos(yaw_path), np.sin(yaw_path)
    displacement = np.empty((steps, count, 3))
    displacement[..., 0] = (cos * history[..., 0] - sin * history[..., 1]) * dt[:, None]
    displacement[..., 1] = (sin * history[..., 0] + cos * history[..., 1]) * dt[:, None]
    displacement[..., 2] = history[..., 2] * dt[:, None]
    if flow is not None:
        displacement += np.asarray(flow, dtype=np.float64) * dt[:, None, None]
    path = np.cumsum(np.concatenate([state.position[None], displacement]), axis=0)
    upper = np.asarray(tank.size)
    position = path[-1].copy()
    walled = np.flatnonzero(((path < 0.0) | (path > upper)).any(axis=(0, 2)))
    if walled.size:
        # Fish that touch a wall are clipped after every step, as the model says.
        clipped = state.position[walled].copy()
        moves = displacement[:, walled]
        for n in range(steps):
            np.add(clipped, moves[n], out=clipped)
            np.minimum(np.maximum(clipped, 0.0, out=clipped), upper, out=clipped)
        position[walled] = clipped
    yaw = yaw_path[-1] if steps else state.yaw.copy()
    yaw = np.remainder(yaw + math.pi, 2 * math.pi) - math.pi
    return State(position, yaw, velocity[:, :3].copy(), velocity[:, 3].copy())
