"""The fish actor: perception in → policy → command out, and fins off when perceptions stop.

The same actor runs in simulation (the world sends perceptions) and on a BlueBot (the
driver does). It knows nothing of clocks or physics; it owns only its memory, its safety
watchdog and its messages.
"""

from __future__ import annotations

import logging
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


@dataclass(frozen=True)
class FishSettings:
    """How one fish actor behaves.

    Attributes:
        fish_id: the fish's id.
        policy: what it does.
        keys: the swarm's key space.
        perception_timeout: with no perception for this long, the fins go off, s.
        inbox_timeout: longest wait for the deliveries a perception announces, s.
    """

    fish_id: int
    policy: Policy
    keys: KeySpace = KeySpace()
    perception_timeout: float = 5.0
    inbox_timeout: float = 5.0


class Fish:
    """One fish actor. ``await fish.run(session)`` serves until cancelled."""

    def __init__(self, settings: FishSettings) -> None:
        self.settings = settings
        self._intake = Intake(f"fish {settings.fish_id}")
        self._memory = Memory.fresh(1)
        self._last_tick = -1
        self._commands = 0
        self._watchdog_stops = 0
        self._deliveries_missed = 0
        self.deliveries: list[Delivery] = []
        self._last_seen = 0.0
        self._perceiving = trio.Event()

    def statistics(self) -> dict[str, int]:
        """Counters: perceptions accepted, commands sent, rejected messages, watchdog stops."""
        return {
            "perceptions": self._intake.accepted,
            "commands": self._commands,
            "rejected": self._intake.rejected_total,
            "watchdog_stops": self._watchdog_stops,
            "deliveries_missed": self._deliveries_missed,
        }

    async def run(
        self,
        session: zenoh.Session,
        *,
        task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
    ) -> None:
        """Serve perceptions until cancelled; report readiness once subscribed and alive."""
        keys, fish_id = self.settings.keys, self.settings.fish_id
        perceptions: Inbox[tuple[str, bytes]] = Inbox()
        inbox: Inbox[tuple[str, bytes]] = Inbox()
        put = publisher(session)
        # Subscribe before declaring the token: whoever sees us alive can reach us.
        async with (
            open_subscriber(
                session, keys.perception(fish_id), lambda k, p: perceptions.push((k, p)), exact=True
            ),
            open_subscriber(
                session, keys.inbox(fish_id), lambda k, p: inbox.push((k, p)), exact=True
            ),
            open_token(session, keys.alive("fish", fish_id)),
            trio.open_nursery() as nursery,
        ):
            self._last_seen = trio.current_time()
            nursery.start_soon(self._watchdog, put)
            task_status.started()
            async for key, payload in perceptions:
                perception = self._accept(key, payload)
                if perception is None:
                    continue
                self._last_seen = trio.current_time()
                self._perceiving.set()
                deliveries = (
                    await self._collect_deliveries(inbox, perception)
                    if perception.inbox_count
                    else []
                )
                self._respond(put, perception, deliveries)

    async def _watchdog(self, put: Put) -> None:
        """Turn the fins off when perceptions stop for ``perception_timeout`` (robot safety)."""
        timeout = self.settings.perception_timeout
        while True:
            await trio.sleep_until(self._last_seen + timeout)
            if trio.current_time() >= self._last_seen + timeout:
                self._stop_fins(put)
                self._perceiving = trio.Event()
                await self._perceiving.wait()

    def _accept(self, key: str, payload: bytes) -> Perception | None:
        perception = self._intake.decode(key, payload, Perception)
        if perception is None:
            return None
        if perception.fish_id != self.settings.fish_id:
            self._intake.reject(key, "misaddressed", f"perception for fish {perception.fish_id}")
            return None
        if perception.tick <= self._last_tick:
            self._intake.reject(key, "stale", f"tick {perception.tick} after {self._last_tick}")
            return None
        return perception

    async def _collect_deliveries(
        self, inbox: Inbox[tuple[str, bytes]], perception: Perception
    ) -> list[Delivery]:
        wanted, found = perception.inbox_count, list[Delivery]()
        with trio.move_on_after(self.settings.inbox_timeout):
            while len(found) < wanted:
                key, payload = await inbox.receive()
                delivery = self._intake.decode(key, payload, Delivery)
                if delivery is not None and delivery.tick == perception.tick:
                    found.append(delivery)
        self._deliveries_missed += wanted - len(found)
        return found

    def _respond(self, put: Put, perception: Perception, deliveries: list[Delivery]) -> None:
        neighbors = perception.neighbors[None, :, :]
        mask = np.ones((1, perception.neighbors.shape[0]), dtype=np.bool_)
        fins, self._memory = act(self.settings.policy, neighbors, mask, self._memory)
        self.deliveries = deliveries
        command = Command(self.settings.fish_id, perception.tick, fins[0], led=True, broadcasts=0)
        self._send(put, command)
        self._last_tick = perception.tick

    def _stop_fins(self, put: Put) -> None:
        log.warning(
            "fish %d: no perception for %.1f s, fins off",
            self.settings.fish_id,
            self.settings.perception_timeout,
        )
        self._watchdog_stops += 1
        tick = max(self._last_tick, 0)
        self._send(put, Command(self.settings.fish_id, tick, stop_fins(1)[0], led=False))

    def _send(self, put: Put, command: Command) -> None:
        put(self.settings.keys.command(self.settings.fish_id), encode(command))
        self._commands += 1
