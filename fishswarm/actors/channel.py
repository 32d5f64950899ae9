"""The channel actor (simulation only): delivers broadcasts to the fish that can receive them.

After the world's snapshot of tick k+1 (which says how many broadcasts each fish sent at
tick k), the channel waits for exactly those outbox messages, works out the receptions with
the positions of tick k+1, publishes the deliveries for tick k+1, and then a report telling
the world how many deliveries each fish gets, so that each fish can wait for all of them:
deterministic, and nothing lost.

In a world with robots, the channel also plays the robots' light for the simulated fish: a
robot whose LEDs flash (the snapshot says so; its fish holds its place in a formation, and
its flags go by light, never onto the link) reaches the simulated fish that see it with a
one-bit formation flag, as a robot's cameras would take it. Robots (known by their drivers'
liveliness tokens) get none of these: they see each other flash with their cameras. The
simulated fish's own flags still reach robots through the channel, their only way there.

A channel run apart from its world (``fishswarm channel``) asks each run's world for its
scenario when the run starts and takes the world's medium — range, loss, seed, how flags
travel and the vision that decides who sees whom: a channel started
with other settings would otherwise deliver what no batch run of the world's scenario
delivers.
"""

from __future__ import annotations

import logging
from collections import defaultdict, deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import numpy as np
import trio

from fishswarm.actors.bus import Bus, open_alive_events, open_subscriber, open_token
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.intake import LOGGED_SENDERS, Intake
from fishswarm.behaviors.core import FishParams
from fishswarm.behaviors.formation import flag_seen_in_light
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import fish_id_of
from fishswarm.protocols.messages import (
    BROADCAST_KINDS,
    FLASHING,
    Broadcast,
    ChannelReport,
    Delivery,
    FormationFlag,
    Snapshot,
)
from fishswarm.sim.medium import flashes_shown, receptions, travelling
from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.sim.streams import Stream, stream

log = logging.getLogger(__name__)


FIRST_SNAPSHOT_WAIT = 0.5
"""Longest wait for the broadcasts that the first snapshot a channel sees announces, when
that snapshot is not a run's first (the channel came up while the run went on), s: enough
for broadcasts on their way, little against a tick."""
OUTBOX_TIMEOUT = 5.0
"""How long the channel waits for the broadcasts a snapshot announces, s."""

FIRST_TICKS = 2
"""A run's first broadcasts are of ticks 0 to this: those of a run the channel has not seen
a snapshot of yet (a new world's, whose first snapshot is still on its way) are kept for
it."""

HELD_BROADCASTS_MAX = 100_000
"""Most broadcasts the channel keeps for one run it has not seen a snapshot of yet: more
are refused (as a flood), and do not crowd out another run's."""

ENDED_RUNS_KEPT = 16
"""How many runs that have given way the channel remembers, to let go their late snapshots."""

HELD_RUNS_MAX = 4
"""Most runs not seen yet that the channel keeps broadcasts for at once: a run's fish
broadcast before its first snapshot reaches the channel only in the moment its world
starts, so a broadcast of a further run lets go what was held for the earliest (the run
about to start is the latest)."""


@dataclass(frozen=True)
class ChannelStatistics:
    """Counters of the channel.

    Attributes:
        delivered: deliveries made.
        missing_broadcasts: broadcasts announced in a snapshot that never arrived.
        rejected: messages rejected: malformed, misaddressed, of a tick long gone or not
            yet come, or from a fish that sent more than it announced.
        unannounced: valid broadcasts no snapshot announced, not delivered: their
            sender's command came late or not at all (lost, left), or their run had
            ended. An ordinary part of a real-time run, or of fish coming and going.
    """

    delivered: int
    missing_broadcasts: int
    rejected: int
    unannounced: int = 0


