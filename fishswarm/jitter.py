"""Jittered time: each fish decides on its own clock, simulated time goes event by event.

DESIGN §3's jitter mode, after the later BlueSim scheduler. Each control period of each fish
is drawn from N(control period, jitter), clipped to half and one and a half periods, from the
fish's own random stream — so a fish's decision times never depend on the others, on how
many there are, or on which process serves them. Between events every fish swims on with the
fins of its last decision. Snapshots (for the channel and observers) are taken at whole
control periods. At equal times a snapshot comes before decisions, and decisions go in fish-id
order; the whole sequence is a pure function of the scenario, shared by the world actor and
the batch engine, so both give the same trajectories bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fishswarm.behaviors.policy import Memory, act
from fishswarm.scenario import Scenario
from fishswarm.simulation import (
    Stream,
    Trajectory,
    TrajectoryRecorder,
    advance,
    observe,
    observe_landmarks,
    place,
    policy_of,
    stream,
)


def draw_period(scenario: Scenario, rng: np.random.Generator) -> float:
    """One control period of one fish, s."""
    period = scenario.control_period
    drawn = rng.normal(period, scenario.jitter) if scenario.jitter > 0 else period
    return float(np.clip(drawn, 0.5 * period, 1.5 * period))


@dataclass
class JitterSchedule:
    """When each fish decides next.

    Attributes:
        scenario: the run's scenario (control period, jitter, seed).
        next_time: the next decision time of each live fish, s.
    """

    scenario: Scenario
    next_time: dict[int, float] = field(default_factory=dict)
    _rngs: dict[int, np.random.Generator] = field(default_factory=dict)

    def add(self, fish_id: int, at: float) -> None:
        """A fish joins: it decides first at ``at``."""
        self._rngs.setdefault(fish_id, stream(self.scenario.seed, Stream.JITTER, fish_id))
        self.next_time[fish_id] = at

    def remove(self, fish_id: int) -> None:
        """A fish leaves."""
        self.next_time.pop(fish_id, None)

    def next_decision(self) -> float:
        """The earliest next decision time, s (inf with no fish)."""
        return min(self.next_time.values(), default=float("inf"))

    def due(self, now: float) -> list[int]:
        """The fish that decide at ``now``, in id order."""
        return sorted(fish_id for fish_id, at in self.next_time.items() if at <= now)

    def decided(self, fish_ids: list[int]) -> None:
        """These fish have decided: draw each one's next period."""
        for fish_id in fish_ids:
            self.next_time[fish_id] += draw_period(self.scenario, self._rngs[fish_id])


def next_event(schedule: JitterSchedule, snapshot_time: float) -> tuple[str, float]:
    """What happens next: ("snapshot", time) or ("decide", time); snapshots win ties."""
    decision = schedule.next_decision()
    if snapshot_time <= decision:
        return "snapshot", snapshot_time
    return "decide", decision


def run_jittered(scenario: Scenario) -> Trajectory:
    """The batch engine in jitter mode: the same events as the world actor, in this process.

    Returns the fish at every snapshot (whole control periods), like :func:`run_batch`.
    """
    ids = np.arange(scenario.fish, dtype=np.int64)
    state = place(scenario, ids)
    policy = policy_of(scenario)
    memory = Memory.fresh(scenario.fish)
    fins = np.zeros((scenario.fish, 4))
    vision_rngs = [stream(scenario.seed, Stream.VISION, int(i)) for i in ids]
    schedule = JitterSchedule(scenario)
    for fish_id in ids.tolist():
        schedule.add(fish_id, 0.0)
    recorder = TrajectoryRecorder()
    now, snapshot_tick = 0.0, 0
    while True:
        kind, at = next_event(schedule, snapshot_tick * scenario.control_period)
        state = advance(scenario, state, fins, duration=at - now)
        now = at
        perceived = observe(scenario, state, vision_rngs)
        if kind == "snapshot":
            recorder.add(now, state, perceived)
            if snapshot_tick == scenario.ticks:
                break
            snapshot_tick += 1
            continue
        due = np.array(schedule.due(now), dtype=np.intp)
        landmarks = observe_landmarks(scenario, state)
        decided, remembered = act(
            policy,
            perceived.neighbors[due],
            perceived.mask[due],
            state.position[due, 2],
            memory.take(due),
            landmarks.neighbors[due],
            landmarks.mask[due],
        )
        fins[due] = decided
        memory = memory.replaced(due, remembered)
        schedule.decided(due.tolist())
    return recorder.trajectory(ids)
