"""Jittered time: each fish's clock, event order, and determinism of the batch engine."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.jitter import JitterSchedule, draw_period, next_event
from fishswarm.scenario import ConfigError, Scenario
from fishswarm.simulation import Stream, run_batch, stream


def _times(scenario: Scenario, fish_id: int, others: list[int], decisions: int) -> list[float]:
    schedule = JitterSchedule(scenario)
    for member in sorted({fish_id, *others}):
        schedule.add(member, 0.0)
    times = []
    for _ in range(decisions):
        times.append(schedule.next_time[fish_id])
        schedule.decided([fish_id])
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
    scenario = Scenario(time_mode="jitter", jitter=1.0, control_period=1.0)
    rng = stream(0, Stream.JITTER, 0)
    periods = [draw_period(scenario, rng) for _ in range(500)]
    assert min(periods) == 0.5 and max(periods) == 1.5
    assert draw_period(Scenario(jitter=0.0), rng) == 1.0


def test_snapshots_win_ties_and_decisions_go_in_id_order() -> None:
    schedule = JitterSchedule(Scenario(time_mode="jitter"))
    for fish_id in (7, 2, 5):
        schedule.add(fish_id, 1.0)
    assert next_event(schedule, 1.0) == ("snapshot", 1.0)
    assert next_event(schedule, 2.0) == ("decide", 1.0)
    assert schedule.due(1.0) == [2, 5, 7]
    schedule.remove(5)
    assert schedule.due(1.0) == [2, 7]


def test_jitter_runs_are_deterministic_and_differ_from_lockstep() -> None:
    jittered = Scenario(fish=10, duration=10, seed=8, time_mode="jitter")
    first, again = run_batch(jittered), run_batch(jittered)
    np.testing.assert_array_equal(first.position, again.position)
    np.testing.assert_array_equal(first.t, np.arange(11.0))
    lockstep = run_batch(jittered.replace(time_mode="lockstep"))
    assert not np.array_equal(first.position, lockstep.position)
    other_seed = run_batch(jittered.replace(seed=9))
    assert not np.array_equal(first.position, other_seed.position)


def test_bad_jitter_is_explained() -> None:
    with pytest.raises(ConfigError, match="jitter must be a standard deviation"):
        Scenario(jitter=-0.1)
    with pytest.raises(ConfigError, match="time_mode must be one of lockstep, jitter, realtime"):
        Scenario(time_mode="wobbly")
