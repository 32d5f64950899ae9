"""The world actor (simulation only): owns every fish's state, integrates, perceives.

Lockstep mode (DESIGN.md §3): at tick k the world publishes the snapshot and every live
fish's perception, waits until every live fish has answered tick k (a fish that disappears
from liveliness or misses ``command_timeout`` is marked lost), integrates one control period
and moves on, as fast as the machine allows. Everything order-dependent is done in fish-id
order, so the same seed gives bit-identical trajectories however the fish are spread over
processes.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import trio
import zenoh
from numpy.typing import ArrayLike

from fishswarm.actors.bridge import (
    Inbox,
    Put,
    declare_subscriber,
    open_alive_events,
    open_queryable,
    open_subscriber,
    open_token,
    publisher,
    reply,
)
from fishswarm.actors.intake import Intake
from fishswarm.actors.perceptions import perception_messages
from fishswarm.bluebot.dynamics import State
from fishswarm.bluebot.vision import Perceived
from fishswarm.jitter import JitterSchedule, next_event
from fishswarm.progress import ids_text
from fishswarm.protocols.codec import MessageError, decode, encode
from fishswarm.protocols.messages import (
    ChannelReport,
    Command,
    CommandBatch,
    ControlReply,
    ControlRequest,
    Snapshot,
)
from fishswarm.scenario import Scenario
from fishswarm.simulation import Stream, advance, observe, observe_landmarks, place, stream

log = logging.getLogger(__name__)

NO_FINS = np.zeros(4)
"""Fins of a fish that has not decided yet: off."""

Event = tuple[str, str, bytes | bool]


class StartTimeout(RuntimeError):
    """The fish the world waits for did not all come up in time."""


@dataclass(frozen=True)
class WorldSettings:
    """How the world runs.

    Attributes:
        scenario: what to simulate.
        expected_fish: ids the world waits for before the first tick.
        start_timeout: longest wait for them, s.
        command_timeout: a fish that has not answered a tick within this is marked lost, s.
        channel_timeout: longest wait for the channel's report on a tick, s.
        admit_delay: a fish that comes up is admitted at the first tick at least this long
            after the world subscribed to its commands, s (the subscription must reach the
            router first when the world runs as a client).
    """

    scenario: Scenario
    expected_fish: tuple[int, ...] = ()
    start_timeout: float = 30.0
    command_timeout: float = 10.0
    channel_timeout: float = 5.0
    admit_delay: float = 0.1


@dataclass
class LostFish:
    """A fish that left the run.

    Attributes:
        fish_id: which fish.
        tick: the tick at which it was marked lost.
        reason: why.
        noticed_at: ``time.monotonic()`` when the world noticed.
    """

    fish_id: int
    tick: int
    reason: str
    noticed_at: float = field(default_factory=time.monotonic)


@dataclass
class _Tick:
    """The commands of one tick as they come in, row by row in the order of the world's ids."""

    rows: dict[int, int] = field(default_factory=dict)
    waiting: set[int] = field(default_factory=set)
    fins: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    broadcasts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    report: ChannelReport | None = None

    @classmethod
    def of(cls, ids: list[int], report: ChannelReport | None) -> _Tick:
        """A tick waiting for a command of each of ``ids``."""
        return cls(
            {fish_id: row for row, fish_id in enumerate(ids)},
            set(ids),
            np.zeros((len(ids), 4)),
            np.zeros(len(ids), dtype=np.int64),
            report,
        )


