"""The fish actor: perception in → policy → command out, and fins off when perceptions stop.

The same actor runs in simulation (the world sends perceptions) and on a BlueBot (the
driver does). It knows nothing of clocks or physics; it owns only its fish's memory, their
safety watchdog and their messages.

One actor serves one or more fish on one session: on a robot a single fish, in a worker
process many. Each fish keeps its own liveliness token, memory, inbox and watchdog; what
the fish share is the work. Perceptions that arrive together are decided in one batched
call of the policy — the same pure function, with the same result bit for bit as one call
per fish (tested).

Perceptions and commands travel either on each fish's own keys (``fish/<id>/perception``
and ``fish/<id>/command``: what a robot does) or, for a *school*, as one
:class:`~fishswarm.protocols.messages.PerceptionBatch` and one
:class:`~fishswarm.protocols.messages.CommandBatch` per tick on the school's keys, which
spares Python's per-message cost once per fish.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trio
import zenoh
from numpy.typing import NDArray

from fishswarm.actors.bridge import Inbox, Put, open_subscriber, open_token, publisher
from fishswarm.actors.intake import Intake
from fishswarm.behaviors.policy import Memory, Policy, act, pad_neighbors
from fishswarm.bluebot.control import stop_fins
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import (
    Command,
    CommandBatch,
    Delivery,
    Perception,
    PerceptionBatch,
)

log = logging.getLogger(__name__)

Rows = NDArray[np.intp]

PERCEPTION, BATCH, DELIVERY = "perception", "batch", "delivery"

Event = tuple[int, str, str, bytes]
"""(fish index or −1 for a school batch, kind, key, payload)."""


@dataclass(frozen=True)
class FishSettings:
    """How a fish actor behaves.

    Attributes:
        fish_ids: the fish it serves (one on a robot).
        policy: what they do.
        keys: the swarm's key space.
        perception_timeout: a fish with no perception for this long turns its fins off, s.
        inbox_timeout: longest wait for the deliveries a perception announces, s.
        school: serve the fish through this school's batched keys; None: each fish on its
            own keys.
    """

    fish_ids: tuple[int, ...]
    policy: Policy
    keys: KeySpace = KeySpace()
    perception_timeout: float = 5.0
    inbox_timeout: float = 5.0
    school: str | None = None

    def __post_init__(self) -> None:
        if not self.fish_ids or len(set(self.fish_ids)) != len(self.fish_ids):
            raise ValueError(f"fish_ids must be distinct and not empty, got {self.fish_ids}")
        if self.perception_timeout <= 0 or self.inbox_timeout <= 0:
            raise ValueError("perception_timeout and inbox_timeout must be positive")
        if self.school is not None:
            self.keys.school_commands(self.school)  # checks the name


@dataclass(eq=False)
class _Pending:
    """Perceptions of some fish at one tick, waiting for the deliveries they announce.

    Attributes:
        rows: (G,) indices of the fish in the actor's ``fish_ids``.
        tick: the tick.
        depth: (G,) m.
        neighbor_counts: (G,) visible neighbours per fish.
        neighbors: (ΣK, 3) their body-frame positions, m, fish by fish.
        landmark_counts: (G,) visible landmarks per fish.
        landmarks: (ΣL, 3) their body-frame positions, m, fish by fish.
        inbox_counts: (G,) deliveries each fish waits for.
        deadline: when to stop waiting for deliveries (trio time).
    """

    rows: Rows
    tick: int
    depth: NDArray[np.float64]
    neighbor_counts: NDArray[np.int64]
    neighbors: NDArray[np.float64]
    landmark_counts: NDArray[np.int64]
    landmarks: NDArray[np.float64]
    inbox_counts: NDArray[np.int64]
    deadline: float


@dataclass
class _Counters:
    perceptions: int = 0
    commands: int = 0
    watchdog_stops: int = 0
    deliveries_missed: int = 0
    batches: int = 0


class Fish:
    """Fish actors. ``await fish.run(session)`` serves until cancelled."""

    def __init__(self, settings: FishSettings) -> None:
        self.settings = settings
        ids = np.array(settings.fish_ids, dtype=np.int64)
        count = ids.size
        self._ids = ids
        self._order = np.argsort(ids)
        self._sorted_ids = ids[self._order]
        self._all_rows = np.arange(count)
        self._intake = Intake(f"fish {_span(settings.fish_ids)}")
        self._memory = Memory.fresh(count)
        self._last_tick = np.full(count, -1, dtype=np.int64)
        self._last_seen = np.zeros(count)
        self._stopped = np.zeros(count, dtype=np.bool_)
        self._busy = np.zeros(count, dtype=np.bool_)
        self._pending: list[_Pending] = []
        self._mail: dict[int, list[Delivery]] = {n: [] for n in range(count)}
        self._counters = _Counters()
        self._resumed = trio.Event()
        self.deliveries: dict[int, list[Delivery]] = {}
        """The deliveries each fish acted on at its last tick, by fish id."""

    def statistics(self) -> dict[str, int]:
        """Counters: perceptions accepted (per fish), commands sent (per fish), rejected
        messages, watchdog stops, deliveries announced but never received, and batched
        decisions made."""
        counters = self._counters
        return {
            "perceptions": counters.perceptions,
            "commands": counters.commands,
            "rejected": self._intake.rejected_total,
            "watchdog_stops": counters.watchdog_stops,
            "deliveries_missed": counters.deliveries_missed,
            "batches": counters.batches,
        }

    async def run(
        self,
        session: zenoh.Session,
        *,
        task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
    ) -> None:
        """Serve perceptions until cancelled; report readiness once every fish is subscribed
        and alive."""
        keys, school = self.settings.keys, self.settings.school
        events: Inbox[Event] = Inbox()
        put = publisher(session)
        async with contextlib.AsyncExitStack() as stack:
            # Subscribe before declaring the tokens: whoever sees a fish alive can reach it.
            subscriptions = [
                (index, DELIVERY, keys.inbox(fish_id))
                for index, fish_id in enumerate(self.settings.fish_ids)
            ]
            if school is None:
                subscriptions += [
                    (index, PERCEPTION, keys.perception(fish_id))
                    for index, fish_id in enumerate(self.settings.fish_ids)
                ]
            else:
                subscriptions.append((-1, BATCH, keys.school_perceptions(school)))
            for index, kind, key in subscriptions:
                await stack.enter_async_context(
                    open_subscriber(session, key, _pusher(events, index, kind), exact=True)
                )
            for fish_id in self.settings.fish_ids:
                await stack.enter_async_context(
                    open_token(session, keys.alive("fish", fish_id, school))
                )
            nursery = await stack.enter_async_context(trio.open_nursery())
            self._last_seen[:] = trio.current_time()
            nursery.start_soon(self._watchdog, put)
            task_status.started()
            while True:
                event = None
                with trio.move_on_at(self._next_deadline()):
                    event = await events.receive()
                batch = [] if event is None else [event]
                while (more := events.receive_nowait()) is not None:
                    batch.append(more)
                for index, kind, key, payload in batch:
                    if kind == PERCEPTION:
                        self._take_perception(index, key, payload)
                    elif kind == BATCH:
                        self._take_batch(key, payload)
                    else:
                        self._take_delivery(index, key, payload)
                self._decide(put)

    def _take_perception(self, index: int, key: str, payload: bytes) -> None:
        perception = self._intake.decode_addressed(
            key, payload, Perception, field="fish_id", owner=self.settings.fish_ids[index]
        )
        if perception is None:
            return
        rows = np.array([index], dtype=np.intp)
        pending = _Pending(
            rows,
            perception.tick,
            np.array([perception.depth]),
            np.array([perception.neighbors.shape[0]], dtype=np.int64),
            perception.neighbors,
            np.array([perception.landmarks.shape[0]], dtype=np.int64),
            perception.landmarks,
            np.array([perception.inbox_count], dtype=np.int64),
            trio.current_time() + self.settings.inbox_timeout,
        )
        self._admit(key, pending)

    def _take_batch(self, key: str, payload: bytes) -> None:
        batch = self._intake.decode(key, payload, PerceptionBatch)
        if batch is None:
            return
        places = np.searchsorted(self._sorted_ids, batch.ids)
        places[places >= self._sorted_ids.size] = 0
        if self._sorted_ids.size == 0 or not np.array_equal(self._sorted_ids[places], batch.ids):
            self._intake.reject(key, "misaddressed", f"fish {batch.ids.tolist()} not all ours")
            return
        pending = _Pending(
            self._order[places].astype(np.intp),
            batch.tick,
            batch.depth,
            batch.neighbor_counts,
            batch.neighbors,
            batch.landmark_counts,
            batch.landmarks,
            batch.inbox_counts,
            trio.current_time() + self.settings.inbox_timeout,
        )
        self._admit(key, pending)

    def _admit(self, key: str, pending: _Pending) -> None:
        rows = pending.rows
        if (self._last_tick[rows] >= pending.tick).any() or self._busy[rows].any():
            self._intake.reject(key, "stale", f"tick {pending.tick} repeated or out of order")
            return
        self._counters.perceptions += rows.size
        self._last_seen[rows] = trio.current_time()
        if self._stopped[rows].any():
            self._stopped[rows] = False
            self._resumed.set()
        self._busy[rows] = True
        self._pending.append(pending)

    def _take_delivery(self, index: int, key: str, payload: bytes) -> None:
        delivery = self._intake.decode_addressed(
            key, payload, Delivery, field="receiver_id", owner=self.settings.fish_ids[index]
        )
        if delivery is not None and delivery.tick > self._last_tick[index]:
            self._mail[index].append(delivery)

    def _next_deadline(self) -> float:
        return min((pending.deadline for pending in self._pending), default=float("inf"))

    def _complete(self, pending: _Pending, now: float) -> bool:
        """Whether the pending perceptions have their deliveries (or waited long enough);
        if so, hand the deliveries to their fish."""
        wanted = pending.inbox_counts.tolist()
        if not any(wanted):
            return True
        rows, tick = pending.rows.tolist(), pending.tick
        mail = [[d for d in self._mail[row] if d.tick == tick] for row in rows]
        if now < pending.deadline and any(len(m) < w for m, w in zip(mail, wanted, strict=True)):
            return False
        for row, fish_mail, count in zip(rows, mail, wanted, strict=True):
            self._counters.deliveries_missed += max(0, count - len(fish_mail))
            self.deliveries[self.settings.fish_ids[row]] = fish_mail[:count]
            self._mail[row] = [d for d in self._mail[row] if d.tick > tick]
        return True

    def _decide(self, put: Put) -> None:
        """Act for every fish whose perception is complete (or whose deliveries timed out)."""
        if not self._pending:
            return
        now = trio.current_time()
        ready = [pending for pending in self._pending if self._complete(pending, now)]
        if not ready:
            return
        self._pending = [pending for pending in self._pending if pending not in ready]
        # One fish's perception (a robot) is decided as it is; several are stacked first.
        merged = ready[0] if len(ready) == 1 else _merge(ready)
        rows, depth = merged.rows, merged.depth
        neighbors, mask = pad_neighbors(merged.neighbor_counts, merged.neighbors)
        landmarks, landmark_mask = pad_neighbors(merged.landmark_counts, merged.landmarks)
        whole = rows.size == self._ids.size and bool((rows == self._all_rows).all())
        memory = self._memory if whole else self._memory.take(rows)
        fins, memory = act(
            self.settings.policy, neighbors, mask, depth, memory, landmarks, landmark_mask
        )
        self._memory = memory if whole else self._memory.replaced(rows, memory)
        self._counters.batches += 1
        start = 0
        for pending in ready:
            end = start + pending.rows.size
            self._send(put, pending.rows, pending.tick, fins[start:end], led=True)
            self._last_tick[pending.rows] = pending.tick
            self._busy[pending.rows] = False
            start = end

    async def _watchdog(self, put: Put) -> None:
        """Turn a fish's fins off when its perceptions stop for ``perception_timeout``."""
        timeout = self.settings.perception_timeout
        while True:
            running = ~self._stopped
            if not running.any():
                self._resumed = trio.Event()
                await self._resumed.wait()
                continue
            due = float(self._last_seen[running].min()) + timeout
            await trio.sleep_until(due)
            late = np.flatnonzero(running & (self._last_seen + timeout <= trio.current_time()))
            if late.size == 0:
                continue
            for index in late.tolist():
                log.warning(
                    "fish %d: no perception for %.1f s, fins off",
                    self.settings.fish_ids[index],
                    timeout,
                )
            self._stopped[late] = True
            self._counters.watchdog_stops += late.size
            # The last tick is repeated so that a driver acts on it at once.
            tick = int(max(self._last_tick[late].max(), 0))
            self._send(put, late, tick, stop_fins(late.size), led=False)

    def _send(self, put: Put, rows: Rows, tick: int, fins: np.ndarray, *, led: bool) -> None:
        """Commands of the fish at ``rows`` for ``tick``: one batch for a school, or one
        command per fish on its own key."""
        keys, school = self.settings.keys, self.settings.school
        self._counters.commands += rows.size
        if school is not None:
            order = np.argsort(self._ids[rows])
            batch = CommandBatch(
                tick,
                self._ids[rows][order],
                fins[order],
                np.full(rows.size, led),
                np.zeros(rows.size, dtype=np.int64),
            )
            put(keys.school_commands(school), encode(batch))
            return
        for row, gains in zip(rows.tolist(), fins, strict=True):
            fish_id = self.settings.fish_ids[row]
            put(keys.command(fish_id), encode(Command(fish_id, tick, gains, led=led)))


def _merge(ready: list[_Pending]) -> _Pending:
    """Several pending perceptions stacked into one, rows in order (tick and deadline of the
    first: only the arrays are decided on)."""
    first = ready[0]
    return _Pending(
        np.concatenate([p.rows for p in ready]),
        first.tick,
        np.concatenate([p.depth for p in ready]),
        np.concatenate([p.neighbor_counts for p in ready]),
        np.concatenate([p.neighbors for p in ready]),
        np.concatenate([p.landmark_counts for p in ready]),
        np.concatenate([p.landmarks for p in ready]),
        np.concatenate([p.inbox_counts for p in ready]),
        first.deadline,
    )


def _pusher(events: Inbox[Event], index: int, kind: str) -> Callable[[str, bytes], None]:
    def push(key: str, payload: bytes) -> None:
        events.push((index, kind, key, payload))

    return push


def _span(ids: tuple[int, ...]) -> str:
    return str(ids[0]) if len(ids) == 1 else f"{ids[0]}–{ids[-1]}"
