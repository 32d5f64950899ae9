"""The tick sequence's bookkeeping: fish joining and leaving, held fins, and effort."""

from __future__ import annotations

import numpy as np

from fishswarm.bluebot.parameters import fin_frequencies
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import Scenario
from fishswarm.sim.tick import WorldSim


def test_fin_frequencies_follow_the_gains() -> None:
    fins = np.array([[1.0, 0.0, 0.5, 0.0], [0.5, 1.0, 1.0, 0.1]])
    # Caudal 1–3 Hz, dorsal 6 Hz whenever on, pectorals 1–10 Hz; gain 0 is off.
    np.testing.assert_allclose(fin_frequencies(fins), [[3.0, 0.0, 5.5, 0.0], [2.0, 6.0, 10.0, 1.9]])


def test_effort_counts_fin_beats_and_follows_a_fish_that_leaves_and_returns() -> None:
    world = WorldSim(WorldParams.of(Scenario(fish=3, duration=10.0)))
    world.join([0, 1, 2])
    world.next_event()  # tick 0: nothing has moved yet
    world.hold([0, 1, 2], np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0, 0]]))
    world.next_event()  # one control period (1 s) with those fins
    np.testing.assert_allclose(world.effort, [3.0, 6.0, 0.0])
    world.leave([1])
    world.next_event()
    np.testing.assert_allclose(world.effort, [6.0, 0.0])  # fish 1 is gone; 0 swam on
    world.join([1])
    assert world.ids.tolist() == [0, 1, 2]
    np.testing.assert_allclose(world.effort, [6.0, 6.0, 0.0])  # it keeps what it spent
    np.testing.assert_array_equal(world.fins[1], [0, 0, 0, 0])  # and rejoins fins off
