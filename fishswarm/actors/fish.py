"""The fish actor: perception and inbox in → the fish core decides → command and broadcasts
out; fins off when perceptions stop.

The same actor runs in simulation (the world sends perceptions, the channel deliveries) and
on a BlueBot (the driver does both, over an in-memory Bus in the same process). It knows
nothing of clocks or physics; it owns only its fish's memory, their safety watchdog and
their messages: the decision itself is :func:`fishswarm.behaviors.core.decide`.

One actor serves one or more fish on one Bus: on a robot a single fish, in a worker process
or beside the world in ``fishswarm run``'s own process many. Each fish keeps its own
liveliness token, memory, inbox and watchdog; what the fish share is the work. Perceptions
that arrive together are decided in one batched call — the same result bit for bit as one
call per fish (tested).

Perceptions and commands travel either on each fish's own keys (``fish/<id>/perception``
and ``fish/<id>/command``: what a robot does) or, for a *school*, as one
:class:`~fishswarm.protocols.messages.PerceptionBatch` and one
:class:`~fishswarm.protocols.messages.CommandBatch` per tick on the school's keys.
A fish's broadcasts always go out on its own outbox key, before its command, and the command
says how many there were, so that the world's tick waits for their delivery.

A perception of another run of the world (its ``run`` differs from the last one the fish
saw) starts the fish afresh: a robot's fish actor serves run after run.
"""

from __future__ import annotations

import collections
import contextlib
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import trio
from numpy.typing import NDArray

from fishswarm import __version__
from fishswarm.actors.bus import Bus, open_alive_events, open_subscriber, open_token
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.intake import Intake
from fishswarm.behaviors.core import (
    Decision,
    FishMemory,
    FishParams,
    Heard,
    Outbox,
    Perception,
    decide,
    inbox_of,
    pad_rows,
    put_rows,
    take_rows,
)
from fishswarm.behaviors.core import Inbox as HeardInbox
from fishswarm.behaviors.formation import apply_directive
from fishswarm.behaviors.registry import rules_of, settings_digest, settings_parts
from fishswarm.bluebot.control import stop_fins
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import (
    BROADCAST_KINDS,
    Broadcast,
    Command,
    CommandBatch,
    Delivery,
    FishAbout,
    PerceptionBatch,
    WorldPulse,
)
from fishswarm.protocols.messages import Perception as PerceptionMessage

log = logging.getLogger(__name__)

Rows = NDArray[np.intp]

PERCEPTION, BATCH, DELIVERY, PULSE, WORLD = "perception", "batch", "delivery", "pulse", "world"

PERCEPTION_TIMEOUT = 5.0
"""How long a fish swims on without a perception or a pulse of its world before its
watchdog turns its fins off, by default, s."""

ENDED_RUNS_KEPT = 16
"""Ended runs a fish actor remembers, to refuse their late perceptions."""

MAX_WAITING_DELIVERIES = 10_000
"""Most deliveries one fish keeps waiting for their perception."""

Event = tuple[int, str, str, bytes]
"""(fish index or −1 for a school batch, kind, key, payload)."""