class Channel:
    """The simulated broadcast medium. ``await channel.run(bus)`` serves until cancelled.

    Args:
        scenario: the medium: range, loss, seed, how flags travel and who sees whom.
        outbox_timeout: longest wait for the broadcasts a snapshot announces, s.
        ask_world: for a channel apart from its world, how to ask the world of a run that
            starts for its scenario (None if no world answers; it may raise
            :class:`ConfigError`); the medium then takes the world's scenario.
            None (the default): ``scenario`` is the world's, as in ``fishswarm run``.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        outbox_timeout: float = OUTBOX_TIMEOUT,
        ask_world: Callable[[], Awaitable[Scenario | None]] | None = None,
    ) -> None:
        self.scenario = scenario
        """The medium's settings now (a standalone channel's: its last run's world's
        scenario; the channel's keys stay its own)."""
        self._own = scenario
        self._ask_world = ask_world
        self.keys = scenario.keys
        self.outbox_timeout = outbox_timeout
        self._intake = Intake("channel")
        self._events: Inbox[tuple[str, str, bytes]]
        self._outbox: dict[int, dict[int, list[Broadcast]]] = defaultdict(dict)
        """Broadcasts received, by tick and sender."""
        self._early: deque[tuple[str, bytes]] = deque()
        """Snapshots that came while the channel gathered an earlier one's broadcasts."""
        self._rngs: dict[tuple[Stream, int], np.random.Generator] = {}
        self._robot_events: Inbox[tuple[str, bool]]
        self._robots: set[int] = set()
        """Robots up on the swarm (their drivers' tokens)."""
        self._params: FishParams | None = None
        self._params_of: Scenario | None = None
        """The scenario ``_params`` were read from."""
        self._delivered = 0
        self._missing = 0
        self._unannounced = 0
        self._unannounced_named: set[int] = set()
        """Senders whose unannounced broadcasts have been logged."""
        self._last_tick = 0
        self._run = 0
        """The run of the last snapshot (0: none seen, or its world does not tell)."""
        self._held: dict[int, list[Broadcast]] = {}
        """Broadcasts of the first ticks of runs not yet seen, by run."""
        self._ended_runs: deque[int] = deque(maxlen=ENDED_RUNS_KEPT)
        """Runs that have given way to a later one, latest last: a late snapshot of one is
        let go (it would start that run again, and the next snapshot the current one)."""
        self._first_tick: int | None = None
        """The first tick of the run this channel has seen a snapshot of (0: the whole run;
        later: it came up while the run went on)."""

    def statistics(self) -> ChannelStatistics:
        """The channel's counters so far."""
        return ChannelStatistics(
            self._delivered, self._missing, self._intake.rejected_total, self._unannounced
        )

    async def run(
        self, bus: Bus, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED
    ) -> None:
        """Deliver broadcasts until cancelled."""
        self._events = events = Inbox[tuple[str, str, bytes]]()
        self._robot_events = robots = Inbox[tuple[str, bool]]()
        keys = self.keys
        async with (
            open_subscriber(bus, keys.snapshot, lambda k, p: events.push(("snapshot", k, p))),
            open_subscriber(bus, keys.fish_outboxes(), lambda k, p: events.push(("outbox", k, p))),
            open_alive_events(bus, keys.alive_all("robot"), lambda k, up: robots.push((k, up))),
            open_token(bus, keys.alive("channel", 0)),
        ):
            task_status.started()
            while True:
                before = self._run if self._first_tick is not None else None
                snapshot = await self._next_snapshot()
                self._take_robots()
                if self._first_tick is None or snapshot.tick == 0:
                    self._first_tick = snapshot.tick
                # A run starts at its tick 0, or, where that snapshot was lost, at the first
                # snapshot of another run than the last one seen: its losses then still draw
                # from their start. (A channel come up during a run joins it as it is.)
                if snapshot.tick == 0 or before not in (None, snapshot.run):
                    self._start_run()
                    if self._ask_world is not None:
                        await self._take_the_worlds_medium(self._ask_world)
                if snapshot.tick == 0:
                    continue
                shown = flashes_shown(snapshot.lights, time_mode=self.scenario.time_mode)
                if int(snapshot.broadcasts.sum()) == 0 and not shown:
                    self._settle(snapshot.tick - 1, {})  # nothing announced: nothing to wait for
                    continue
                broadcasts = await self._gather(snapshot)
                self._deliver(bus, snapshot, broadcasts, shown)

    async def _next_snapshot(self) -> Snapshot:
        while True:
            if self._early:
                key, payload = self._early.popleft()
            else:
                kind, key, payload = await self._events.receive()
                if kind != "snapshot":
                    self._take_outbox(key, payload)
                    continue
            snapshot = self._intake.decode(key, payload, Snapshot)
            if snapshot is not None and snapshot.run and snapshot.run in self._ended_runs:
                self._intake.disregard()
                continue
            if snapshot is not None:
                self._last_tick = snapshot.tick
                if snapshot.run != self._run:
                    if self._run:
                        self._ended_runs.append(self._run)
                    self._run = snapshot.run
                    self._take_held()
                return snapshot

    def _take_outbox(self, key: str, payload: bytes) -> Broadcast | None:
        """Keep a broadcast for delivery; the broadcast kept, or None."""
        sender, _ = self.keys.member_of(key)
        owner = fish_id_of(sender)
        if owner is None:
            self._intake.reject(key, "misaddressed", f"{sender!r} is not a fish id")
            return None
        broadcast = self._intake.decode_addressed(
            key, payload, Broadcast, field="sender_id", owner=owner
        )
        if broadcast is None:
            return None
        if broadcast.run is not None and not self._of_this_run(broadcast):
            self._hold(key, broadcast, broadcast.run)
            return None
        # Only broadcasts of the ticks about to be delivered are kept: anything else is
        # stale or forged, and would pile up.
        if not self._last_tick - 1 <= broadcast.tick <= self._last_tick + 2:
            self._intake.refuse(key, "stale", f"broadcast of tick {broadcast.tick}")
            return None
        self._outbox[broadcast.tick].setdefault(broadcast.sender_id, []).append(broadcast)
        return broadcast

    async def _gather(self, snapshot: Snapshot) -> list[Broadcast]:
        """The broadcasts the snapshot announces, by sender: each sender's first as many as
        it announced. Waits for them (at most ``outbox_timeout``); any other broadcast of
        the tick — from a fish that was not announced (lost, or late), or one too many — is
        not delivered, and counted."""
        sent_tick = snapshot.tick - 1
        wanted = {
            int(fish): int(count)
            for fish, count in zip(snapshot.ids.tolist(), snapshot.broadcasts.tolist(), strict=True)
            if count > 0
        }
        kept = self._outbox[sent_tick]
        remaining = sum(max(0, n - len(kept.get(fish, []))) for fish, n in wanted.items())
        # Come up while the run went on, the channel may have missed the broadcasts its first
        # snapshot announces (sent before it listened): waiting the whole timeout for them
        # would hold the world; those still on their way come within a moment.
        patience = self.outbox_timeout
        if snapshot.tick == self._first_tick:
            patience = min(patience, FIRST_SNAPSHOT_WAIT)
        with trio.move_on_after(patience):
            while remaining > 0:
                kind, key, payload = await self._events.receive()
                if kind == "snapshot":
                    self._early.append((key, payload))
                    continue
                broadcast = self._take_outbox(key, payload)
                if (
                    broadcast is not None
                    and broadcast.tick == sent_tick
                    and len(kept[broadcast.sender_id]) <= wanted.get(broadcast.sender_id, 0)
                ):
                    remaining -= 1
        chosen = self._settle(sent_tick, wanted)
        wanted_total = sum(wanted.values())
        if len(chosen) < wanted_total:
            self._missing += wanted_total - len(chosen)
            log.warning(
                "channel: %d of %d broadcasts of tick %d never arrived",
                wanted_total - len(chosen),
                wanted_total,
                sent_tick,
            )
        return chosen

    def _settle(self, sent_tick: int, wanted: dict[int, int]) -> list[Broadcast]:
        """Take the broadcasts of ``sent_tick`` out of the outbox: each sender's first
        ``wanted`` of them, by sender. More from an announced sender than it announced are
        rejected; those of a sender the snapshot does not announce, and any of older ticks,
        are let go as unannounced."""
        for old in sorted(t for t in self._outbox if t < sent_tick):
            # Its snapshot never came (lost), or came before the broadcast did.
            self._let_go(old, f"of tick {old}, whose snapshot had gone by")
        got = self._outbox.pop(sent_tick, {})
        chosen = [b for fish in sorted(wanted) for b in got.get(fish, [])[: wanted[fish]]]
        for fish, broadcasts in got.items():
            if fish not in wanted:
                for _ in broadcasts:
                    self._let_go_one(
                        fish,
                        f"of tick {sent_tick}, which the snapshot of tick {sent_tick + 1} "
                        "does not announce (its command came late or not at all)",
                    )
                continue
            for _ in range(len(broadcasts) - wanted[fish]):
                self._intake.refuse(
                    self.keys.outbox(fish), "surplus",
                    f"one broadcast of tick {sent_tick} more than its sender announced",
                )  # fmt: skip
        return chosen

    def _deliver(
        self, bus: Bus, snapshot: Snapshot, broadcasts: list[Broadcast], shown: bool
    ) -> None:
        """Deliver the broadcasts, and with ``shown`` the robots' flashes, then report."""
        index_of = {int(i): n for n, i in enumerate(snapshot.ids.tolist())}
        present = [b for b in broadcasts if b.sender_id in index_of]
        # By light or beacon, only "I hold my place" travels, and it says nothing else.
        travels = [
            (present[n], values)
            for n, values in travelling(
                [BROADCAST_KINDS.index(b.kind) for b in present],
                [b.values for b in present],
                one_bit_flags=self.scenario.one_bit_flags,
            )
        ]
        rngs = [self._rng(int(i)) for i in snapshot.ids.tolist()]
        found = receptions(
            snapshot.position,
            snapshot.yaw,
            [index_of[b.sender_id] for b, _ in travels],
            channel_range=self.scenario.channel_range,
            loss=self.scenario.channel_loss,
            rngs=rngs,
            sight=self.scenario.flag_sight,
        )
        deliveries = [(r, travels[r.broadcast][0].kind, travels[r.broadcast][1]) for r in found]
        flag = self._light_flag(snapshot) if shown else None
        if flag is not None:
            # Seen with the world's eyes, lost at the run's rate, with losses of their own:
            # the broadcasts' receptions and draws stay those of a run without robots.
            assert snapshot.lights is not None
            flashing = snapshot.ids[snapshot.lights == FLASHING]
            seen = receptions(
                snapshot.position,
                snapshot.yaw,
                [index_of[int(robot)] for robot in flashing],
                channel_range=self.scenario.channel_range,
                loss=self.scenario.channel_loss,
                rngs=[self._rng(int(i), Stream.LIGHT) for i in snapshot.ids.tolist()],
                sight=self.scenario.vision(),
            )
            # Robots see each other flash with their cameras.
            to_fish = [r for r in seen if int(snapshot.ids[r.receiver]) not in self._robots]
            deliveries += [(r, "formation", flag.values()) for r in to_fish]
        counts = np.zeros(snapshot.ids.size, dtype=np.int64)
        run = snapshot.run or None
        for reception, kind, values in deliveries:
            receiver_id = int(snapshot.ids[reception.receiver])
            delivery = Delivery(
                receiver_id,
                snapshot.tick,
                kind,
                values,
                reception.sender_position,
                # A robot's driver numbers its fish's mail by its own run: the world's is
                # left off the wire, which a driver not yet upgraded still reads.
                None if receiver_id in self._robots else run,
            )
            bus.put(self.keys.inbox(receiver_id), encode(delivery))
            counts[reception.receiver] += 1
        self._delivered += len(deliveries)
        bus.put(
            self.keys.channel_report, encode(ChannelReport(snapshot.tick, snapshot.ids, counts))
        )

    def _hold(self, key: str, broadcast: Broadcast, run: int) -> None:
        """Keep a broadcast of ``run``, which the channel has not seen a snapshot of, if it
        may be one of that run's first: a new world's fish can broadcast before its first
        snapshot reaches the channel."""
        held = self._held.get(run)
        if broadcast.tick > FIRST_TICKS:  # a run's that has ended, come late: no new one's
            self._let_go_one(broadcast.sender_id, f"of tick {broadcast.tick} of run {run}")
            return
        if held is None and len(self._held) >= HELD_RUNS_MAX:
            earliest = next(iter(self._held))
            for kept in self._held.pop(earliest):
                self._let_go_one(kept.sender_id, f"of run {earliest}, which never came")
        if held is not None and len(held) >= HELD_BROADCASTS_MAX:
            self._intake.refuse(
                key, "flood", f"{HELD_BROADCASTS_MAX} broadcasts of run {run} held already"
            )
        else:
            self._held.setdefault(run, []).append(broadcast)

    def _start_run(self) -> None:
        """A run starts (its first snapshot): the medium starts afresh, so that a channel
        that serves run after run gives each the losses its seed gives a run alone; what
        an earlier run left in the outbox is counted and let go."""
        self._rngs.clear()
        # A new run's first broadcasts are of ticks 0 to 2: anything later is the last
        # run's, as is anything that names another run.
        for tick in list(self._outbox):
            if tick > FIRST_TICKS:
                self._let_go(tick, f"of tick {tick}, of a run that has ended")
                continue
            for sender, sent in list(self._outbox[tick].items()):
                kept = [b for b in sent if self._of_this_run(b)]
                for _ in range(len(sent) - len(kept)):
                    self._let_go_one(sender, f"of tick {tick}, of a run that has ended")
                self._outbox[tick][sender] = kept

    def _of_this_run(self, broadcast: Broadcast) -> bool:
        """Whether ``broadcast`` is of the run of the snapshots (or names none: a sender
        or world that does not tell runs)."""
        return broadcast.run in (None, 0, self._run)

    def _take_held(self) -> None:
        """The run of the snapshots changed: take what its fish sent before this snapshot
        came, and let go what was held for other runs."""
        for run, held in self._held.items():
            for broadcast in held:
                if run == self._run:
                    sent = self._outbox[broadcast.tick]
                    sent.setdefault(broadcast.sender_id, []).append(broadcast)
                else:
                    self._let_go_one(broadcast.sender_id, f"of run {run}, which never came")
        self._held.clear()

    async def _take_the_worlds_medium(
        self, ask_world: Callable[[], Awaitable[Scenario | None]]
    ) -> None:
        """Take the medium — range, loss, seed, how flags travel and who sees whom — from the
        world of the run that starts (before its first broadcasts are delivered, at the
        snapshot of tick 1); the channel's own settings, said in a warning, if the world does
        not tell them."""
        own = self._own
        try:
            world = await ask_world()
        except ConfigError as error:
            world = None
            log.warning("channel: %s", error)
        if world is None:
            log.warning(
                "channel: the run's world did not tell its settings: the medium takes the "
                "channel's own (range %g m, loss %g, seed %d, flags by %s)",
                own.channel_range,
                own.channel_loss,
                own.seed,
                own.flag_medium,
            )
        chosen = own if world is None else world
        log.info(
            "channel: a run starts: range %g m, loss %g, seed %d, flags by %s",
            chosen.channel_range,
            chosen.channel_loss,
            chosen.seed,
            chosen.flag_medium,
        )
        # The rngs were let go at the run's first snapshot: the next draws use this seed.
        # The world's scenario whole: its range, loss, seed and flag medium, and its vision
        # (flags by light reach the fish that see their sender).
        self.scenario = chosen

    def _let_go(self, tick: int, reason: str) -> None:
        """Count every broadcast of ``tick`` in the outbox as unannounced, and drop them."""
        for fish, broadcasts in self._outbox.pop(tick, {}).items():
            for _ in broadcasts:
                self._let_go_one(fish, reason)

    def _let_go_one(self, fish: int, reason: str) -> None:
        """Count a valid broadcast of ``fish`` that no snapshot announced, and say so once
        for each sender (of up to :data:`LOGGED_SENDERS`): a fish's late or lost command,
        or a run's end, not a bad message."""
        self._unannounced += 1
        if fish in self._unannounced_named or len(self._unannounced_named) >= LOGGED_SENDERS:
            return
        self._unannounced_named.add(fish)
        log.info(
            "channel: a broadcast of fish %d %s, not delivered; further ones of this fish are "
            "counted as unannounced broadcasts",
            fish,
            reason,
        )

    def _light_flag(self, snapshot: Snapshot) -> FormationFlag | None:
        """The flag a simulated fish takes a flashing robot for, in the shape the snapshot
        tells (None: its fish heed no flags)."""
        scenario = self.scenario
        if scenario.behavior != "formation" or not scenario.flags:
            return None  # and no parameters to read (a replica model's file, say)
        if self._params_of is not scenario:
            self._params, self._params_of = scenario.fish_params(), scenario
        assert self._params is not None
        return flag_seen_in_light(self._params, snapshot.formation)

    def _take_robots(self) -> None:
        """Note the robots that came up or went since the last snapshot (their drivers'
        tokens)."""
        for key, up in self._robot_events.drain():
            robot = self.keys.robot_of(key)
            if robot is not None:
                (self._robots.add if up else self._robots.discard)(robot)

    def _rng(self, fish_id: int, role: Stream = Stream.CHANNEL) -> np.random.Generator:
        if (role, fish_id) not in self._rngs:
            self._rngs[role, fish_id] = stream(self.scenario.seed, role, fish_id)
        return self._rngs[role, fish_id]
