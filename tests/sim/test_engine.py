"""The batch engine as the fish core sees it: what each decision hears, is told and reads
from its compass."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest

from fishswarm.behaviors import core
from fishswarm.behaviors.core import Decision, FishMemory, FishParams, Inbox, Outbox, Perception
from fishswarm.behaviors.formation import FormationParams
from fishswarm.sim import engine
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario
from tests.behaviors.signal_behavior import registered


@dataclass(frozen=True)
class Seen:
    """One call of the fish core: when, by how many fish, what each heard (broadcasts
    delivered), its compass, and the parameters it decided with."""

    time: float
    heard: list[int]
    heading: np.ndarray | None
    params: FishParams


def _watch(monkeypatch: pytest.MonkeyPatch, *, silent_from: float = math.inf) -> list[Seen]:
    """Record every decision the engine asks for; from ``silent_from`` s on, the fish
    broadcast nothing."""
    seen: list[Seen] = []

    def watching(
        memory: FishMemory, perception: Perception, inbox: Inbox, *, params: FishParams
    ) -> tuple[FishMemory, Decision]:
        time = float(perception.time[0])
        heard = inbox.mask.sum(axis=1).tolist()
        seen.append(Seen(time, heard, perception.heading, params))
        memory, decision = core.decide(memory, perception, inbox, params=params)
        if time >= silent_from:
            decision = dataclasses.replace(decision, outbox=Outbox.silent(perception.count))
        return memory, decision

    monkeypatch.setattr(engine, "decide", watching)
    return seen


def test_a_broadcast_is_heard_at_the_next_decision_and_only_there(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Three fish within a metre of each other (the channel carries 3 m, loses nothing)
    # broadcast at tick 0 only: each hears the other two at tick 1, and nothing after.
    seen = _watch(monkeypatch, silent_from=1.0)
    scenario = Scenario(fish=3, duration=4.0, seed=2, behavior=registered().name, channel_loss=0)
    simulate_batch(scenario)
    assert [(s.time, s.heard) for s in seen] == [
        (0.0, [0, 0, 0]),
        (1.0, [2, 2, 2]),
        (2.0, [0, 0, 0]),
        (3.0, [0, 0, 0]),
    ]


def test_jitter_mode_delivers_no_broadcasts(monkeypatch: pytest.MonkeyPatch) -> None:
    # Every fish broadcasts at every decision; all three decide together at 0 s, then each
    # on its own clock — and nobody ever hears anything.
    seen = _watch(monkeypatch)
    scenario = Scenario(
        fish=3, duration=4.0, seed=2, behavior=registered().name, time_mode="jitter"
    )
    simulate_batch(scenario)
    assert seen[0].time == 0.0 and len(seen[0].heard) == 3
    assert len(seen) > 4
    assert all(heard == 0 for s in seen for heard in s.heard)


def test_each_fish_reads_its_own_yaw_on_its_compass(monkeypatch: pytest.MonkeyPatch) -> None:
    seen = _watch(monkeypatch)
    trajectory = simulate_batch(Scenario(fish=4, duration=3.0, seed=5))
    assert [s.time for s in seen] == [0.0, 1.0, 2.0]
    for tick, decision in enumerate(seen):
        assert decision.heading is not None
        np.testing.assert_array_equal(decision.heading, trajectory.yaw[tick])


def test_the_fish_are_told_the_scenario_s_formation_switch_when_it_comes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    seen = _watch(monkeypatch)
    scenario = Scenario(
        fish=4,
        duration=4.0,
        seed=1,
        behavior="formation",
        formation="pyramid",
        switch_formation="diamond",
        switch_at=2.0,
    )
    simulate_batch(scenario)
    shapes = []
    for decision in seen:
        assert isinstance(decision.params.steering, FormationParams)
        shapes.append((decision.time, decision.params.steering.shape))
    assert shapes == [(0.0, "pyramid"), (1.0, "pyramid"), (2.0, "diamond"), (3.0, "diamond")]
