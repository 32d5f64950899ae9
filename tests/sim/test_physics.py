"""The world's physics set-up: where fish start and how far apart."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.sim.physics import WorldParams, place, spawn_spacing
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
