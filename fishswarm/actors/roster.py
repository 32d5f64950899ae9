"""Who is in the swarm, as the world sees it: live fish, their schools and command keys, the
channel, and the fish that joined late or were lost.

Membership comes from liveliness tokens. A fish that comes up gets a command subscription
(its own key, or its school's) and is admitted at the first event at least ``admit_delay``
after that subscription was declared (through a router, a subscription takes a moment to
reach the publishers). A fish whose token goes, or that misses a command deadline, is lost.
One token speaks for a fish at a time: another that comes up for a fish id already spoken
for (a second process given that id, or a restart before the old token went) waits as a
spare, and takes the fish over when the first goes or the fish is lost; the fish then
leaves the world and comes back at a later tick.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fishswarm.actors.bus import Declared
from fishswarm.actors.perceptions import Schools
from fishswarm.actors.tick_commands import among
from fishswarm.protocols.keys import KeySpace, fish_id_of

log = logging.getLogger(__name__)

TOKEN_GONE = "left (liveliness token gone)"
"""Why a fish whose token went is lost, unless its launcher says more."""


@dataclass(frozen=True)
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


class Roster:
    """The world's membership bookkeeping.

    Args:
        keys: the swarm's key space.
        subscribe_commands: declares a subscription to a command key (``kind`` is
            ``command`` for a fish's own key or ``batch`` for a school's).
    """

    def __init__(self, keys: KeySpace, subscribe_commands: Callable[[str, str], Declared]) -> None:
        self.keys = keys
        self.alive: set[int] = set()
        self.school_of: dict[int, str | None] = {}
        self.command_key: dict[int, str] = {}
        self.channels = 0
        self.worlds: set[str] = set()
        """Liveliness tokens of the worlds of the swarm up now (a world's own among them)."""
        self.robots: set[int] = set()
        """Robots of the swarm up now (their drivers' tokens ``alive/robot/<id>``)."""
        self.queue: dict[str, tuple[int, int]] = {}
        """Places of the worlds of the swarm waiting for their turn, by their token (a
        world's own among them): see :meth:`KeySpace.queue_place`."""
        self.lost: list[LostFish] = []
        self._loss_reasons: dict[int, str] = {}
        """Why fish whose process failed left, as their launcher said (:meth:`explain_loss`)."""
        self.joined: list[tuple[int, int]] = []
        self._subscribe = subscribe_commands
        self._subscriptions: dict[str, tuple[Declared, float]] = {}
        self._senders: dict[str, NDArray[np.int64]] = {}
        """Per command key, the fish whose commands come on it, ascending (built on demand)."""
        self._schools: tuple[NDArray[np.int64], Schools] | None = None
        """The last numbering of schools and the ids it numbers (until a school changes)."""
        self._token_of: dict[int, str] = {}
        """The liveliness token that speaks for each fish up now."""
        self._handed_over: set[int] = set()
        """Fish whose token went while a spare took them over: their loss keeps them alive,
        to come back (until they are admitted again)."""
        self._spare_tokens: dict[int, list[str]] = {}
        """Tokens of a fish id already spoken for, oldest first: a second process started
        with a taken id (ignored while the first is up: it would take the fish from its
        school), or a restarted one whose token came before the old one's went (it takes
        over then)."""

    def on_alive(self, key: str, alive: bool, now: float) -> int | None:
        """A liveliness token came or went; the fish that left, if one did."""
        try:
            member = self.keys.parse_alive(key)
        except ValueError:
            return None
        if member.role == "channel":
            self.channels += 1 if alive else -1
            return None
        if member.role == "world":
            (self.worlds.add if alive else self.worlds.discard)(key)
            return None
        if member.role == "robot":
            robot = self.keys.robot_of(key)
            if robot is not None:
                (self.robots.add if alive else self.robots.discard)(robot)
            return None
        if member.role == "queue":
            place = self.keys.place_of(member.member_id)
            if alive and place is not None:
                self.queue[key] = place
            else:
                self.queue.pop(key, None)
            return None
        fish_id = fish_id_of(member.member_id)
        if member.role != "fish" or fish_id is None:
            return None
        if not alive:
            return self._gone(fish_id, key, now)
        current = self._token_of.get(fish_id)
        # A fish lost (silent) may be taken over at once by a process that came up for it.
        if current is not None and current != key and fish_id in self.alive:
            spares = self._spare_tokens.setdefault(fish_id, [])
            if key not in spares:
                spares.append(key)
                # Which came up first is not known here (a world that comes up hears every
                # token at once): only which it heard of first.
                log.warning(
                    "fish %d is served by two processes, %s and %s: this world takes the "
                    "commands of %s, heard of first, while it is up; give each fish process "
                    "its own ids",
                    fish_id,
                    current,
                    key,
                    current,
                )
            return None
        self._speaks_for(fish_id, key, member.school, now)
        return None

    def _gone(self, fish_id: int, key: str, now: float) -> int | None:
        """Token ``key`` of ``fish_id`` went: the fish left, unless another token of it is
        up (a spare goes unsaid; the speaking one's place goes to the oldest spare)."""
        spares = self._spare_tokens.get(fish_id, [])
        if key in spares:
            spares.remove(key)
            return None
        if self._token_of.get(fish_id) != key:
            return None  # a token that never spoke for the fish (not a valid school)
        del self._token_of[fish_id]
        # The fish leaves the world either way (this tick's perception went to the process
        # that left); a spare that takes it over brings it back at a later tick.
        if self._hand_over(fish_id, now):
            self._handed_over.add(fish_id)
        else:
            self.alive.discard(fish_id)
        return fish_id

    def _hand_over(self, fish_id: int, now: float) -> bool:
        """Whether the oldest spare token of ``fish_id`` that can speaks for it now."""
        spares = self._spare_tokens.get(fish_id, [])
        while spares:
            spare = spares.pop(0)
            if self._speaks_for(fish_id, spare, self.keys.parse_alive(spare).school, now):
                log.warning("fish %d: %s speaks for it now", fish_id, spare)
                return True
        return False

    def _speaks_for(self, fish_id: int, key: str, school: str | None, now: float) -> bool:
        """Whether token ``key`` (of ``school``) speaks for ``fish_id`` from now on, its
        commands subscribed; not when no key can name its school."""
        try:
            if school is None:
                command_key, kind = self.keys.command(fish_id), "command"
            else:
                command_key, kind = self.keys.school_commands(school), "batch"
        except ValueError:  # a token naming a school that no key can name: not a fish of ours
            log.warning("ignored the liveliness token %s: not a valid school name", key)
            return False
        self._token_of[fish_id] = key
        self.alive.add(fish_id)
        if self.school_of.get(fish_id, ()) != school:
            self.school_of[fish_id] = school
            self._schools = None
        if self.command_key.get(fish_id) != command_key:
            self.command_key[fish_id] = command_key
            self._senders.clear()
        if command_key not in self._subscriptions:
            self._subscriptions[command_key] = (self._subscribe(command_key, kind), now)
        return True

    def schools(self, ids: NDArray[np.int64]) -> Schools:
        """The schools of the fish ``ids`` (the world's, as it is now), numbered once for as
        long as neither the fish nor their schools change."""
        cached = self._schools
        if cached is None or cached[0] is not ids:
            # The world replaces its ids array when fish join or leave, never edits it.
            cached = self._schools = (ids, Schools.of(ids, self.school_of))
        return cached[1]

    def all_on(self, command_key: str, fish_ids: NDArray[np.int64]) -> bool:
        """Whether each of ``fish_ids`` sends its commands on ``command_key``."""
        senders = self._senders.get(command_key)
        if senders is None:
            on_key = [i for i, key in self.command_key.items() if key == command_key]
            senders = self._senders[command_key] = np.array(sorted(on_key), dtype=np.int64)
        return bool(among(senders, fish_ids).all())

    def ready(self, present: set[int], now: float, admit_delay: float) -> list[int]:
        """Live fish not yet in the world whose commands have been subscribed long enough."""
        ready = sorted(
            fish_id
            for fish_id in self.alive - present
            if self._subscriptions[self.command_key[fish_id]][1] <= now - admit_delay
        )
        self._handed_over.difference_update(ready)
        return ready

    def why_gone(self, fish_id: int) -> str:
        """Why a fish whose token went is lost: what its launcher said of it, if anything."""
        return self._loss_reasons.get(fish_id, TOKEN_GONE)

    def explain_loss(self, fish_ids: Iterable[int], reason: str) -> None:
        """Say why fish leave or left: their process failed (``reason``). Their losses give
        it instead of their tokens' going, when recorded already and when still to come."""
        ids = set(fish_ids)
        self._loss_reasons.update(dict.fromkeys(ids, reason))
        self.lost = [
            dataclasses.replace(lost, reason=reason)
            if lost.fish_id in ids and lost.reason == TOKEN_GONE
            else lost
            for lost in self.lost
        ]

    def mark_lost(self, fish_id: int, tick: int, reason: str, now: float = 0.0) -> bool:
        """Record a fish as lost at ``tick`` (once per tick); whether it is news. ``now``:
        the world's clock, s, when a spare takes the fish over (its subscription's start)."""
        if any(f.fish_id == fish_id and f.tick == tick for f in self.lost):
            return False
        log.warning("fish %d lost at tick %d: %s", fish_id, tick, reason)
        self.lost.append(LostFish(fish_id, tick, reason))
        # A process that took the fish over (or a spare that can now: the lost one hangs
        # with its token up) brings it back at a later tick.
        if fish_id in self._handed_over:
            self._handed_over.discard(fish_id)
        elif fish_id not in self._token_of or not self._hand_over(fish_id, now):
            self.alive.discard(fish_id)
        return True

    def close(self) -> None:
        """Withdraw every command subscription."""
        for declared, _ in self._subscriptions.values():
            declared.undeclare()
        self._subscriptions.clear()
