"""The tick sequence's bookkeeping: fish joining and leaving, held fins, and effort."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from fishswarm.bluebot.parameters import effort_rate, fin_frequencies
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import Scenario
from fishswarm.sim.tick import WorldSim


def test_fin_frequencies_follow_the_gains() -> None:
    fins = np.array([[1.0, 0.0, 0.5, 0.0], [0.5, 1.0, 1.0, 0.1]])
    # Caudal 1–3 Hz, dorsal 6 Hz whenever on, pectorals 1–10 Hz; gain 0 is off.
    np.testing.assert_allclose(fin_frequencies(fins), [[3.0, 0.0, 5.5, 0.0], [2.0, 6.0, 10.0, 1.9]])


def test_effort_weighs_each_fins_beats_by_its_gain() -> None:
    fins = np.array([[1.0, 0.0, 0.5, 0.0], [0.5, 1.0, 1.0, 0.1], [1.5, -1.0, 0.0, 0.0]])
    # 1·3 + 0.5·5.5 = 5.75; 0.5·2 + 1·6 + 1·10 + 0.1·1.9 = 17.19; gains clipped: 1·3.
    np.testing.assert_allclose(effort_rate(fins), [5.75, 17.19, 3.0])


@settings(max_examples=80, deadline=None)
@example(fins=np.full((2, 4), -0.0))  # −0.0 gains: the row's sum starts from +0.0
@given(
    fins=arrays(
        np.float64, st.tuples(st.integers(0, 50), st.just(4)), elements=st.floats(-0.5, 1.5)
    )
)
def test_effort_rate_adds_the_fins_as_a_sum_over_each_row_does(fins: np.ndarray) -> None:
    # Added column by column for speed: bit for bit numpy's sum over the row.
    expected = (np.clip(fins, 0.0, 1.0) * fin_frequencies(fins)).sum(axis=1)
    assert effort_rate(fins).tobytes() == expected.tobytes()


def test_effort_counts_fin_beats_and_follows_a_fish_that_leaves_and_returns() -> None:
    world = WorldSim(WorldParams.of(Scenario(fish=3, duration=10.0)))
    world.join([0, 1, 2])
    world.next_event()  # tick 0: nothing has moved yet
    world.hold(np.array([0, 1, 2]), np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0, 0]]))
    world.next_event()  # one control period (1 s) with those fins
    np.testing.assert_allclose(world.effort, [3.0, 6.0, 0.0])
    world.leave([1])
    world.next_event()
    np.testing.assert_allclose(world.effort, [6.0, 0.0])  # fish 1 is gone; 0 swam on
    world.join([1])
    assert world.ids.tolist() == [0, 1, 2]
    np.testing.assert_allclose(world.effort, [6.0, 6.0, 0.0])  # it keeps what it spent
    np.testing.assert_array_equal(world.fins[1], [0, 0, 0, 0])  # and rejoins fins off


def test_the_study_codes_start_delay_holds_every_fish_for_two_periods() -> None:
    from fishswarm.sim.engine import simulate_batch

    for time_mode in ("lockstep", "jitter"):
        scenario = Scenario(fish=6, duration=6, time_mode=time_mode, study_code=("start-delay",))
        held = simulate_batch(scenario)
        early = held.t < 2.0 + 1e-9
        np.testing.assert_array_equal(
            held.position[early], held.position[:1].repeat(early.sum(), 0)
        )
        np.testing.assert_array_equal(held.effort[early], 0.0)
        assert np.abs(held.position[-1] - held.position[0]).max() > 0.01
    # Without the switch the fish move from the first period.
    free = simulate_batch(Scenario(fish=6, duration=6))
    assert np.abs(free.position[1] - free.position[0]).max() > 1e-3


def test_in_jitter_mode_a_fish_decides_on_its_own_clock_from_when_it_joins() -> None:
    # No jitter, a period of 0.5 s: fish 0 decides at 0 and every 0.5 s; fish 1, joining at
    # the 0.5-s snapshot, first decides then too. Effort is rate × time: 3 beats/s × 0.5 s.
    scenario = Scenario(fish=2, duration=2.0, time_mode="jitter", jitter=0.0, control_period=0.5)
    world = WorldSim(WorldParams.of(scenario))
    world.join([0])
    first = world.next_event()
    assert (first.time, first.snapshot, world.now) == (0.0, 0, 0.0)
    due, rows = world.due()
    assert due.tolist() == [0] and rows.tolist() == [0]
    world.hold(due, np.array([[1.0, 0.0, 0.0, 0.0]]))
    snapshot = world.next_event()
    assert (snapshot.time, snapshot.snapshot, snapshot.deciding) == (0.5, 1, False)
    assert world.now == 0.5
    np.testing.assert_allclose(world.effort, [1.5])
    world.join([1])
    deciding = world.next_event()
    assert (deciding.time, deciding.deciding, world.now) == (0.5, True, 0.5)
    assert world.due()[0].tolist() == [0, 1]
    np.testing.assert_allclose(world.effort, [1.5, 0.0])  # no time passed


def test_a_fish_that_joins_below_others_gets_its_own_row_of_fins() -> None:
    world = WorldSim(WorldParams.of(Scenario(fish=3)))
    world.join([2])
    world.hold(np.array([2]), np.array([[0.5, 0.0, 1.0, 0.0]]))
    world.join([0, 2])  # 2 is in already: it is not added twice
    assert world.ids.tolist() == [0, 2]
    np.testing.assert_array_equal(world.fins, [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, 1.0, 0.0]])
    assert world.state.position.shape == (2, 3)
