"""The world's physics set-up: where fish start and how far apart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.bluebot.dynamics import State, step
from fishswarm.sim import kernels
from fishswarm.sim.physics import WorldParams, advance, place, spawn_spacing
from fishswarm.sim.scenario import Scenario


def test_two_fish_start_as_far_apart_as_their_spawn_poses() -> None:
    params = WorldParams.of(Scenario(fish=2, seed=4))
    first, second = place(params, np.array([0, 1])).position
    assert spawn_spacing(params, 2) == pytest.approx(float(np.linalg.norm(first - second)))
    assert spawn_spacing(params, 1) == math.inf


def test_fish_spread_over_the_tank_start_further_apart_than_in_the_start_ball() -> None:
    # 1 000 fish in the study's start ball (radius 0.26 m) against the whole tank (3.7 m³):
    # a uniform spread of N fish in a volume V puts the median nearest neighbour near
    # 0.55·(V/N)^(1/3) (a ball of 0.074 m³: about 2.3 cm; the tank: about 8.5 cm).
    ball = spawn_spacing(WorldParams.of(Scenario(fish=1000)), 1000)
    tank = spawn_spacing(WorldParams.of(Scenario(fish=1000, spawn_region="tank")), 1000)
    assert 0.015 < ball < 0.03
    assert 0.07 < tank < 0.10


def _swimming_pair() -> State:
    """Two fish heading +x at 0.1 m/s, the second 0.2 m straight behind the first."""
    position = np.array([[1.2, 0.9, 0.5], [1.0, 0.9, 0.5]])
    velocity = np.array([[0.1, 0.0, 0.0], [0.1, 0.0, 0.0]])
    return State(position, np.zeros(2), velocity, np.zeros(2))


def test_a_fish_in_another_fish_s_wake_swims_further_with_wake_saving() -> None:
    pair = _swimming_pair()
    fins = np.array([[1.0, 0.5, 0.0, 0.0], [1.0, 0.5, 0.0, 0.0]])  # full caudal, level
    still = advance(pair, fins, duration=1.0, params=WorldParams.of(Scenario(fish=2)))
    params = WorldParams.of(Scenario(fish=2, wake_saving=0.9))
    saved = advance(pair, fins, duration=1.0, params=params)
    # The follower is 0.2 m behind on the axis of a 0.5 m wake: shelter 1 − 0.2/0.5 = 0.6,
    # so its surge drag is 1 − 0.9 × 0.6 = 0.46 of still water's; the leader's is whole.
    expected = step(
        pair, fins, duration=1.0, robot=params.robot, tank=params.tank,
        drag_scale=np.array([1.0, 0.46]),
    )  # fmt: skip
    np.testing.assert_allclose(saved.position, expected.position, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(saved.position[0], still.position[0])
    moved = saved.position[:, 0] - pair.position[:, 0]
    moved_still = still.position[:, 0] - pair.position[:, 0]
    assert moved[1] > 1.03 * moved_still[1]
    assert saved.body_velocity[1, 0] > 1.05 * still.body_velocity[1, 0]


def test_formation_switch_is_in_force_from_its_time_on() -> None:
    params = WorldParams.of(
        Scenario(behavior="formation", formation="pyramid", switch_formation="diamond", switch_at=5)
    )
    assert params.formation_at(4.0) is None
    assert params.formation_at(5.0) == "diamond"  # the decision at tick 5 already switches
    assert params.formation_at(6.0) == "diamond"
    assert WorldParams.of(Scenario()).formation_at(1e9) is None


def test_flow_and_wakes_keep_a_large_swarm_off_the_compiled_integrator(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The compiled integrator knows neither flow nor wakes: a 200-fish swarm in a flow
    # must still drift with it.
    monkeypatch.setattr(kernels, "available", lambda: True)
    assert WorldParams.of(Scenario(fish=200)).compiled
    assert not WorldParams.of(Scenario(fish=200, wake_saving=0.5)).compiled
    params = WorldParams.of(Scenario(fish=200, flow=(0.02, 0.0, 0.0)))
    assert not params.compiled
    fish = place(params, np.arange(200, dtype=np.int64))
    fins_off = np.zeros((200, 4))
    after = advance(fish, fins_off, duration=1.0, params=params)
    # At rest with fins off nothing pushes a fish along x: the water carries it 0.02 m.
    np.testing.assert_allclose(after.position[:, 0] - fish.position[:, 0], 0.02, atol=1e-12)
