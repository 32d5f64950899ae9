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


def test_a_pectoral_fin_pushes_back_and_sideways_by_hand() -> None:
    # The left pectoral at full gain, angled π/6 back from the side: from rest, one 0.01 s
    # step gives a_x = −sin(π/6)·0.006/0.5 = −0.006 m/s² and a_y = +cos(π/6)·0.006/0.5 =
    # 0.010392 m/s² (body y to the right): v_x = −6e-5, v_y = +1.0392e-4 m/s. Half dorsal
    # balances buoyancy, so v_z stays 0.
    state = _one([0.0, 0.5, 1.0, 0.0], 0.01)
    np.testing.assert_allclose(
        state.body_velocity[0], [-6e-5, math.cos(math.pi / 6) * 0.012 * 0.01, 0.0], atol=1e-12
    )
    right = _one([0.0, 0.5, 0.0, 1.0], 0.01)
    np.testing.assert_allclose(
        right.body_velocity[0], state.body_velocity[0] * [1, -1, 1], atol=1e-12
    )


def test_a_period_that_is_not_a_whole_number_of_steps_ends_on_time() -> None:
    # 0.025 s is two 0.01-s steps and one of 0.005 s: full caudal from rest reaches
    # v_x = 0.04 m/s²·0.025 s = 1.0e-3 m/s (drag, 1.6e-6 m/s² at that speed, is negligible),
    # not the 1.2e-3 of three whole steps.
    state = _one([1.0, 0.5, 0.0, 0.0], 0.025)
    assert state.body_velocity[0, 0] == pytest.approx(1.0e-3, rel=1e-4)


@pytest.mark.parametrize(
    ("given", "clipped"),
    [([2.0, 0.5, 0.0, 0.0], [1.0, 0.5, 0.0, 0.0]), ([-1.0, 0.5, 3.0, -2.0], [0, 0.5, 1, 0])],
)
def test_fin_gains_outside_0_to_1_are_clipped(given: list[float], clipped: list[float]) -> None:
    a, b = _one(given, 1.0), _one(clipped, 1.0)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.body_velocity, b.body_velocity)


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


STUDY_CODE = BlueBot(euler_step=0.1, yaw_before_update=True, speed_dependent_drag=True)


@pytest.mark.parametrize("forward", [0.1, -0.05])
def test_a_substep_of_the_study_codes_dynamics_by_hand(forward: float) -> None:
    # One 0.1-s substep (SPEC §8) from v = (forward, 0.02, 0) m/s, ω = 0.5 rad/s, yaw 0.3,
    # with the caudal fin full and the others off.
    rho, length, width, height, mass = 998.0, 0.150, 0.050, 0.080, 0.5
    area_x = math.pi / 4 * height * width
    area_y = math.pi / 4 * length * height + 2 * 0.00075
    area_z = math.pi / 4 * length * width
    inertia = mass / 5 * (length**2 + height**2) / 4
    c_x = 0.5 if forward > 0 else 1.0  # backward drag
    c_y = 2.1 * (1 + 4 * abs(forward) / 0.16)
    c_yaw = 1.0 * (1 + 9 * abs(forward) / 0.16)
    vx, vy, omega, dt = forward, 0.02, 0.5, 0.1
    vx_new = vx + dt / mass * (0.020 - 0.5 * rho * c_x * area_x * math.copysign(vx * vx, vx))
    vy_new = vy + dt / mass * (-0.5 * rho * c_y * area_y * vy * vy)
    vz_new = 0.0 + dt / mass * (0.0 - 0.010 - 0.5 * rho * 0.7 * area_z * 0.0)
    omega_new = omega + dt / inertia * (-0.5 * rho * c_yaw * area_y * (length / 6 * omega) ** 2)
    yaw_new = 0.3 + dt * omega  # turned by the rate before the update
    x = 1.0 + dt * (math.cos(yaw_new) * vx_new - math.sin(yaw_new) * vy_new)
    y = 1.0 + dt * (math.sin(yaw_new) * vx_new + math.cos(yaw_new) * vy_new)
    z = 0.5 + dt * vz_new
    state = State(
        np.array([[1.0, 1.0, 0.5]]), np.array([0.3]), np.array([[vx, vy, 0.0]]), np.array([omega])
    )
    after = step(state, np.array([[1.0, 0.0, 0.0, 0.0]]), duration=dt, robot=STUDY_CODE, tank=TANK)
    np.testing.assert_allclose(after.body_velocity[0], [vx_new, vy_new, vz_new], rtol=1e-12)
    assert after.yaw_rate[0] == pytest.approx(omega_new, rel=1e-12)
    assert after.yaw[0] == pytest.approx(yaw_new, rel=1e-12)
    np.testing.assert_allclose(after.position[0], [x, y, z], rtol=1e-12)