class World:
    """The simulated world. ``await world.run(session)`` runs the scenario to its end."""

    def __init__(self, settings: WorldSettings) -> None:
        self.settings = settings
        self.scenario = settings.scenario
        self.keys = settings.scenario.keys
        self.state_name = "waiting"
        self.tick = 0
        self.lost: list[LostFish] = []
        self.joined: list[tuple[int, int]] = []
        self.wall_time = 0.0
        self._intake = Intake("world")
        self._events: Inbox[Event]
        self._alive_fish: set[int] = set()
        self._session: zenoh.Session | None = None
        # Command subscriptions by key, with the time each was declared; the command key of
        # every fish (its own, or its school's).
        self._command_subscribers: dict[str, tuple[zenoh.Subscriber[None], float]] = {}
        self._command_key: dict[int, str] = {}
        self._school_of: dict[int, str | None] = {}
        self._channel_alive = 0
        self._ids = np.zeros(0, dtype=np.int64)
        self._state = place(self.scenario, self._ids)
        self._broadcasts = np.zeros(0, dtype=np.int64)
        self._vision_rngs: dict[int, np.random.Generator] = {}
        self._departed: dict[int, State] = {}
        self._resume = trio.Event()
        self._resume.set()
        self._stop_requested = False
        self._messages_out = 0
        self._current = _Tick()
        self._answer_tick = 0
        """The tick the commands now awaited must carry (the event number in jitter mode)."""
        self._last_fins: dict[int, np.ndarray] = {}
        self.late_commands = 0
        """Realtime mode: commands that missed their tick's deadline (the fish kept its last)."""

    @property
    def time(self) -> float:
        """Simulated time now, s."""
        return self.tick * self.scenario.control_period

    def statistics(self) -> dict[str, object]:
        """Counters of the run so far."""
        return {
            "ticks": self.tick,
            "messages_in": self._intake.accepted,
            "messages_out": self._messages_out,
            "rejected": self._intake.rejected_total,
            "rejected_by_kind": dict(self._intake.rejected),
            "lost_fish": len(self.lost),
            "joined_fish": len(self.joined),
            "late_commands": self.late_commands,
            "live_fish": int(self._ids.size),
        }

    async def run(
        self,
        session: zenoh.Session,
        *,
        task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
    ) -> None:
        """Run the scenario to its end (or a stop request); readiness once subscribed."""
        self._events = Inbox()
        keys = self.keys
        put = publisher(session)
        events = self._events
        self._session = session
        # One exact subscription per fish, not one on fish/*/command: a router matches a
        # wildcard for every message (measured: 155 µs per command against 22 µs).
        async with (
            open_subscriber(
                session, keys.channel_report, lambda k, p: events.push(("report", k, p))
            ),
            open_alive_events(
                session, keys.alive_all(), lambda k, alive: events.push(("alive", k, alive))
            ),
            open_queryable(session, keys.control) as queries,
            open_token(session, keys.alive("world", 0)),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(self._serve_control, queries)
            task_status.started()
            try:
                await self._wait_for_fish()
                started = time.perf_counter()
                self.state_name = "running"
                try:
                    await self._loop(put)
                finally:
                    self.wall_time = time.perf_counter() - started
            finally:
                for subscriber, _ in self._command_subscribers.values():
                    subscriber.undeclare()
                self._command_subscribers.clear()
            self.state_name = "stopped" if self._stop_requested else "finished"
            nursery.cancel_scope.cancel()

    async def _wait_for_fish(self) -> None:
        expected = set(self.settings.expected_fish)
        with trio.move_on_after(self.settings.start_timeout):
            while not expected <= self._alive_fish:
                self._handle(await self._events.receive())
        missing = sorted(expected - self._alive_fish)
        if missing:
            raise StartTimeout(
                f"{len(missing)} of {len(expected)} fish did not come up within "
                f"{self.settings.start_timeout:g} s (missing ids: {ids_text(missing)})"
            )
        await trio.sleep(self.settings.admit_delay)
        self._drain()
        self._admit_new_fish()

    async def _loop(self, put: Put) -> None:
        if self.scenario.time_mode == "jitter":
            await self._loop_jitter(put)
            return
        realtime = self.scenario.time_mode == "realtime"
        tick_start = trio.current_time()
        while True:
            self._drain()
            self._drop_lost()
            self._admit_new_fish()
            perceived = self._observe()
            if self._publish_snapshot(put, perceived):
                return
            await self._resume.wait()
            if realtime and trio.current_time() - tick_start > self.scenario.control_period:
                tick_start = trio.current_time()  # after a pause: pace from now on
            inbox_counts = await self._inbox_counts()
            self._current = _Tick.of(self._ids.tolist(), self._current.report)
            landmarks = observe_landmarks(self.scenario, self._state)
            self._answer_tick = self.tick
            self._publish_perceptions(
                put, perceived, landmarks, inbox_counts, tick=self.tick, time=self.time
            )
            if realtime:
                tick_start += self.scenario.control_period
                await self._collect_until(tick_start)
            else:
                await self._collect_commands()
            self._drop_lost()
            # Fish lost while the world waited have left self._ids; keep the others' rows.
            rows = [self._current.rows[fish_id] for fish_id in self._ids.tolist()]
            self._state = advance(self.scenario, self._state, self._current.fins[rows])
            self._broadcasts = self._current.broadcasts[rows]
            if realtime:
                self._last_fins = dict(
                    zip(self._ids.tolist(), self._current.fins[rows], strict=True)
                )
            self.tick += 1

    async def _loop_jitter(self, put: Put) -> None:
        """Jitter mode: event by event, each fish on its own clock (:mod:`fishswarm.jitter`).

        The same events as :func:`fishswarm.jitter.run_jittered`: snapshots at whole control
        periods, decisions of the due fish in between; perceptions carry the event number as
        their tick. Broadcasts are not delivered in this mode.
        """
        schedule = JitterSchedule(self.scenario)
        fins: dict[int, np.ndarray] = {}
        now, event = 0.0, 0
        while True:
            self._drain()
            self._drop_lost()
            self._admit_new_fish()
            live = self._ids.tolist()
            for fish_id in set(schedule.next_time) - set(live):
                schedule.remove(fish_id)
            for fish_id in live:
                if fish_id not in schedule.next_time:
                    schedule.add(fish_id, now)
            kind, at = next_event(schedule, self.tick * self.scenario.control_period)
            held = np.array([fins.get(i, NO_FINS) for i in live]).reshape(-1, 4)
            self._state = advance(self.scenario, self._state, held, duration=at - now)
            now = at
            perceived = self._observe()
            if kind == "snapshot":
                if self._publish_snapshot(put, perceived):
                    return
                self.tick += 1
                continue
            await self._resume.wait()
            due = schedule.due(now)
            rows = [live.index(fish_id) for fish_id in due]
            event += 1
            self._answer_tick = event
            self._current = _Tick.of(due, None)
            landmarks = observe_landmarks(self.scenario, self._state)
            inbox_counts = np.zeros(len(live), dtype=np.int64)
            self._publish_perceptions(
                put, perceived, landmarks, inbox_counts, tick=event, time=now, rows=rows
            )
            # A fish lost while the world waited keeps fins off; it leaves at the next event.
            await self._collect_commands()
            for fish_id in due:
                fins[fish_id] = self._current.fins[self._current.rows[fish_id]]
            schedule.decided(due)

    def _publish_perceptions(
        self,
        put: Put,
        perceived: Perceived,
        landmarks: Perceived,
        inbox_counts: np.ndarray,
        *,
        tick: int,
        time: float,
        rows: list[int] | None = None,
    ) -> None:
        """The perceptions of the fish at ``rows`` (default all live fish): one message per
        school, one per fish on its own keys."""
        for key, message in perception_messages(
            self.keys,
            ids=self._ids,
            school_of=self._school_of,
            depth=self._state.position[:, 2],
            perceived=perceived,
            landmarks=landmarks,
            inbox_counts=inbox_counts,
            tick=tick,
            time=time,
            rows=rows,
        ):
            put(key, encode(message))
            self._messages_out += 1

    def _observe(self) -> Perceived:
        """What every live fish sees now (each fish's own vision-noise stream)."""
        rngs = [self._vision_rngs[fish_id] for fish_id in self._ids.tolist()]
        return observe(self.scenario, self._state, rngs)

    def _publish_snapshot(self, put: Put, perceived: Perceived) -> bool:
        """Publish the snapshot of this tick; whether the run ends with it."""
        put(self.keys.snapshot, encode(self._snapshot(perceived)))
        self._messages_out += 1
        return self.tick >= self.scenario.ticks or self._stop_requested

    def _snapshot(self, perceived: Perceived) -> Snapshot:
        return Snapshot(
            self.tick,
            self.time,
            self._ids,
            self._state.position,
            self._state.tank_velocity(),
            self._state.yaw,
            perceived.counts,
            self._broadcasts,
        )

    async def _inbox_counts(self) -> np.ndarray:
        counts = np.zeros(self._ids.size, dtype=np.int64)
        if self.tick == 0 or int(self._broadcasts.sum()) == 0:
            return counts
        if not self._channel_alive:
            log.warning("broadcasts at tick %d but no channel is running: not delivered", self.tick)
            return counts
        with trio.move_on_after(self.settings.channel_timeout):
            while self._current.report is None or self._current.report.tick != self.tick:
                self._handle(await self._events.receive())
        report = self._current.report
        if report is None or report.tick != self.tick:
            log.warning("no channel report for tick %d: deliveries not announced", self.tick)
            return counts
        by_id = dict(zip(report.ids.tolist(), report.inbox_counts.tolist(), strict=True))
        return np.array([by_id.get(i, 0) for i in self._ids.tolist()], dtype=np.int64)

    async def _collect_until(self, deadline: float) -> None:
        """Realtime mode: take commands until the tick's wall-clock end; a fish that has not
        answered by then keeps its last command (fins off if it never sent one)."""
        for fish_id in self._current.waiting:
            last = self._last_fins.get(fish_id)
            if last is not None:
                self._current.fins[self._current.rows[fish_id]] = last
        with trio.move_on_at(deadline):
            while True:
                self._handle(await self._events.receive())
        self.late_commands += len(self._current.waiting)

    def _late(self, tick: int) -> bool:
        """Realtime mode: a command for a tick already integrated came late, which is normal
        there (counted in ``late_commands`` when its tick closed), not bad input."""
        return self.scenario.time_mode == "realtime" and tick < self._answer_tick

    async def _collect_commands(self) -> None:
        deadline = trio.current_time() + self.settings.command_timeout
        with trio.move_on_at(deadline):
            while self._current.waiting:
                self._handle(await self._events.receive())
        for fish_id in sorted(self._current.waiting):
            self._mark_lost(fish_id, f"no command within {self.settings.command_timeout:g} s")

    def _drain(self) -> None:
        while (event := self._events.receive_nowait()) is not None:
            self._handle(event)

    def _handle(self, event: Event) -> None:
        kind, key, payload = event
        if kind == "alive":
            assert isinstance(payload, bool)
            self._on_alive(key, payload)
            return
        assert isinstance(payload, bytes)
        if kind == "report":
            report = self._intake.decode(key, payload, ChannelReport)
            if report is not None:
                self._current.report = report
            return
        if kind == "batch":
            self._take_batch(key, payload)
            return
        sender, _ = self.keys.member_of(key)
        command = self._intake.decode_addressed(
            key, payload, Command, field="fish_id", owner=int(sender)
        )
        if command is None:
            return
        self._accept(key, command.tick, [command.fish_id], command.fins[None], [command.broadcasts])

    def _take_batch(self, key: str, payload: bytes) -> None:
        batch = self._intake.decode(key, payload, CommandBatch)
        if batch is None:
            return
        ids = batch.ids.tolist()
        if any(self._command_key.get(fish_id) != key for fish_id in ids):
            self._intake.reject(key, "misaddressed", f"fish {ids} are not all of this school")
            return
        self._accept(key, batch.tick, ids, batch.fins, batch.broadcasts)

    def _accept(
        self, key: str, tick: int, ids: list[int], fins: np.ndarray, broadcasts: ArrayLike
    ) -> None:
        """Take the commands of fish ``ids`` for ``tick``, unless late or stale."""
        current = self._current
        if self._late(tick):
            return
        if tick != self._answer_tick or not current.waiting.issuperset(ids):
            self._intake.reject(key, "stale", f"commands for tick {tick} at {self._answer_tick}")
            return
        rows = [current.rows[fish_id] for fish_id in ids]
        current.fins[rows] = fins
        current.broadcasts[rows] = broadcasts
        current.waiting.difference_update(ids)

    def _on_alive(self, key: str, alive: bool) -> None:
        try:
            member = self.keys.parse_alive(key)
        except ValueError:
            return
        if member.role == "channel":
            self._channel_alive += 1 if alive else -1
            return
        if member.role != "fish" or not member.member_id.isdigit():
            return
        fish_id = int(member.member_id)
        if alive:
            self._alive_fish.add(fish_id)
            self._school_of[fish_id] = member.school
            self._subscribe_commands(fish_id, member.school)
        else:
            self._alive_fish.discard(fish_id)
            if fish_id in self._ids:
                self._mark_lost(fish_id, "left (liveliness token gone)")

    def _subscribe_commands(self, fish_id: int, school: str | None) -> None:
        if self._session is None:
            return
        if school is None:
            key, kind = self.keys.command(fish_id), "command"
        else:
            key, kind = self.keys.school_commands(school), "batch"
        self._command_key[fish_id] = key
        if key in self._command_subscribers:
            return
        events = self._events
        subscriber = declare_subscriber(
            self._session,
            key,
            lambda key, payload: events.push((kind, key, payload)),
            exact=True,
        )
        self._command_subscribers[key] = (subscriber, trio.current_time())

    def _mark_lost(self, fish_id: int, reason: str) -> None:
        if any(f.fish_id == fish_id and f.tick == self.tick for f in self.lost):
            return
        log.warning("fish %d lost at tick %d: %s", fish_id, self.tick, reason)
        self.lost.append(LostFish(fish_id, self.tick, reason))
        self._alive_fish.discard(fish_id)
        self._current.waiting.discard(fish_id)

    def _drop_lost(self) -> None:
        gone = {f.fish_id for f in self.lost if f.tick == self.tick}
        if not gone.intersection(self._ids.tolist()):
            return
        keep = np.array([i not in gone for i in self._ids.tolist()], dtype=bool)
        for index in np.flatnonzero(~keep):
            self._departed[int(self._ids[index])] = self._state.take(np.array([index]))
        self._ids = self._ids[keep]
        self._state = self._state.take(np.flatnonzero(keep))
        self._broadcasts = self._broadcasts[keep]

    def _admit_new_fish(self) -> None:
        ready_since = trio.current_time() - self.settings.admit_delay
        new = sorted(
            fish_id
            for fish_id in self._alive_fish - set(self._ids.tolist())
            if self._command_subscribers[self._command_key[fish_id]][1] <= ready_since
        )
        if not new:
            return
        for fish_id in new:
            self._vision_rngs.setdefault(
                fish_id, stream(self.scenario.seed, Stream.VISION, fish_id)
            )
            if self.tick > 0:
                self.joined.append((fish_id, self.tick))
                log.info("fish %d joined at tick %d", fish_id, self.tick)
        parts = [self._state]
        for fish_id in new:
            parts.append(
                self._departed.pop(fish_id)
                if fish_id in self._departed
                else place(self.scenario, np.array([fish_id], dtype=np.int64))
            )
        ids = np.concatenate([self._ids, np.array(new, dtype=np.int64)])
        order = np.argsort(ids, kind="stable")
        merged = State(
            np.concatenate([p.position for p in parts])[order],
            np.concatenate([p.yaw for p in parts])[order],
            np.concatenate([p.body_velocity for p in parts])[order],
            np.concatenate([p.yaw_rate for p in parts])[order],
        )
        self._broadcasts = np.concatenate([self._broadcasts, np.zeros(len(new), np.int64)])[order]
        self._ids, self._state = ids[order], merged

    async def _serve_control(self, queries: Inbox[zenoh.Query]) -> None:
        async for query in queries:
            try:
                payload = b"" if query.payload is None else query.payload.to_bytes()
                request = decode(payload, ControlRequest)
            except MessageError as error:
                self._intake.reject(str(query.key_expr), "malformed", str(error))
                query.drop()
                continue
            if request.action == "pause":
                self._resume = trio.Event()
                self.state_name = "paused"
            elif request.action == "resume" and not self._resume.is_set():
                self._resume.set()
                self.state_name = "running"
            elif request.action == "stop":
                self._stop_requested = True
                self._resume.set()
            reply_message = ControlReply(
                self.state_name, self.tick, self.time, len(self._alive_fish)
            )
            reply(query, encode(reply_message))
