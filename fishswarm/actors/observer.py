"""The observer actor: watches snapshots and liveliness, records, computes metrics, reports.

Any number of observers can attach, locally or from another machine, and leave without
disturbing the run: an observer only listens.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import trio

from fishswarm.actors.bus import Bus, open_alive_events, open_subscriber, open_token
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.intake import Intake
from fishswarm.actors.threads import in_thread_at_once
from fishswarm.actors.world import OFFLOAD_FISH
from fishswarm.protocols.keys import KeySpace, run_id_of
from fishswarm.protocols.messages import Snapshot, WorldPulse
from fishswarm.sim import kernels
from fishswarm.sim.scenario import Scenario
from fishswarm.study.metrics import (
    FormationTarget,
    FormationTargets,
    OrbitTarget,
    OrbitTracker,
    orbit_target_of,
    prepare_metrics,
    swarm_metrics,
)
from fishswarm.study.recording import Recorder
from fishswarm.study.scene import Scene, Stage, scene_message, scene_of, stage_of

log = logging.getLogger(__name__)


WORLD_END_SETTLE = 1.0
"""How long an observer goes on listening for snapshots after the world has left, s."""

ENDED_RUNS_KEPT = 16
"""How many runs that have given way an observer remembers, to refuse their late snapshots."""

RECORDED_SCENE_FISH = 1000
"""Recordings carry the scene of swarms up to this size; beyond, its JSON (about 270 bytes
a fish, 3 ms a snapshot at 1 000 fish) would outweigh the snapshots several times over and
slow the observer."""


@dataclass(frozen=True)
class Progress:
    """What an observer knows after a snapshot: its tick, time (s), fish and metrics, and
    in a formation run the shape the fish were told to take, which the formation metrics
    measure (None in other runs)."""

    tick: int
    time: float
    fish: int
    metrics: dict[str, float]
    shape: str | None = None


@dataclass(frozen=True)
class ObserverStatistics:
    """Counters of an observer.

    Attributes:
        snapshots: snapshots accepted.
        rejected: messages rejected.
        events: liveliness events seen.
    """

    snapshots: int
    rejected: int
    events: int


class Observer:
    """Watches a swarm. ``await observer.run(bus)`` serves until cancelled.

    Args:
        keys: the swarm's key space.
        recorder: where to record snapshots, metrics and events (optional).
        on_progress: called after every snapshot.
        observer_id: id of this observer's liveliness token.
        formations: the targets to measure formation metrics against (formation runs): the
            one of the shape each snapshot says the fish are told to take.
        orbit: a post and radius to measure orbit metrics against (orbit, milling, waltz).
        stage: the tank and landmark, drawn in the recorded scenes (optional).
        on_scene: called after every snapshot with what the swarm looks like and the
            snapshot's metrics (e.g. a live view).
        on_new_run: called with its run id when the snapshots of a later run begin (a world
            run again on the swarm while the observer stays), before the first of them is
            measured or drawn. The observer then starts afresh: its ticks, its orbit counts
            and its wait for the world's end are the new run's, and the earlier run's
            snapshots, should any come late, are refused as stale. Without it (None) the
            observer watches the first run it sees, and lets later runs' snapshots go.
    """

    def __init__(
        self,
        keys: KeySpace,
        *,
        recorder: Recorder | None = None,
        on_progress: Callable[[Progress], None] | None = None,
        observer_id: str = "0",
        formations: FormationTargets | None = None,
        orbit: OrbitTarget | None = None,
        stage: Stage | None = None,
        on_scene: Callable[[Scene, dict[str, float]], None] | None = None,
        on_new_run: Callable[[int], None] | None = None,
        fish: int | None = None,
    ) -> None:
        self.keys = keys
        self.fish = fish
        """How many fish the runs watched have, when known beforehand (None: not known): what
        measures them is then loaded while the fish come up."""
        self.on_new_run = on_new_run
        self.stage = stage
        self.on_scene = on_scene
        self.recorder = recorder
        self.on_progress = on_progress
        self.observer_id = observer_id
        self.formations = formations
        self.orbit = orbit
        self._orbit_tracker = None if orbit is None else OrbitTracker(orbit)
        self.history: list[Progress] = []
        self.events: list[dict[str, Any]] = []
        self._intake = Intake(f"observer {observer_id}")
        self._inbox: Inbox[tuple[str, str, bytes | bool]]
        self._last_tick = -1
        self._tick_reached = trio.Event()
        self._world_left = trio.Event()
        self._world_back = trio.Event()
        self._sim_time = 0.0
        self.world_run: int | None = None
        """Take only the snapshots of this run of the world (None: any): an observer that
        records one world's run must not record another's, on the same swarm."""
        self.current_run: int | None = None
        """The run of the snapshots taken so far (None before the first)."""
        self._later_runs = 0
        """How many runs' snapshots have begun after the first's."""
        self._left_run: int | None = None
        """The run whose world left last."""
        self._ended_runs: deque[int] = deque(maxlen=ENDED_RUNS_KEPT)
        """Runs that have given way to a later one, latest last."""
        self._pulsing: deque[int] = deque(maxlen=ENDED_RUNS_KEPT)
        """Runs whose world's pulse came through (a router may not pass it on)."""
        self._said_ended: deque[int] = deque(maxlen=ENDED_RUNS_KEPT)
        """Runs whose world said, by its last pulse, that the run is over."""

    @classmethod
    def of(
        cls,
        scenario: Scenario,
        *,
        recorder: Recorder | None = None,
        on_progress: Callable[[Progress], None] | None = None,
        observer_id: str = "0",
        on_scene: Callable[[Scene, dict[str, float]], None] | None = None,
    ) -> Observer:
        """An observer of a run of ``scenario``, measuring what its behaviour aims at (a
        formation's shape, an orbit's post and radius) besides the distances."""
        return cls(
            scenario.keys,
            recorder=recorder,
            on_progress=on_progress,
            observer_id=observer_id,
            formations=FormationTargets.of(scenario),
            orbit=orbit_target_of(scenario),
            stage=stage_of(scenario),
            on_scene=on_scene,
            fish=scenario.fish,
        )

    @property
    def formation(self) -> FormationTarget | None:
        """The target of the run's configured shape (None: not a formation run)."""
        return None if self.formations is None else self.formations.at(None)

    def measure_as(self, scenario: Scenario) -> None:
        """From the next snapshot on, measure and draw the run of ``scenario`` (for an
        observer that attached before it knew what runs)."""
        self.formations = FormationTargets.of(scenario)
        self.orbit = orbit_target_of(scenario)
        self._orbit_tracker = None if self.orbit is None else OrbitTracker(self.orbit)
        self.stage = stage_of(scenario)

    def statistics(self) -> ObserverStatistics:
        """The observer's counters so far."""
        return ObserverStatistics(
            self._intake.accepted, self._intake.rejected_total, len(self.events)
        )

    async def run(
        self, bus: Bus, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED
    ) -> None:
        """Observe until cancelled; readiness once subscribed."""
        self._inbox = inbox = Inbox[tuple[str, str, bytes | bool]]()
        async with (
            open_subscriber(bus, self.keys.snapshot, lambda k, p: inbox.push(("snapshot", k, p))),
            open_subscriber(bus, self.keys.world_pulse, lambda k, p: inbox.push(("pulse", k, p))),
            open_alive_events(bus, self.keys.alive_all(), lambda k, a: inbox.push(("alive", k, a))),
            open_token(bus, self.keys.alive("observer", self.observer_id)),
            trio.open_nursery() as nursery,
        ):
            if self.fish is not None and kernels.compiles(self.fish):
                nursery.start_soon(_prepare_in_thread, self.fish)
            task_status.started()
            async for kind, key, payload in inbox:
                if kind == "alive":
                    assert isinstance(payload, bool)
                    self._on_alive(key, payload)
                elif kind == "pulse":
                    assert isinstance(payload, bytes)
                    self._on_pulse(key, payload)
                else:
                    assert isinstance(payload, bytes)
                    await self._on_snapshot(key, payload)

    async def wait_for_tick(self, tick: int) -> None:
        """Wait until a snapshot of ``tick`` or later has been seen (bound it with a timeout).

        Any number of tasks may wait at once."""
        while self._last_tick < tick:
            await self._tick_reached.wait()

    @property
    def last_tick(self) -> int:
        """The latest tick of the run watched that a snapshot has shown (-1: none yet)."""
        return self._last_tick

    async def wait_for_world_back(self) -> None:
        """Wait until the world of the run watched, once left, is back on the swarm (bound
        it with a timeout): its token seen again, as after a lost router came back. Its
        leaving may then be waited for again. Returns at once if it is back already (its
        token may return while its end is still being waited for)."""
        if not self._world_left.is_set():
            return
        await self._world_back.wait()

    def world_said_ended(self, run: int | None = None) -> bool | None:
        """Whether the world of the run watched said its run is over — at its end, or when
        it was stopped or failed — by its last pulse: True; it pulsed but did not say so (it
        died, or the router was lost): False; no pulse of it came through, so this cannot
        be told (a secured router whose access control predates the pulse's reaching
        observers): None. ``run``: the run of that world (None: the run watched now)."""
        if run is None:
            run = self.current_run
        if run in self._said_ended:
            return True
        return False if run in self._pulsing else None

    async def wait_for_world_end(
        self,
        *,
        settle: float = WORLD_END_SETTLE,
        on_left: Callable[[], None] | None = None,
    ) -> int | None:
        """Wait until the world leaves the swarm and its last snapshots are in (bound it with
        a timeout); the run of that world (None: no snapshot of it came).

        The world's snapshots travel apart from its liveliness token, and the last of them
        may arrive just after the token is gone (seen under load): once the world has left
        (its token gone, or a later run begun; ``on_left`` is called then), this waits until
        no snapshot has come for ``settle`` seconds, or until the snapshots of a later run
        begin (which ends the run waited for, too)."""
        later_runs = self._later_runs
        await self._world_left.wait()
        run = self._left_run
        if on_left is not None:
            on_left()
        while self._later_runs == later_runs:
            arrived = self._tick_reached
            with trio.move_on_after(settle) as quiet:
                await arrived.wait()
            if quiet.cancelled_caught:
                return run
        return run

    def _on_pulse(self, key: str, payload: bytes) -> None:
        pulse = self._intake.decode(key, payload, WorldPulse)
        if pulse is None:
            return
        self._intake.disregard()  # a pulse is no snapshot: the count of those stays exact
        if pulse.run not in self._pulsing:
            self._pulsing.append(pulse.run)
        if pulse.state == "ended" and pulse.run not in self._said_ended:
            self._said_ended.append(pulse.run)

    def _on_alive(self, key: str, alive: bool) -> None:
        try:
            member = self.keys.parse_alive(key)
        except ValueError:
            return
        event = {
            "event": "joined" if alive else "left",
            "role": member.role,
            "id": member.member_id,
            "time": self._sim_time,
        }
        self.events.append(event)
        if self.recorder is not None:
            self.recorder.event(self._sim_time, event)
        # The world of the run being watched has left (a world token names its run): not
        # that of an earlier run, whose leaving may come after the next run's first snapshot.
        watched = self.current_run in (None, run_id_of(member.member_id))
        if member.role == "world" and not alive and watched:
            self._left_run = self.current_run
            self._world_left.set()
        elif member.role == "world" and alive and watched and self._world_left.is_set():
            # Its token is back (the router was lost, and is back): it has not left after all.
            self._world_left = trio.Event()
            self._world_back.set()
            self._world_back = trio.Event()

    def _start_run(self, run: int) -> None:
        """The snapshots of ``run`` begin: a later run starts afresh (and is announced)."""
        earlier = self.current_run
        self.current_run = run
        if earlier is None:
            return
        self._ended_runs.append(earlier)
        self._later_runs += 1
        self._last_tick = -1
        self._left_run = earlier
        self._world_left.set()  # the earlier run is over (worlds take turns): wake its waiters
        self._world_left = trio.Event()
        self._orbit_tracker = None if self.orbit is None else OrbitTracker(self.orbit)
        if self.on_new_run is not None:
            self.on_new_run(run)

    async def _on_snapshot(self, key: str, payload: bytes) -> None:
        snapshot = self._intake.decode(key, payload, Snapshot)
        if snapshot is None:
            return
        if self.world_run is not None and snapshot.run != self.world_run:
            # Another world's run on the swarm (worlds take turns on a router): ordinary,
            # so neither a rejection nor a warning, and not this observer's to measure.
            self._intake.disregard()
            return
        if snapshot.run != self.current_run:
            if snapshot.run in self._ended_runs:
                self._intake.refuse(
                    key, "stale", f"snapshot of run {snapshot.run}, which has given way"
                )
                return
            if self.current_run is not None and self.on_new_run is None:
                self._intake.disregard()  # a later run: this observer watches its first only
                return
            self._start_run(snapshot.run)
        if snapshot.tick <= self._last_tick:
            self._intake.refuse(key, "stale", f"snapshot of tick {snapshot.tick} repeated")
            return
        measure = (snapshot.position, snapshot.neighbors_seen, snapshot.effort)
        if snapshot.ids.size >= OFFLOAD_FISH:
            # Hundreds of fish or more: the distances take a millisecond or more; in a
            # thread, the world's tick (in this process) goes on meanwhile.
            metrics = await in_thread_at_once(
                lambda: swarm_metrics(*measure), name="fishswarm observer metrics"
            )
        else:
            metrics = swarm_metrics(*measure)
        shape, target = None, None
        if self.formations is not None:
            shape = self.formations.shape_told(snapshot.formation, snapshot.time)
            target = self.formations.at(shape)
        if target is not None:
            try:
                metrics.update(target.metrics(snapshot.position))
            except ValueError as error:  # e.g. positions no assignment can handle
                log.warning("no formation metrics at tick %d: %s", snapshot.tick, error)
        if self._orbit_tracker is not None:
            metrics.update(
                self._orbit_tracker.metrics(snapshot.ids, snapshot.position, snapshot.time)
            )
        progress = Progress(snapshot.tick, snapshot.time, int(snapshot.ids.size), metrics, shape)
        self.history.append(progress)
        self._sim_time = snapshot.time
        if self.recorder is not None:
            self.recorder.snapshot(snapshot.time, payload)
            self.recorder.metrics(
                snapshot.time,
                {"tick": snapshot.tick, "time": snapshot.time, "fish": progress.fish, **metrics},
            )
        recording_scene = self.recorder is not None and progress.fish <= RECORDED_SCENE_FISH
        if recording_scene or self.on_scene is not None:
            scene = scene_of(snapshot, target)
            if recording_scene:
                assert self.recorder is not None
                self.recorder.scene(snapshot.time, scene_message(scene, self.stage))
            if self.on_scene is not None:
                self.on_scene(scene, metrics)
        self._last_tick = snapshot.tick
        # Wake every waiter, and give later waiters a fresh event.
        self._tick_reached.set()
        self._tick_reached = trio.Event()
        if self.on_progress is not None:
            self.on_progress(progress)


async def _prepare_in_thread(fish: int) -> None:
    """Load what the metrics of ``fish`` fish take (:func:`prepare_metrics`) in a thread,
    beside the observer's first messages; a cancelled observer leaves the thread to finish
    on its own. Only a head start: should it fail, the first snapshot's metrics load them
    (and say what is wrong), so the observer goes on."""
    try:
        await trio.to_thread.run_sync(prepare_metrics, fish, abandon_on_cancel=True)
    except Exception as error:  # any failure: the first snapshot's metrics will tell it
        log.debug("the metrics of %d fish were not loaded ahead: %s", fish, error)