def test_the_study_codes_drag_slows_turning_at_speed_and_brakes_backwards() -> None:
    # Full caudal and left pectoral for 10 s: with yaw drag growing with speed the fish turns
    # less; coasting backwards it stops sooner than with the forward coefficient.
    turning = rest_state(np.array([[0.9, 0.9, 0.5]]), np.zeros(1))
    fins = np.array([[1.0, 0.5, 1.0, 0.0]])
    paper = step(turning, fins, duration=10.0, robot=BlueBot(), tank=TANK)
    study = step(turning, fins, duration=10.0, robot=STUDY_CODE, tank=TANK)
    assert abs(study.yaw_rate[0]) < 0.5 * abs(paper.yaw_rate[0])
    backwards = State(
        np.array([[0.9, 0.9, 0.5]]), np.zeros(1), np.array([[-0.1, 0.0, 0.0]]), np.zeros(1)
    )
    coast = np.zeros((1, 4))
    paper_coast = step(backwards, coast, duration=2.0, robot=BlueBot(euler_step=0.1), tank=TANK)
    study_coast = step(backwards, coast, duration=2.0, robot=STUDY_CODE, tank=TANK)
    assert -0.1 < paper_coast.body_velocity[0, 0] < study_coast.body_velocity[0, 0] < 0


def test_a_flow_carries_the_fish_and_drag_acts_on_its_motion_through_the_water() -> None:
    flow = np.array([-0.05, 0.02, 0.0])
    start = np.array([1.0, 0.8, 0.5])
    # Half dorsal balances buoyancy: a fish with no thrust drifts exactly with the water,
    # 0.05·10 = 0.5 m back and 0.2 m sideways in 10 s.
    state = rest_state(start[None].copy(), np.array([0.3]))
    drifting = step(state, np.array([[0.0, 0.5, 0.0, 0.0]]), duration=10.0, robot=ROBOT,
                    tank=TANK, flow=flow)  # fmt: skip
    np.testing.assert_allclose(drifting.position[0], start + 10.0 * flow, atol=1e-12)
    np.testing.assert_allclose(drifting.body_velocity, 0.0, atol=1e-15)
    # Swimming, its path is the still-water path plus the water's: speeds stay relative.
    fins = np.array([[0.6, 0.5, 0.2, 0.0]])
    still = step(state, fins, duration=7.0, robot=ROBOT, tank=TANK)
    carried = step(state, fins, duration=7.0, robot=ROBOT, tank=TANK, flow=flow)
    np.testing.assert_allclose(carried.position, still.position + 7.0 * flow, atol=1e-12)
    np.testing.assert_array_equal(carried.body_velocity, still.body_velocity)
    np.testing.assert_array_equal(carried.yaw, still.yaw)


def test_a_fish_with_less_surge_drag_reaches_a_higher_speed() -> None:
    # v_t = sqrt(F / (m·k_x·scale)): with half the drag, √2 times the terminal speed.
    start = rest_state(np.array([[0.1, 0.9, 0.5], [0.1, 0.5, 0.5]]), np.zeros(2))
    fins = np.array([[0.25, 0.5, 0.0, 0.0], [0.25, 0.5, 0.0, 0.0]])
    # τ = 1/(k·scale·v_t) is 11 s for the sheltered fish: 200 s is 18 τ.
    state = step(start, fins, duration=200.0, robot=ROBOT, tank=Tank((40.0, 2.0, 1.17)),
                 drag_scale=np.array([1.0, 0.5]))  # fmt: skip
    expected = 0.5 * ROBOT.terminal_speed()  # a quarter of the force: half the speed
    assert state.body_velocity[0, 0] == pytest.approx(expected, rel=1e-6)
    assert state.body_velocity[1, 0] == pytest.approx(expected * math.sqrt(2), rel=1e-6)
    # A scale of one changes nothing, bit for bit.
    plain = step(start, fins, duration=3.0, robot=ROBOT, tank=TANK)
    ones = step(start, fins, duration=3.0, robot=ROBOT, tank=TANK, drag_scale=np.ones(2))
    np.testing.assert_array_equal(plain.position, ones.position)