@dataclass(frozen=True)
class FishSettings:
    """How a fish actor behaves.

    Attributes:
        fish_ids: the fish it serves (one on a robot).
        params: what they do (behaviour, controller, parameters).
        keys: the swarm's key space.
        perception_timeout: a fish with no perception for this long turns its fins off, s.
        inbox_timeout: longest wait for the deliveries a perception announces, s.
        school: serve the fish through this school's batched keys; None: each fish on its
            own keys.
    """

    fish_ids: tuple[int, ...]
    params: FishParams
    keys: KeySpace = KeySpace()
    perception_timeout: float = PERCEPTION_TIMEOUT
    inbox_timeout: float = 5.0
    school: str | None = None

    def __post_init__(self) -> None:
        if not self.fish_ids or len(set(self.fish_ids)) != len(self.fish_ids):
            raise ValueError(f"fish_ids must be distinct and not empty, got {self.fish_ids}")
        for name in ("perception_timeout", "inbox_timeout"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be a positive number of seconds")
        if self.school is not None:
            self.keys.school_commands(self.school)  # checks the name


@dataclass(frozen=True)
class FishStatistics:
    """Counters of a fish actor (summed over its fish).

    Attributes:
        perceptions: perceptions accepted.
        commands: commands sent.
        broadcasts: broadcasts sent.
        deliveries: deliveries acted on.
        rejected: messages rejected (malformed, misaddressed, stale).
        watchdog_stops: times a fish's fins were turned off for lack of perceptions.
        deliveries_missed: deliveries announced but never received.
        batches: batched decisions made.
        runs: new runs of the world started (after the first).
    """

    perceptions: int = 0
    commands: int = 0
    broadcasts: int = 0
    deliveries: int = 0
    rejected: int = 0
    watchdog_stops: int = 0
    deliveries_missed: int = 0
    batches: int = 0
    runs: int = 0


@dataclass(eq=False)
class _Pending:
    """Perceptions of some fish at one tick, waiting for the deliveries they announce.

    Attributes:
        rows: (G,) indices of the fish in the actor's ``fish_ids``.
        tick: the tick.
        time: simulated (or robot) time of the tick, s.
        depth: (G,) m.
        neighbor_counts: (G,) visible neighbours per fish.
        neighbors: (ΣK, 3) their body-frame positions, m, fish by fish.
        landmark_counts: (G,) visible landmarks per fish.
        landmarks: (ΣL, 3) their body-frame positions, m, fish by fish.
        inbox_counts: (G,) deliveries each fish waits for.
        deadline: when to stop waiting for deliveries (trio time).
        heading: (G,) compass headings, rad, or None without a compass.
        formation: the formation the fish are told to take (None: as configured).
    """

    rows: Rows
    tick: int
    time: float
    depth: NDArray[np.float64]
    neighbor_counts: NDArray[np.int64]
    neighbors: NDArray[np.float64]
    landmark_counts: NDArray[np.int64]
    landmarks: NDArray[np.float64]
    inbox_counts: NDArray[np.int64]
    deadline: float
    heading: NDArray[np.float64] | None = None
    formation: str | None = None


class Fish:
    """Fish actors. ``await fish.run(bus)`` serves until cancelled."""

    def __init__(self, settings: FishSettings) -> None:
        self.settings = settings
        self._settings_digest = settings_digest(settings.params)
        """What the fish tell the world their settings are (30–40 µs to compute, so once)."""
        self._settings_parts = settings_parts(settings.params)
        """The same, parameter by parameter (so that the world can name those that differ)."""
        ids = np.array(settings.fish_ids, dtype=np.int64)
        count = ids.size
        self._ids = ids
        self._order = np.argsort(ids)
        self._sorted_ids = ids[self._order]
        self._all_rows = np.arange(count)
        self._intake = Intake(f"fish {fish_span(settings.fish_ids)}")
        self._params = settings.params
        """What the fish do now (an operator may switch their formation)."""
        self._memory = FishMemory.fresh(settings.params, count)
        self._run = np.full(count, -1, dtype=np.int64)
        self._latest_run = -1
        self._ended_runs: collections.deque[int] = collections.deque(maxlen=ENDED_RUNS_KEPT)
        """Runs whose world said they ended, latest last: their late perceptions are stale."""
        self._unannounced: list[tuple[Rows, int]] = []
        """Fish that started a run and have not yet said what they run."""
        self._last_tick = np.full(count, -1, dtype=np.int64)
        self._last_seen = np.zeros(count)
        self._stopped = np.zeros(count, dtype=np.bool_)
        self._watched = np.zeros(count, dtype=np.bool_)
        """Fish the watchdog watches: from their first perception until their run ends."""
        self._busy = np.zeros(count, dtype=np.bool_)
        self._pending: list[_Pending] = []
        self._mail: dict[int, list[Delivery]] = {n: [] for n in range(count)}
        self._counts = dict.fromkeys(
            (
                "perceptions",
                "commands",
                "broadcasts",
                "deliveries",
                "watchdog_stops",
                "deliveries_missed",
                "batches",
                "runs",
            ),
            0,
        )
        self._resumed = trio.Event()

    def statistics(self) -> FishStatistics:
        """The actor's counters so far."""
        return FishStatistics(rejected=self._intake.rejected_total, **self._counts)

    async def run(
        self, bus: Bus, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED
    ) -> None:
        """Serve perceptions until cancelled; report readiness once every fish is subscribed
        and alive."""
        keys, school = self.settings.keys, self.settings.school
        events: Inbox[Event] = Inbox()
        async with contextlib.AsyncExitStack() as stack:
            # Subscribe before declaring the tokens: whoever sees a fish alive can reach it.
            subscriptions: list[tuple[str, Callable[[str, bytes], None]]] = []
            if school is None:
                for index, fish_id in enumerate(self.settings.fish_ids):
                    subscriptions += [
                        (keys.inbox(fish_id), _pusher(events, index, DELIVERY)),
                        (keys.perception(fish_id), _pusher(events, index, PERCEPTION)),
                    ]
            else:
                # One subscription for the whole school's inboxes: a Zenoh session declares
                # thousands of subscribers in a time that grows with their square (5 000:
                # 12 s), so a school takes every fish's deliveries and keeps its own. The
                # price: each delivery reaches every school (traffic × schools), and only
                # behaviours that broadcast (formation flags) have any.
                subscriptions += [
                    (
                        keys.fish_inboxes(),
                        _school_inbox_pusher(events, keys, self.settings.fish_ids),
                    ),
                    (keys.school_perceptions(school), _pusher(events, -1, BATCH)),
                ]
            subscriptions.append((keys.world_pulse, _pusher(events, -1, PULSE)))
            for key, push in subscriptions:
                await stack.enter_async_context(open_subscriber(bus, key, push))
            for fish_id in self.settings.fish_ids:
                await stack.enter_async_context(
                    open_token(bus, keys.alive("fish", fish_id, school))
                )
            # Say who the fish are on their own keys (which a secured router lets only them
            # put), now and whenever a world comes up: a secured world admits only fish
            # vouched for so, not whoever shows a liveliness token.
            self._hello(bus)
            await stack.enter_async_context(
                open_alive_events(
                    bus,
                    keys.alive_all("world"),
                    lambda key, alive: events.push((-1, WORLD, key, b"")) if alive else None,
                )
            )
            nursery = await stack.enter_async_context(trio.open_nursery())
            self._last_seen[:] = trio.current_time()
            nursery.start_soon(self._watchdog, bus)
            task_status.started()
            while True:
                batch: list[Event] = []
                with trio.move_on_at(self._next_deadline()):
                    batch.append(await events.receive())
                # Let the tasks woken with this fish go first: in the launcher's process the
                # observer then hands a large school's metrics to its thread, which runs
                # beside this decision instead of beside the world's next physics.
                await trio.lowlevel.checkpoint()
                batch += events.drain()
                for index, kind, key, payload in batch:
                    if kind == PERCEPTION:
                        self._take_perception(index, key, payload)
                    elif kind == BATCH:
                        self._take_batch(key, payload)
                    elif kind == PULSE:
                        self._take_pulse(key, payload)
                    elif kind == WORLD:
                        self._hello(bus)
                    else:
                        self._take_delivery(index, key, payload)
                self._announce(bus)
                self._decide(bus)

    def _take_perception(self, index: int, key: str, payload: bytes) -> None:
        perception = self._intake.decode_addressed(
            key, payload, PerceptionMessage, field="fish_id", owner=self.settings.fish_ids[index]
        )
        if perception is None:
            return
        pending = _Pending(
            np.array([index], dtype=np.intp),
            perception.tick,
            perception.time,
            np.array([perception.depth]),
            np.array([perception.neighbors.shape[0]], dtype=np.int64),
            perception.neighbors,
            np.array([perception.landmarks.shape[0]], dtype=np.int64),
            perception.landmarks,
            np.array([perception.inbox_count], dtype=np.int64),
            trio.current_time() + self.settings.inbox_timeout,
            None if perception.heading is None else np.array([perception.heading]),
            perception.formation,
        )
        self._admit(key, pending, perception.run)

    def _take_batch(self, key: str, payload: bytes) -> None:
        batch = self._intake.decode(key, payload, PerceptionBatch)
        if batch is None:
            return
        places = np.searchsorted(self._sorted_ids, batch.ids)
        places[places >= self._sorted_ids.size] = 0
        if self._sorted_ids.size == 0 or not np.array_equal(self._sorted_ids[places], batch.ids):
            self._intake.refuse(key, "misaddressed", f"fish {batch.ids.tolist()} not all ours")
            return
        pending = _Pending(
            self._order[places].astype(np.intp),
            batch.tick,
            batch.time,
            batch.depth,
            batch.neighbor_counts,
            batch.neighbors,
            batch.landmark_counts,
            batch.landmarks,
            batch.inbox_counts,
            trio.current_time() + self.settings.inbox_timeout,
            batch.heading,
            batch.formation,
        )
        self._admit(key, pending, batch.run)

    def _take_pulse(self, key: str, payload: bytes) -> None:
        """The world of the fish's run is alive: their next perceptions will come, so their
        watchdog waits afresh (stopped fish stay stopped until a perception comes)."""
        pulse = self._intake.decode(key, payload, WorldPulse)
        if pulse is None:
            return
        ours = self._run == pulse.run
        if pulse.state == "ended":
            self._watched[ours] = False
            if pulse.run not in self._ended_runs:
                self._ended_runs.append(pulse.run)
                self._drop_mail_of(pulse.run)
        else:
            self._last_seen[ours & self._watched & ~self._stopped] = trio.current_time()

    def _admit(self, key: str, pending: _Pending, run: int) -> None:
        rows = pending.rows
        if run in self._ended_runs:
            # A perception of a run that has ended, come late (two worlds overlapping, or a
            # slow link): starting that run again would drop the current run's work.
            self._intake.refuse(key, "stale", f"run {run} has ended")
            return
        fresh = rows[self._run[rows] != run]
        if fresh.size:
            self._start_run(fresh, run, pending.tick)
        if (self._last_tick[rows] >= pending.tick).any():
            self._intake.refuse(key, "stale", f"tick {pending.tick} repeated or out of order")
            return
        if self._busy[rows].any():
            self._intake.refuse(
                key, "stale", f"tick {pending.tick} came while an earlier tick waits for its mail"
            )
            return
        self._counts["perceptions"] += rows.size
        self._last_seen[rows] = trio.current_time()
        self._stopped[rows] = False
        self._watched[rows] = True
        self._resumed.set()  # wakes the watchdog: these fish are watched (again)
        self._busy[rows] = True
        self._pending.append(pending)

    def _start_run(self, rows: Rows, run: int, tick: int) -> None:
        """These fish start a new run of the world at ``tick``: memory fresh."""
        if run != self._latest_run:
            if self._latest_run >= 0:
                self._counts["runs"] += 1
                log.info("fish %s: a new run (%d) starts", fish_span(self._ids[rows].tolist()), run)
            self._latest_run = run
        # Joining a run under way, a fish hears its first tick's deliveries before the world
        # (which waits for the channel's report) sends it that tick: it keeps the mail of
        # its new run from this tick on, and drops the rest (an earlier run's; another
        # run's, heard while another process spoke for its id). Mail that names no run
        # (from an older channel) is kept for this tick and the next, by a fish in its
        # first run only.
        first = set(rows[self._run[rows] < 0].tolist())
        self._run[rows] = run
        self._unannounced.append((rows, run))
        self._last_tick[rows] = -1
        # Perceptions of the old run waiting for deliveries are dropped whole: every fish in
        # them is free to take the next perception.
        dropped = [p for p in self._pending if np.isin(p.rows, rows).any()]
        for pending in dropped:
            self._busy[pending.rows] = False
        self._pending = [p for p in self._pending if not np.isin(p.rows, rows).any()]
        for row in rows.tolist():
            unnamed = row in first and self._mail[row]
            self._mail[row] = [
                d
                for d in self._mail[row]
                if (d.run == run and d.tick >= tick)
                or (unnamed and d.run is None and tick <= d.tick <= tick + 1)
            ]
        self._params = self.settings.params  # a new run starts as configured
        fresh = FishMemory.fresh(self._params, rows.size)
        self._memory = put_rows(self._memory, rows, fresh)

    def _hello(self, bus: Bus) -> None:
        """Vouch for the fish on their own about keys (run 0: before any run)."""
        groups = (
            [self._sorted_ids] if self.settings.school is not None else self._sorted_ids[:, None]
        )
        for ids in groups:
            self._say_about(bus, ids, 0)

    def _announce(self, bus: Bus) -> None:
        """Tell the world what the fish that started a run run (behaviour, version, rules,
        control period), so that it can warn when that is not what its scenario says."""
        for rows, run in self._unannounced:
            self._say_about(bus, np.sort(self._ids[rows]), run)
        self._unannounced = []

    def _say_about(self, bus: Bus, ids: NDArray[np.int64], run: int) -> None:
        """Put what fish ``ids`` (ascending) run, for ``run``, on their about key."""
        params = self.settings.params
        about = FishAbout(
            np.asarray(ids, dtype=np.int64), params.behavior.name, __version__, run,
            rules_of(params), params.control_period, self._settings_digest, self._settings_parts,
        )  # fmt: skip
        bus.put(self.settings.keys.about(int(ids[0]), self.settings.school), encode(about))

    def _take_delivery(self, index: int, key: str, payload: bytes) -> None:
        delivery = self._intake.decode_addressed(
            key, payload, Delivery, field="receiver_id", owner=self.settings.fish_ids[index]
        )
        if delivery is None:
            return
        if delivery.run is not None and delivery.run in self._ended_runs:
            # Ordinary: the channel delivers a run's last tick after its world has ended it.
            self._intake.disregard()
            return
        last = int(self._last_tick[index])
        # Mail of another run (the fish's next, come before its first perception) is kept
        # until that run starts for the fish or ends.
        if _of_run(delivery, int(self._run[index])) and delivery.tick <= last:
            self._intake.refuse(key, "stale", f"delivery for tick {delivery.tick} after {last}")
            return
        # Deliveries wait for their perception; a fish that gets many more than any tick
        # could bring is being flooded: the excess is dropped, not kept.
        if len(self._mail[index]) >= MAX_WAITING_DELIVERIES:
            self._intake.refuse(key, "flood", f"more than {MAX_WAITING_DELIVERIES} waiting")
            return
        self._mail[index].append(delivery)

    def _next_deadline(self) -> float:
        return min((pending.deadline for pending in self._pending), default=float("inf"))

    def _complete(self, pending: _Pending, now: float) -> list[list[Delivery]] | None:
        """The deliveries of the pending fish if all have arrived (or waited long enough),
        else None; an empty list when none was announced to any of them."""
        rows, tick = pending.rows.tolist(), pending.tick
        if not pending.inbox_counts.any():
            if any(self._mail.values()):  # nothing announced: what waits for this tick is stale
                for row in rows:
                    if self._mail[row]:
                        self._mail[row] = self._mail_after(row, tick)
            return []
        wanted = pending.inbox_counts.tolist()
        runs = self._run.tolist()
        mail = [
            [d for d in self._mail[row] if d.tick == tick and _of_run(d, runs[row])] for row in rows
        ]
        if now < pending.deadline and any(len(m) < w for m, w in zip(mail, wanted, strict=True)):
            return None
        for row, fish_mail, count in zip(rows, mail, wanted, strict=True):
            self._counts["deliveries_missed"] += max(0, count - len(fish_mail))
            self._mail[row] = self._mail_after(row, tick)
        return [fish_mail[:count] for fish_mail, count in zip(mail, wanted, strict=True)]

    def _mail_after(self, row: int, tick: int) -> list[Delivery]:
        """The mail of fish ``row`` that is still to come once it has decided ``tick``: of
        later ticks of its run, and of another run (which may start for it next)."""
        run = int(self._run[row])
        return [d for d in self._mail[row] if d.tick > tick or not _of_run(d, run)]

    def _drop_mail_of(self, run: int) -> None:
        """Let go the mail of a run that has ended."""
        for row, mail in self._mail.items():
            if any(d.run == run for d in mail):
                self._mail[row] = [d for d in mail if d.run != run]

    def _decide(self, bus: Bus) -> None:
        """Decide for every fish whose perception is complete (or whose deliveries timed
        out), in one batched call."""
        if not self._pending:
            return
        now = trio.current_time()
        ready: list[_Pending] = []
        mail: list[list[list[Delivery]]] = []
        waiting: list[_Pending] = []
        for pending in self._pending:
            delivered = self._complete(pending, now)
            if delivered is None:
                waiting.append(pending)
            else:
                ready.append(pending)
                mail.append(delivered)
        if not ready:
            return
        self._pending = waiting
        directive = next((p.formation for p in ready if p.formation is not None), None)
        switched, self._memory = apply_directive(self._params, self._memory, directive)
        if switched is not self._params:
            log.info("fish %s switch to formation %s", fish_span(self.settings.fish_ids), directive)
            self._params = switched
        rows = np.concatenate([p.rows for p in ready]) if len(ready) > 1 else ready[0].rows
        whole = rows.size == self._ids.size and bool((rows == self._all_rows).all())
        memory = self._memory if whole else take_rows(self._memory, rows)
        memory, decision = decide(
            memory, _perception(ready), _inbox(ready, mail), params=self._params
        )
        self._memory = memory if whole else put_rows(self._memory, rows, memory)
        self._counts["batches"] += 1
        self._counts["deliveries"] += sum(len(m) for part in mail for m in part)
        start = 0
        for pending in ready:
            end = start + pending.rows.size
            part = decision if len(ready) == 1 else take_rows(decision, np.arange(start, end))
            self._broadcast(bus, pending.rows, pending.tick, part)
            self._send(bus, pending.rows, pending.tick, part)
            self._last_tick[pending.rows] = pending.tick
            self._busy[pending.rows] = False
            start = end

    async def _watchdog(self, bus: Bus) -> None:
        """Turn a fish's fins off when its perceptions stop for ``perception_timeout``."""
        timeout = self.settings.perception_timeout
        while True:
            # A fish is watched from its first perception on (before it, its fins never ran)
            # until the world says its run has ended.
            running = self._watched & ~self._stopped
            if not running.any():
                self._resumed = trio.Event()
                await self._resumed.wait()
                continue
            due = float(self._last_seen[running].min()) + timeout
            await trio.sleep_until(due)
            running = self._watched & ~self._stopped  # a run may have ended meanwhile
            late = np.flatnonzero(running & (self._last_seen + timeout <= trio.current_time()))
            if late.size == 0:
                continue
            log.warning(
                "%s: no perception for %.1f s, fins off until one comes",
                _many(sorted(self._ids[late].tolist())),
                timeout,
            )
            self._stopped[late] = True
            self._counts["watchdog_stops"] += late.size
            # The last tick is repeated so that a driver acts on it at once.
            tick = int(max(self._last_tick[late].max(), 0))
            count = late.size
            stop = Decision(stop_fins(count), np.zeros(count, dtype=np.bool_), Outbox.silent(count))
            self._send(bus, late, tick, stop, watchdog=True)

    def _broadcast(self, bus: Bus, rows: Rows, tick: int, decision: Decision) -> None:
        """Each broadcasting fish's broadcast, on its own outbox key."""
        outbox = decision.outbox
        for row in np.flatnonzero(outbox.mask).tolist():
            fish_id = self.settings.fish_ids[int(rows[row])]
            message = Broadcast(
                fish_id, tick, BROADCAST_KINDS[int(outbox.kind[row])], outbox.values[row],
                int(self._run[int(rows[row])]),
            )  # fmt: skip
            bus.put(self.settings.keys.outbox(fish_id), encode(message))
            self._counts["broadcasts"] += 1

    def _send(
        self, bus: Bus, rows: Rows, tick: int, decision: Decision, *, watchdog: bool = False
    ) -> None:
        """Commands of the fish at ``rows`` for ``tick``: one batch for a school, or one
        command per fish on its own key (``watchdog``: the watchdog's stop, which a
        robot's driver reports as such)."""
        keys, school = self.settings.keys, self.settings.school
        self._counts["commands"] += rows.size
        broadcasts = decision.outbox.mask.astype(np.int64)
        if school is not None:
            order = np.argsort(self._ids[rows])
            batch = CommandBatch(
                tick,
                self._ids[rows][order],
                decision.fins[order],
                decision.led[order],
                broadcasts[order],
                watchdog=True if watchdog else None,
            )
            bus.put(keys.school_commands(school), encode(batch, reuse=True))
            return
        for n, row in enumerate(rows.tolist()):
            fish_id = self.settings.fish_ids[row]
            command = Command(
                fish_id,
                tick,
                decision.fins[n],
                led=bool(decision.led[n]),
                broadcasts=int(broadcasts[n]),
                watchdog=True if watchdog else None,
            )
            bus.put(keys.command(fish_id), encode(command, reuse=True))


def _of_run(delivery: Delivery, run: int) -> bool:
    """Whether ``delivery`` is mail of ``run`` (or names no run: an older channel's)."""
    return delivery.run is None or delivery.run == run


def _inbox(ready: list[_Pending], mail: list[list[list[Delivery]]]) -> HeardInbox:
    """What the ready fish heard (each part's mail, an empty list: nothing), as one inbox."""
    count = sum(pending.rows.size for pending in ready)
    if not any(mail):
        return HeardInbox.empty(count)
    heard: list[list[Heard]] = []
    for pending, part in zip(ready, mail, strict=True):
        if not part:
            heard += [[] for _ in range(pending.rows.size)]
            continue
        heard += [
            [(BROADCAST_KINDS.index(d.kind), d.values, d.sender_position) for d in fish_mail]
            for fish_mail in part
        ]
    return inbox_of(heard)


def _perception(ready: list[_Pending]) -> Perception:
    """The pending perceptions as one batch for the fish core, rows in order."""
    if len(ready) == 1:  # one fish (a robot) or one school: nothing to stack
        first = ready[0]
        neighbors, mask = pad_rows(first.neighbor_counts, first.neighbors)
        landmarks, landmark_mask = pad_rows(first.landmark_counts, first.landmarks)
        return Perception(
            np.full(first.rows.size, first.time),
            first.depth,
            neighbors,
            mask,
            landmarks,
            landmark_mask,
            first.heading,
        )
    neighbors, mask = pad_rows(
        np.concatenate([p.neighbor_counts for p in ready]),
        np.concatenate([p.neighbors for p in ready]),
    )
    landmarks, landmark_mask = pad_rows(
        np.concatenate([p.landmark_counts for p in ready]),
        np.concatenate([p.landmarks for p in ready]),
    )
    headings = [np.full(p.rows.size, np.nan) if p.heading is None else p.heading for p in ready]
    known = any(p.heading is not None for p in ready)
    return Perception(
        np.concatenate([np.full(p.rows.size, p.time) for p in ready]),
        np.concatenate([p.depth for p in ready]),
        neighbors,
        mask,
        landmarks,
        landmark_mask,
        np.concatenate(headings) if known else None,
    )


def _school_inbox_pusher(
    events: Inbox[Event], keys: KeySpace, fish_ids: Sequence[int]
) -> Callable[[str, bytes], None]:
    """Deliveries to a school's fish, from the swarm's inbox keys; others' are let go (they
    are another school's, not bad input)."""
    index_of = {str(fish_id): index for index, fish_id in enumerate(fish_ids)}

    def push(key: str, payload: bytes) -> None:
        try:
            fish_id, _ = keys.member_of(key)
        except ValueError:
            return
        index = index_of.get(fish_id)
        if index is not None:
            events.push((index, DELIVERY, key, payload))

    return push


def _pusher(events: Inbox[Event], index: int, kind: str) -> Callable[[str, bytes], None]:
    def push(key: str, payload: bytes) -> None:
        events.push((index, kind, key, payload))

    return push


def fish_span(ids: list[int] | tuple[int, ...]) -> str:
    """``4`` for one fish, ``0–24`` for several (ascending ids): as messages name them."""
    return str(ids[0]) if len(ids) == 1 else f"{ids[0]}–{ids[-1]}"


def _many(ids: list[int]) -> str:
    """``fish 4`` or ``12 fish (0, 1, 2 …)``: one line for however many fish (the robot
    does not import the study's text helpers)."""
    if len(ids) == 1:
        return f"fish {ids[0]}"
    shown = ", ".join(map(str, ids[:10])) + (" …" if len(ids) > 10 else "")
    return f"{len(ids)} fish ({shown})"
