"""The fish actor: perception in → policy → command out, and fins off when perceptions stop.

The same actor runs in simulation (the world sends perceptions) and on a BlueBot (the
driver does). It knows nothing of clocks or physics; it owns only its fish's memory, their
safety watchdog and their messages.

One actor serves one or more fish on one session: on a robot a single fish, in a worker
process many. Each fish keeps its own keys, liveliness token, memory and watchdog; what the
fish share is the work. Perceptions that arrive together are decided in one batched call of
the policy — the same pure function, with the same result bit for bit as one call per fish
(tested), but without paying Python's per-call overhead once per fish.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trio
import zenoh

from fishswarm.actors.bridge import Inbox, Put, open_subscriber, open_token, publisher
from fishswarm.actors.intake import Intake
from fishswarm.behaviors.policy import Memory, Policy, act
from fishswarm.bluebot.control import stop_fins
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import Command, Delivery, Perception

log = logging.getLogger(__name__)

Event = tuple[int, bool, str, bytes]
"""(fish index, is a perception, key, payload)."""


@dataclass(frozen=True)
class FishSettings:
    """How a fish actor behaves.

    Attributes:
        fish_ids: the fish it serves (one on a robot).
        policy: what they do.
        keys: the swarm's key space.
        perception_timeout: a fish with no perception for this long turns its fins off, s.
        inbox_timeout: longest wait for the deliveries a perception announces, s.
    """

    fish_ids: tuple[int, ...]
    policy: Policy
    keys: KeySpace = KeySpace()
    perception_timeout: float = 5.0
    inbox_timeout: float = 5.0

    def __post_init__(self) -> None:
        if not self.fish_ids or len(set(self.fish_ids)) != len(self.fish_ids):
            raise ValueError(f"fish_ids must be distinct and not empty, got {self.fish_ids}")
        if self.perception_timeout <= 0 or self.inbox_timeout <= 0:
            raise ValueError("perception_timeout and inbox_timeout must be positive")


@dataclass
class _Waiting:
    """A perception waiting for the deliveries it announces."""

    perception: Perception
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
        count = len(settings.fish_ids)
        self._intake = Intake(f"fish {_span(settings.fish_ids)}")
        self._memory = Memory.fresh(count)
        self._last_tick = np.full(count, -1, dtype=np.int64)
        self._last_seen = np.zeros(count)
        self._stopped = np.zeros(count, dtype=np.bool_)
        self._waiting: dict[int, _Waiting] = {}
        self._mail: dict[int, list[Delivery]] = {n: [] for n in range(count)}
        self._counters = _Counters()
        self._resumed = trio.Event()
        self.deliveries: dict[int, list[Delivery]] = {}
        """The deliveries each fish acted on at its last tick, by fish id."""

    def statistics(self) -> dict[str, int]:
        """Counters: perceptions accepted, commands sent, rejected messages, watchdog stops,
        deliveries announced but never received, and batched decisions made."""
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
        keys = self.settings.keys
        events: Inbox[Event] = Inbox()
        put = publisher(session)
        async with contextlib.AsyncExitStack() as stack:
            # Subscribe before declaring the tokens: whoever sees a fish alive can reach it.
            for index, fish_id in enumerate(self.settings.fish_ids):
                for is_perception, key in (
                    (True, keys.perception(fish_id)),
                    (False, keys.inbox(fish_id)),
                ):
                    await stack.enter_async_context(
                        open_subscriber(
                            session, key, _pusher(events, index, is_perception), exact=True
                        )
                    )
            for fish_id in self.settings.fish_ids:
                await stack.enter_async_context(open_token(session, keys.alive("fish", fish_id)))
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
                for index, is_perception, key, payload in batch:
                    if is_perception:
                        self._take_perception(index, key, payload)
                    else:
                        self._take_delivery(index, key, payload)
                self._decide(put)

    def _take_perception(self, index: int, key: str, payload: bytes) -> None:
        perception = self._intake.decode_addressed(
            key, payload, Perception, field="fish_id", owner=self.settings.fish_ids[index]
        )
        if perception is None:
            return
        if perception.tick <= self._last_tick[index] or index in self._waiting:
            self._intake.reject(key, "stale", f"tick {perception.tick} repeated or out of order")
            return
        self._counters.perceptions += 1
        self._last_seen[index] = trio.current_time()
        if self._stopped[index]:
            self._stopped[index] = False
            self._resumed.set()
        deadline = trio.current_time() + self.settings.inbox_timeout
        self._waiting[index] = _Waiting(perception, deadline)

    def _take_delivery(self, index: int, key: str, payload: bytes) -> None:
        delivery = self._intake.decode_addressed(
            key, payload, Delivery, field="receiver_id", owner=self.settings.fish_ids[index]
        )
        if delivery is not None and delivery.tick > self._last_tick[index]:
            self._mail[index].append(delivery)

    def _next_deadline(self) -> float:
        if not self._waiting:
            return float("inf")
        return min(waiting.deadline for waiting in self._waiting.values())

    def _decide(self, put: Put) -> None:
        """Act for every fish whose perception is complete (or whose deliveries timed out)."""
        now = trio.current_time()
        ready = []
        for index, waiting in sorted(self._waiting.items()):
            tick, wanted = waiting.perception.tick, waiting.perception.inbox_count
            mail = [d for d in self._mail[index] if d.tick == tick]
            if len(mail) >= wanted or now >= waiting.deadline:
                self._counters.deliveries_missed += max(0, wanted - len(mail))
                self.deliveries[self.settings.fish_ids[index]] = mail[:wanted]
                self._mail[index] = [d for d in self._mail[index] if d.tick > tick]
                ready.append(index)
        if not ready:
            return
        perceptions = [self._waiting.pop(index).perception for index in ready]
        width = max(p.neighbors.shape[0] for p in perceptions)
        neighbors = np.zeros((len(ready), width, 3))
        mask = np.zeros((len(ready), width), dtype=np.bool_)
        for row, perception in enumerate(perceptions):
            seen = perception.neighbors.shape[0]
            neighbors[row, :seen] = perception.neighbors
            mask[row, :seen] = True
        rows = np.array(ready, dtype=np.intp)
        depth = np.array([p.depth for p in perceptions])
        fins, memory = act(self.settings.policy, neighbors, mask, depth, self._memory.take(rows))
        self._memory = self._memory.replaced(rows, memory)
        self._counters.batches += 1
        for row, perception in enumerate(perceptions):
            self._send(put, Command(perception.fish_id, perception.tick, fins[row]))
            self._last_tick[ready[row]] = perception.tick

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
            late = running & (self._last_seen + timeout <= trio.current_time())
            for index in np.flatnonzero(late):
                fish_id = self.settings.fish_ids[index]
                log.warning("fish %d: no perception for %.1f s, fins off", fish_id, timeout)
                self._stopped[index] = True
                self._counters.watchdog_stops += 1
                tick = int(max(self._last_tick[index], 0))
                self._send(put, Command(fish_id, tick, stop_fins(1)[0], led=False))

    def _send(self, put: Put, command: Command) -> None:
        put(self.settings.keys.command(command.fish_id), encode(command))
        self._counters.commands += 1


def _pusher(events: Inbox[Event], index: int, is_perception: bool) -> Callable[[str, bytes], None]:
    def push(key: str, payload: bytes) -> None:
        events.push((index, is_perception, key, payload))

    return push


def _span(ids: tuple[int, ...]) -> str:
    return str(ids[0]) if len(ids) == 1 else f"{ids[0]}–{ids[-1]}"
