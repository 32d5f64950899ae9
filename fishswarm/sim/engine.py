"""The batch engine: a whole run in one process, every fish deciding in one batched call.

It drives the same tick sequence (:class:`~fishswarm.sim.tick.WorldSim`) and the same fish
core (:func:`~fishswarm.behaviors.core.decide`) as the actor system, whose trajectories it
gives bit for bit (tested) in a fraction of the time: for sweeps, learning and as the
reference the actors are checked against. Broadcasts go through the same medium as the
channel actor's (lockstep and realtime modes: decided at tick k, heard at tick k+1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import (
    FishMemory,
    Inbox,
    Perception,
    decide,
    put_rows,
    take_rows,
)
from fishswarm.behaviors.formation import apply_directive
from fishswarm.bluebot.vision import Perceived
from fishswarm.sim.decision_kernels import with_compiled_decisions
from fishswarm.sim.medium import deliver
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import Scenario
from fishswarm.sim.streams import Stream, stream
from fishswarm.sim.tick import WorldSim

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class Trajectory:
    """Recorded states of a run, SI units.

    Attributes:
        t: (T,) times, s.
        ids: (N,) fish ids.
        position: (T, N, 3) tank frame, m.
        velocity: (T, N, 3) tank frame, m/s.
        yaw: (T, N) rad.
        neighbors_seen: (T, N) neighbours seen at each tick.
        effort: (T, N) each fish's effort so far, gain-weighted fin beats.
    """

    t: FloatArray
    ids: IntArray
    position: FloatArray
    velocity: FloatArray
    yaw: FloatArray
    neighbors_seen: IntArray
    effort: FloatArray


class TrajectoryRecorder:
    """Collects the fish at each snapshot and makes a :class:`Trajectory` of them."""

    def __init__(self) -> None:
        self._rows: list[
            tuple[float, FloatArray, FloatArray, FloatArray, IntArray, FloatArray]
        ] = []

    def add(self, time: float, world: WorldSim, perceived: Perceived) -> None:
        """Record the world's fish at ``time``, with the neighbours each sees."""
        state = world.state
        self._rows.append(
            (
                time,
                state.position,
                state.tank_velocity(),
                state.yaw,
                perceived.counts,
                world.effort.copy(),
            )
        )

    def trajectory(self, ids: IntArray) -> Trajectory:
        """Everything recorded, as arrays."""
        times, positions, velocities, yaws, seen, effort = zip(*self._rows, strict=True)
        return Trajectory(
            np.array(times),
            ids,
            np.array(positions),
            np.array(velocities),
            np.array(yaws),
            np.array(seen),
            np.array(effort),
        )


def simulate_batch(scenario: Scenario) -> Trajectory:
    """Run a scenario in this process, all fish as one batch, and record every snapshot.

    Tick 0 is the initial state. Returns the fish at every snapshot (whole control periods).
    """
    params = WorldParams.of(scenario)
    fish = with_compiled_decisions(scenario.fish_params(), scenario.fish)
    ids = np.arange(scenario.fish, dtype=np.int64)
    world = WorldSim(params)
    world.join(ids.tolist())
    memory = FishMemory.fresh(fish, scenario.fish)
    channel_rngs = [stream(scenario.seed, Stream.CHANNEL, int(i)) for i in ids]
    inbox = Inbox.empty(scenario.fish)
    sent = None
    recorder = TrajectoryRecorder()
    while True:
        event = world.next_event()
        perceived = world.sense()
        if event.snapshot is not None:
            recorder.add(event.time, world, perceived)
            if event.last:
                break
            if sent is not None:
                inbox = deliver(
                    world.state.position,
                    world.state.yaw,
                    sent,
                    channel_range=params.channel_range,
                    loss=params.channel_loss,
                    rngs=channel_rngs,
                    sight=params.flag_sight,
                    one_bit_flags=params.one_bit_flags,
                )
                sent = None
        if not event.deciding:
            continue
        fish, memory = apply_directive(fish, memory, params.formation_at(event.time))
        due, rows = world.due()
        everyone = len(due) == ids.size
        perception = perception_of(world, perceived, rows, event.time)
        own = memory if everyone else take_rows(memory, rows)
        heard = inbox if everyone else take_rows(inbox, rows)
        own, decision = decide(own, perception, heard, params=fish)
        memory = own if everyone else put_rows(memory, rows, own)
        world.hold(due, decision.fins)
        inbox = Inbox.empty(scenario.fish)
        if everyone and params.time_mode != "jitter" and decision.outbox.mask.any():
            sent = decision.outbox
    return recorder.trajectory(ids)


def perception_of(
    world: WorldSim, perceived: Perceived, rows: NDArray[np.intp], time: float
) -> Perception:
    """The perception of the fish at ``rows`` as the fish core takes it."""
    landmarks = world.sense_landmarks()
    everyone = rows.size == world.ids.size
    pick = slice(None) if everyone else rows
    count = rows.size
    return Perception(
        np.full(count, time),
        world.state.position[pick, 2],
        perceived.neighbors[pick],
        perceived.mask[pick],
        landmarks.neighbors[pick],
        landmarks.mask[pick],
        world.state.yaw[pick],  # the simulated fish's compass
    )
