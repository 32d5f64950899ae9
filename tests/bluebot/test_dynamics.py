"""BlueBot dynamics against hand-computed physics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.bluebot.dynamics import State, rest_state, step
from fishswarm.bluebot.parameters import BlueBot, Tank

ROBOT = BlueBot()
TANK = Tank()
CENTER = TANK.center


def _one(fins: list[float], seconds: float, yaw: float = 0.0, at: np.ndarray = CENTER) -> State:
    state = rest_state(at[None, :].copy(), np.array([yaw]))
    return step(state, np.array([fins]), duration=seconds, robot=ROBOT, tank=TANK)


def test_terminal_forward_speed_is_about_016() -> None:
    # ½ρ c_dx A_x v² = F_caud  ->  v = sqrt(0.020 / (0.5·998·0.5·π/4·0.08·0.05)) = 0.1597 m/s
    assert ROBOT.terminal_speed() == pytest.approx(0.1597, abs=1e-4)
    start = np.array([0.1, 0.89, 0.5])
    # v(t) = v_t·tanh(t/τ) with τ = m/(½ρc_dxA_x·v_t) ≈ 4 s: after 40 s within 1e-6.
    state = _one([1.0, 0.5, 0.0, 0.0], 40.0, at=start)
    assert state.body_velocity[0, 0] == pytest.approx(ROBOT.terminal_speed(), rel=1e-4)


def test_first_euler_step_by_hand() -> None:
    # From rest, one 0.01 s step with full caudal: v_x = F/m·dt = 0.02/0.5·0.01 = 4e-4 m/s,
    # x advances by v_x·dt = 4e-6 m; buoyancy: v_z = −0.010/0.5·0.01 = −2e-4 m/s.
    state = _one([1.0, 0.0, 0.0, 0.0], 0.01)
    assert state.body_velocity[0, 0] == pytest.approx(4e-4)
    assert state.body_velocity[0, 2] == pytest.approx(-2e-4)
    assert state.position[0, 0] - CENTER[0] == pytest.approx(4e-6)
    assert state.position[0, 2] - CENTER[2] == pytest.approx(-2e-6)


def test_yaw_points_thrust_in_the_tank_frame() -> None:
    state = _one([1.0, 0.5, 0.0, 0.0], 2.0, yaw=math.pi / 2)
    moved = state.position[0] - CENTER
    assert moved[1] > 0.05
    assert abs(moved[0]) < 1e-9


def test_left_pectoral_turns_right_and_right_pectoral_turns_left() -> None:
    left = _one([0.0, 0.5, 1.0, 0.0], 2.0)
    right = _one([0.0, 0.5, 0.0, 1.0], 2.0)
    assert left.yaw_rate[0] > 0 and left.yaw[0] > 0
    assert right.yaw_rate[0] < 0 and right.yaw[0] < 0
    assert left.yaw[0] == pytest.approx(-right.yaw[0])
    # Initial angular acceleration: 0.055·cos(π/6)·0.006 / I.
    first = _one([0.0, 0.5, 1.0, 0.0], 0.01)
    expected = 0.055 * math.cos(math.pi / 6) * 0.006 / ROBOT.inertia * 0.01
    assert first.yaw_rate[0] == pytest.approx(expected)


def test_buoyancy_lifts_a_robot_with_fins_off() -> None:
    state = _one([0.0, 0.0, 0.0, 0.0], 3.0)
    assert state.position[0, 2] < CENTER[2] - 0.05
    assert state.body_velocity[0, 2] < 0


def test_half_dorsal_balances_buoyancy() -> None:
    state = _one([0.0, 0.5, 0.0, 0.0], 5.0)
    np.testing.assert_allclose(state.position[0], CENTER, atol=1e-12)


def test_positions_stay_inside_the_tank() -> None:
    rng = np.random.default_rng(1)
    position = rng.uniform(0, 1, (50, 3)) * np.asarray(TANK.size)
    state = rest_state(position, rng.uniform(-math.pi, math.pi, 50))
    for _ in range(20):
        state = step(state, rng.uniform(0, 1, (50, 4)), duration=1.0, robot=ROBOT, tank=TANK)
        assert np.all(state.position >= 0)
        assert np.all(state.position <= np.asarray(TANK.size))
    assert np.all(np.abs(state.yaw) <= math.pi)


def test_batch_equals_loop_of_single_fish() -> None:
    rng = np.random.default_rng(2)
    position = rng.uniform(0.3, 1.4, (7, 3))
    yaw = rng.uniform(-3, 3, 7)
    fins = rng.uniform(0, 1, (7, 4))
    batch = step(rest_state(position, yaw), fins, duration=1.0, robot=ROBOT, tank=TANK)
    for i in range(7):
        single = step(
            rest_state(position[i : i + 1], yaw[i : i + 1]),
            fins[i : i + 1],
            duration=1.0,
            robot=ROBOT,
            tank=TANK,
        )
        np.testing.assert_array_equal(single.position[0], batch.position[i])
        np.testing.assert_array_equal(single.yaw[0], batch.yaw[i])


def test_bad_duration_is_rejected() -> None:
    with pytest.raises(ValueError, match="duration"):
        _one([0, 0, 0, 0], -1.0)
