"""The clocks: lockstep events, each fish's jittered clock, event order, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.sim.clocks import Event, JitterClock, LockstepClock, draw_period
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.sim.streams import Stream, stream


def _clock(scenario: Scenario) -> JitterClock:
    return JitterClock(
        period=scenario.control_period, jitter=scenario.jitter, seed=scenario.seed, ticks=10
    )


def _times(scenario: Scenario, fish_id: int, others: list[int], decisions: int) -> list[float]:
    schedule = _clock(scenario)
    for member in sorted({fish_id, *others}):
        schedule.add(member, 0.0)
    times = []
    for _ in range(decisions):
        times.append(schedule.next_time[fish_id])
        schedule.decided(np.array([fish_id]))
    return times


def test_a_fish_clock_does_not_depend_on_the_others() -> None:
    scenario = Scenario(seed=5, time_mode="jitter", jitter=0.05)
    alone = _times(scenario, 3, [], 20)
    crowded = _times(scenario, 3, list(range(25)), 20)
    assert alone == crowded
    periods = np.diff(alone)
    assert abs(periods.mean() - 1.0) < 0.05
    assert 0.02 < periods.std() < 0.09  # about the 0.05 s asked for
    assert alone != _times(scenario, 4, [], 20)  # another fish, another clock


def test_periods_are_clipped_to_half_and_one_and_a_half_periods() -> None:
    rng = stream(0, Stream.JITTER, 0)
    periods = [draw_period(1.0, 1.0, rng) for _ in range(500)]
    assert min(periods) == 0.5 and max(periods) == 1.5
    assert draw_period(1.0, 0.0, rng) == 1.0


def test_a_clock_without_jitter_draws_nothing_from_its_stream() -> None:
    rng, fresh = stream(0, Stream.JITTER, 0), stream(0, Stream.JITTER, 0)
    assert [draw_period(0.5, 0.0, rng) for _ in range(3)] == [0.5, 0.5, 0.5]
    assert rng.bit_generator.state == fresh.bit_generator.state


def test_snapshots_win_ties_and_decisions_go_in_id_order() -> None:
    schedule = _clock(Scenario(time_mode="jitter"))
    for fish_id in (7, 2, 5):
        schedule.add(fish_id, 1.0)
    assert schedule.next_event() == Event(0.0, 0.0, 0, last=False, deciding=False, number=0)
    assert schedule.next_event() == Event(1.0, 1.0, 1, last=False, deciding=False, number=0)
    assert schedule.next_event() == Event(1.0, 0.0, None, last=False, deciding=True, number=1)
    assert schedule.due(1.0).tolist() == [2, 5, 7]
    schedule.remove(5)
    assert schedule.due(1.0).tolist() == [2, 7]


def test_lockstep_snapshots_and_decides_every_period_and_ends_with_a_snapshot() -> None:
    clock = LockstepClock(period=0.5, ticks=2)
    for fish_id in (4, 1):
        clock.add(fish_id, 0.0)
    events = [clock.next_event() for _ in range(3)]
    assert events == [
        Event(0.0, None, 0, last=False, deciding=True, number=0),
        Event(0.5, 0.5, 1, last=False, deciding=True, number=1),
        Event(1.0, 0.5, 2, last=True, deciding=False, number=2),
    ]
    assert clock.due(0.5).tolist() == [1, 4]
    # The fish who decide are remembered between ticks, and change as fish come and go.
    assert clock.due(1.0) is clock.due(1.5)
    clock.add(9, 0.5)
    clock.add(3, 0.5)
    assert clock.due(1.0).tolist() == [1, 3, 4, 9]
    clock.remove(4)
    assert clock.due(1.0).tolist() == [1, 3, 9]
    with pytest.raises(ValueError, match="read-only"):
        clock.due(1.0)[0] = 7


def test_jitter_runs_are_deterministic_and_differ_from_lockstep() -> None:
    jittered = Scenario(fish=10, duration=10, seed=8, time_mode="jitter")
    first, again = simulate_batch(jittered), simulate_batch(jittered)
    np.testing.assert_array_equal(first.position, again.position)
    np.testing.assert_array_equal(first.t, np.arange(11.0))
    lockstep = simulate_batch(jittered.replace(time_mode="lockstep"))
    assert not np.array_equal(first.position, lockstep.position)
    other_seed = simulate_batch(jittered.replace(seed=9))
    assert not np.array_equal(first.position, other_seed.position)


def test_bad_jitter_is_explained() -> None:
    with pytest.raises(ConfigError, match="jitter must be a non-negative standard deviation"):
        Scenario(jitter=-0.1)
    with pytest.raises(ConfigError, match="time_mode must be one of lockstep, jitter, realtime"):
        Scenario(time_mode="wobbly")
