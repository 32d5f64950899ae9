"""The tick sequence of the simulated world, written once for every time mode and both drivers.

:class:`WorldSim` holds the fish's states and fins and moves them event by event: the clock
says what comes next, the fish swim up to it with their fins held, the world sees, and the
fish that are due decide. The world actor drives it over the network (its fish decide in
other processes); the batch engine drives it in one process. Both call the same methods in
the same order, so they give the same trajectories bit for bit::

    world.leave(ids)                    # lost fish leave (the world actor only)
    event = world.next_event()          # the fish swim up to the event
    world.join(ids)                     # fish that came up enter (the world actor only)
    perceived = world.sense()           # what every fish sees now
    if event.snapshot is not None: ...  # snapshot (record, publish); stop if event.last
    if event.deciding: ...              # the due fish decide → world.hold(ids, fins)

Everything order-dependent goes in fish-id order; each fish has its own random streams.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.dynamics import State
from fishswarm.bluebot.parameters import effort_rate
from fishswarm.bluebot.vision import Perceived, perceive
from fishswarm.sim.clocks import Clock, Event, clock_for
from fishswarm.sim.physics import WorldParams, advance, observe, observe_landmarks, place
from fishswarm.sim.sight import SightCounts, score_sight
from fishswarm.sim.streams import Stream, stream

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
Rows = NDArray[np.intp]


class WorldSim:
    """The simulated fish of one run and their clock.

    Args:
        params: the compiled scenario.

    Attributes:
        ids: (N,) the fish in the world, ascending.
        state: their states, rows in the order of ``ids``.
        fins: (N, 4) the fins each fish holds until it decides again.
        effort: (N,) each fish's effort so far: gain-weighted fin beats (each fin's gain
            times its beat frequency, :func:`~fishswarm.bluebot.parameters.effort_rate`,
            times how long it ran) — a proxy of the energy the electromagnetic fins spend.
        now: simulated time of the last event, s.
    """

    def __init__(self, params: WorldParams) -> None:
        self.params = params
        self.clock: Clock = clock_for(
            time_mode=params.time_mode,
            period=params.control_period,
            jitter=params.jitter,
            seed=params.seed,
            ticks=params.ticks,
        )
        self.ids = np.zeros(0, dtype=np.int64)
        self.state = place(params, self.ids)
        self.fins = np.zeros((0, 4))
        self.effort = np.zeros(0)
        self.now = 0.0
        self._vision_rngs: dict[int, np.random.Generator] = {}
        self.sight = SightCounts()
        """With camera vision: its detections against the geometric model's, so far."""
        self._exact_vision = params.vision.exact()
        """What the fish could see, without the geometric model's noise (scoring only)."""
        self._departed: dict[int, tuple[State, float]] = {}

    def next_event(self) -> Event:
        """Move on to the next event: every fish swims up to it with its fins held."""
        event = self.clock.next_event()
        duration = event.duration
        if duration is not None and self.params.still_until > 0:
            # The study code's fish did not move before their clock passed 1: only the part
            # of this interval after the hold counts.
            moving = min(duration, event.time - self.params.still_until)
            duration = moving if moving > 0 else None
        if duration is not None:
            self.state = advance(self.state, self.fins, duration=duration, params=self.params)
            self.effort = self.effort + effort_rate(self.fins) * duration
        self.now = event.time
        return event

    def join(self, fish_ids: list[int]) -> None:
        """Fish enter the world now: at their spawn pose, or where they left it; fins off."""
        new = sorted(set(fish_ids) - set(self.ids.tolist()))
        if not new:
            return
        parts = [self.state]
        efforts = [self.effort]
        for fish_id in new:
            self._vision_rngs.setdefault(fish_id, stream(self.params.seed, Stream.VISION, fish_id))
            departed = self._departed.pop(fish_id, None)
            if departed is None:
                parts.append(place(self.params, np.array([fish_id], dtype=np.int64)))
                efforts.append(np.zeros(1))
            else:
                parts.append(departed[0])
                efforts.append(np.array([departed[1]]))
            self.clock.add(fish_id, self.now)
        ids = np.concatenate([self.ids, np.array(new, dtype=np.int64)])
        order = np.argsort(ids, kind="stable")
        self.state = State(
            np.concatenate([p.position for p in parts])[order],
            np.concatenate([p.yaw for p in parts])[order],
            np.concatenate([p.body_velocity for p in parts])[order],
            np.concatenate([p.yaw_rate for p in parts])[order],
        )
        self.fins = np.concatenate([self.fins, np.zeros((len(new), 4))])[order]
        self.effort = np.concatenate(efforts)[order]
        self.ids = ids[order]

    def leave(self, fish_ids: list[int]) -> Rows:
        """Fish leave the world (their state is kept should they come back).

        Returns:
            The rows the remaining fish had before (to cut other per-fish arrays alike).
        """
        gone = np.isin(self.ids, np.array(fish_ids, dtype=np.int64))
        keep: Rows = np.flatnonzero(~gone)
        if not gone.any():
            return keep
        for index in np.flatnonzero(gone).tolist():
            fish_id = int(self.ids[index])
            self._departed[fish_id] = (
                self.state.take(np.array([index])),
                float(self.effort[index]),
            )
            self.clock.remove(fish_id)
        self.ids = self.ids[keep]
        self.state = self.state.take(keep)
        self.fins = self.fins[keep]
        self.effort = self.effort[keep]
        return keep

    def sense(self) -> Perceived:
        """What every fish sees of the others now (each with its own vision-noise stream)."""
        noisy = self.params.cameras is not None or self.params.vision.noise > 0
        rngs = [self._vision_rngs[fish_id] for fish_id in self.ids.tolist()] if noisy else None
        perceived = observe(self.state, params=self.params, rngs=rngs)
        if self.params.cameras is not None:
            truth = perceive(self.state.position, self.state.yaw, vision=self._exact_vision)
            self.sight = self.sight + score_sight(perceived, truth, self.state.position)
        return perceived

    def sense_landmarks(self) -> Perceived:
        """Which landmarks every fish sees now."""
        return observe_landmarks(self.params, self.state)

    def due(self) -> tuple[IntArray, Rows]:
        """The fish that decide now: their ids (ascending, read-only) and rows."""
        due = self.clock.due(self.now)
        rows: Rows = np.searchsorted(self.ids, due).astype(np.intp)
        return due, rows

    def hold(self, fish_ids: IntArray, fins: FloatArray) -> None:
        """The fish ``fish_ids`` (in the world, ascending) decided ``fins`` (rows alike)."""
        rows = np.searchsorted(self.ids, fish_ids)
        self.fins[rows] = fins
        self.clock.decided(fish_ids)
