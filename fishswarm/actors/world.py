"""The world actor (simulation only): drives the simulated world over the Bus.

The tick sequence itself is :class:`~fishswarm.sim.tick.WorldSim`'s, the same as the batch
engine's; the actor adds what needs I/O and time. At each event it publishes the snapshot
(and ends the run with the last one), then the perceptions of the fish that are due, waits
for their commands, and hands their fins to the simulation:

- **lockstep**: it waits until every live fish has answered (a fish that leaves liveliness
  or misses ``command_timeout`` is lost); as fast as the machine allows; deterministic.
- **realtime**: it waits until the tick's wall-clock end; a fish that has not answered by
  then keeps the fins it holds (its last command).
- **jitter**: events come from each fish's own clock; deterministic.

Broadcasts (lockstep and realtime): a snapshot says how many each fish sent at the previous
tick; the channel delivers them and reports how many deliveries each fish gets, which the
world passes on in the perceptions so that each fish waits for all of them.
Everything order-dependent is done in fish-id order, so the same seed gives bit-identical
trajectories however the fish are spread over processes.
"""

from __future__ import annotations

import logging
import math
import secrets
import time
from collections.abc import Callable, Iterable
from contextlib import AsyncExitStack
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import trio
from numpy.typing import ArrayLike, NDArray

from fishswarm import __version__
from fishswarm.actors.bus import Bus, Declared, open_alive_events, open_subscriber, open_token
from fishswarm.actors.channel import OUTBOX_TIMEOUT
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.intake import Intake
from fishswarm.actors.perceptions import perception_messages
from fishswarm.actors.roster import LostFish, Roster
from fishswarm.actors.threads import in_thread_at_once
from fishswarm.actors.tick_commands import TickCommands, among, values_at
from fishswarm.behaviors.registry import differing_parts, rules_of, settings_digest, settings_parts
from fishswarm.protocols.codec import MessageError, decode, encode
from fishswarm.protocols.keys import fish_id_of, run_id_of
from fishswarm.protocols.messages import (
    DARK,
    FLASHING,
    STEADY,
    ChannelReport,
    Command,
    CommandBatch,
    ControlReply,
    ControlRequest,
    FishAbout,
    PerceptionBatch,
    Snapshot,
    WorldPulse,
)
from fishswarm.sim.clocks import Event
from fishswarm.sim.medium import flashes_shown
from fishswarm.sim.physics import WorldParams
from fishswarm.sim.scenario import COMMAND_TIMEOUT, START_TIMEOUT, TURN_DELAY, Scenario
from fishswarm.sim.tick import WorldSim
from fishswarm.study.progress import ids_text

log = logging.getLogger(__name__)

BusEvent = tuple[str, str, bytes | bool]
T = TypeVar("T")
FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MISSING_NOTE_EVERY = 10.0
"""How often a world waiting for its fish says which are not up yet, s."""
PULSE_PERIOD = 1.0
"""How often a world says it is alive while a run goes on, s (its default)."""
OFFLOAD_AFTER = 0.25
"""A simulation step whose last run took longer than this (s) runs in a worker thread: worth
it only when the world would otherwise be deaf for long (and under a test's MockClock, whose
time jumps while a thread runs, never at small sizes). Shorter steps stay in the event loop:
handing one over costs more than it frees, and at 1 000 fish and more it costs more still
(:meth:`World._compute`)."""
OFFLOAD_FISH = 200
"""From this many fish on, a step's first run goes to a thread of its own, which ends with it
(the compiled kernels load then, for up to seconds)."""

MISMATCH_NAMED = 10
"""Warnings a world gives, for each difference, of fish started with other settings that
say so after its first tick, one for each fish or school as it comes (those that answered
the first tick are named together then; the run's end counts them all)."""


STEP_PHASES = {"next_event": "physics", "sense": "vision"}
"""The simulation's steps whose times :meth:`World.statistics` reports, by the part of a
tick they are."""


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
        channel_timeout: longest wait for the channel's report on a tick, s: longer than
            the channel's own wait for announced broadcasts, so that a broadcast lost on
            the way costs its deliveries (the channel reports without it), not the tick's
            report.
        admit_delay: a fish that comes up is admitted at the first event at least this long
            after the world subscribed to its commands, s (the subscription must reach the
            router first when the world runs as a client).
        turn_delay: a world takes its turn no sooner than this after it came up, s: the
            places of the worlds of its swarm up before it reach it first.
        pulse_period: how often the world says it is alive while a run goes on, s (fish
            take the pulse as a sign of life, so a slow world does not trip their watchdog).
        vouched_only: admit only fish vouched for on their own about keys (their own, or
            their school's listing them): in a secured swarm only a fish's own certificate
            may put there, while anyone certified can show a liveliness token (Zenoh's
            access control does not filter liveliness).
    """

    scenario: Scenario
    expected_fish: tuple[int, ...] = ()
    start_timeout: float = START_TIMEOUT
    command_timeout: float = COMMAND_TIMEOUT
    channel_timeout: float = OUTBOX_TIMEOUT + 1.0
    admit_delay: float = 0.1
    turn_delay: float = TURN_DELAY
    pulse_period: float = PULSE_PERIOD
    vouched_only: bool = False

    def __post_init__(self) -> None:
        if self.pulse_period <= 0:
            raise ValueError(f"pulse_period must be positive, got {self.pulse_period}")


@dataclass(frozen=True)
class WorldStatistics:
    """Counters of a world's run.

    Attributes:
        ticks: snapshots after the first.
        messages_in: messages accepted.
        messages_out: messages published.
        rejected: messages rejected, by kind (malformed, misaddressed, stale).
        lost_fish: fish lost.
        joined_fish: fish that joined after the start.
        late_commands: realtime mode: commands that missed their tick.
        live_fish: fish in the world now.
        mismatched_fish: fish that run another behaviour, version, rules, control period
            or decision parameters than the world's.
        unexpected_fish: fish that took part beyond the scenario's ids (robots, or fish
            processes of another run left up on the swarm): they join the run.
        answer_time_median, answer_time_p90: lockstep and jitter modes: how long the fish
            took to answer a tick — perceptions out to the last command in — median and
            90th percentile over the ticks every fish answered, s (0 before any tick; a tick
            in which a fish timed out is left out, its fish counted as lost); the network's
            latency shows here.
        broadcasts: outbox messages the fish in the world said they sent, from the commands
            it held (every fish: those that joined later and robots too).
        physics_time_median, vision_time_median, perceptions_time_median: where the world's
            time goes: the median wall time of its steps — moving the fish to the next tick
            (lockstep; to the next event in jitter mode: physics), seeing for them (vision),
            and building and sending their perceptions (landmarks seen included) — s, 0
            before any; a step handed to a worker thread counts the hand-off too.
    """

    ticks: int
    messages_in: int
    messages_out: int
    rejected: dict[str, int]
    lost_fish: int
    joined_fish: int
    late_commands: int
    live_fish: int
    mismatched_fish: int = 0
    unexpected_fish: int = 0
    answer_time_median: float = 0.0
    answer_time_p90: float = 0.0
    physics_time_median: float = 0.0
    vision_time_median: float = 0.0
    perceptions_time_median: float = 0.0
    broadcasts: int = 0

    @property
    def rejected_total(self) -> int:
        """Messages rejected, of any kind."""
        return sum(self.rejected.values())


class World:
    """The simulated world. ``await world.run(bus)`` runs the scenario to its end."""

    def __init__(self, settings: WorldSettings) -> None:
        self.settings = settings
        self.scenario = settings.scenario
        self.params = WorldParams.of(settings.scenario)
        self.keys = settings.scenario.keys
        self.state_name = "waiting"
        self.tick = 0
        self.wall_time = 0.0
        self.paused_time = 0.0
        """How long the run was held by an operator's pause, s (part of ``wall_time``)."""
        self.late_commands = 0
        """Realtime mode: commands that missed their tick's deadline (the fish kept its fins)."""
        self._answer_times: list[float] = []
        """Per tick every fish answered: perceptions out to the last command in, s."""
        self.run_id = secrets.randbits(62)
        """Names this run in every perception, so fish that served another start afresh."""
        self.sim = WorldSim(self.params)
        self.intake = Intake("world")
        self._events: Inbox[BusEvent]  # made in run(): an inbox needs a running trio
        self._bus: Bus | None = None
        self.roster = Roster(self.keys, self._subscribe_commands)
        self._leaving: set[int] = set()
        self._broadcasters = np.zeros(0, dtype=np.int64)
        """The fish that answered the last tick, ascending (who may have broadcast)."""
        self._broadcasts = np.zeros(0, dtype=np.int64)
        """How many broadcasts each of them sent (rows alike)."""
        self._awaits_report = False
        self._lights: dict[int, int] = {}
        """The fish whose last command said their LEDs are dark or flash (robots), by id:
        an index into LIGHTS; the others' are steady."""
        self._formation: str | None = None
        """The formation an operator asked for (it overrides the scenario's switch)."""
        self._report: ChannelReport | None = None
        self._resume = trio.Event()
        self._resume.set()
        self._waiting = trio.CancelScope()
        """What the world waits for now (its fish, the channel's report, a tick's commands):
        a stop cancels it, so that no wait holds a stop up (see :meth:`_stoppable`)."""
        self._token = self.keys.alive("world", self.run_id)
        """This world's liveliness token, up from when it takes its turn: it names the run."""
        self.place = (time.time_ns() // 1000, self.run_id)
        """Where this world stands in its swarm's queue: when it arrived (µs since the epoch,
        its own clock), its run: worlds of a swarm take their turns in this order."""
        self._turn = "queued"
        """``queued`` (its place token up: worlds ahead may run first), ``taken`` (its token
        up, waiting for its fish) or ``started``."""
        self.answering = True
        """Whether the world answers queries (not :attr:`queued`), kept as a flag that
        Zenoh's threads read as queries arrive (see :mod:`fishswarm.actors.control`)."""
        self._stop_requested = False
        self._messages_out = 0
        self._broadcasts_sent = 0
        self._said_no_channel = False
        self._current = TickCommands()
        self._previous = TickCommands()
        """The tick before, closed: a second process's answer to it may come after."""
        self.mismatched: set[int] = set()
        """Fish that said they run another behaviour, version, rules, control period or
        decision parameters than this world's."""
        self.unexpected: set[int] = set()
        """Fish that took part beyond the scenario's ids (they join its run)."""
        self._twins: set[int] = set()
        """Fish that two processes answer for (warned of once)."""
        self.vouched: set[tuple[int, str | None]] = set()
        """(fish id, school or None) pairs vouched for on their own about keys."""
        self._unvouched: dict[tuple[int, str | None], str] = {}
        """With ``vouched_only``: live fish tokens not (yet) vouched for, held back from the
        roster until they are (a fish's token may come before its vouching)."""
        fish_params = settings.scenario.fish_params()
        self._fish_rules = rules_of(fish_params)
        """The rules this world's scenario says its fish decide by (FishAbout.rules)."""
        self._fish_settings = settings_digest(fish_params)
        """The digest of its fish's decision parameters (FishAbout.settings)."""
        self._fish_parts = settings_parts(fish_params)
        """The same, parameter by parameter (FishAbout.parts)."""
        self._warned: dict[str, dict[int, None]] = {}
        """The fish that differ from this world's settings, by difference: named together
        once the first tick is answered, and any that come later one by one
        (MISMATCH_NAMED at most)."""
        self._differences_named = False
        self._late_warnings: dict[str, int] = {}
        """How many warnings each difference gave of fish that said so after the first
        tick."""
        self._step_times: dict[str, float] = {}
        """How long each step of the simulation took the last time, s: a long one runs in a
        worker thread, so that the world keeps pulsing meanwhile."""
        self._phase_times: dict[str, list[float]] = {
            phase: [] for phase in (*STEP_PHASES.values(), "perceptions")
        }
        """Wall time of every physics and vision step and every sending of perceptions, s."""

    @property
    def lost(self) -> list[LostFish]:
        """The fish that left the run."""
        return self.roster.lost

    @property
    def joined(self) -> list[tuple[int, int]]:
        """(fish id, tick) of every fish that joined after the start."""
        return self.roster.joined

    @property
    def time(self) -> float:
        """Simulated time of the last snapshot, s."""
        return self.tick * self.scenario.control_period

    def statistics(self) -> WorldStatistics:
        """The run's counters so far."""
        return WorldStatistics(
            ticks=self.tick,
            messages_in=self.intake.accepted,
            messages_out=self._messages_out,
            rejected=dict(self.intake.rejected),
            lost_fish=len(self.lost),
            joined_fish=len(self.joined),
            late_commands=self.late_commands,
            live_fish=int(self.sim.ids.size),
            mismatched_fish=len(self.mismatched),
            unexpected_fish=len(self.unexpected),
            answer_time_median=_quantile(self._answer_times, 0.5),
            answer_time_p90=_quantile(self._answer_times, 0.9),
            physics_time_median=_quantile(self._phase_times["physics"], 0.5),
            vision_time_median=_quantile(self._phase_times["vision"], 0.5),
            perceptions_time_median=_quantile(self._phase_times["perceptions"], 0.5),
            broadcasts=self._broadcasts_sent,
        )

    async def run(
        self, bus: Bus, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED
    ) -> None:
        """Run the scenario to its end (or a stop request); readiness once subscribed."""
        self._events = events = Inbox[BusEvent]()
        self._bus = bus
        keys = self.keys
        try:
            async with (
                open_subscriber(
                    bus, keys.channel_report, lambda k, p: events.push(("report", k, p))
                ),
                open_alive_events(
                    bus, keys.alive_all(), lambda k, alive: events.push(("alive", k, alive))
                ),
                open_subscriber(bus, keys.abouts()[0], lambda k, p: events.push(("about", k, p))),
                open_subscriber(bus, keys.abouts()[1], lambda k, p: events.push(("about", k, p))),
                AsyncExitStack() as holding,
            ):
                deadline = trio.current_time() + self.settings.start_timeout
                self.place = (time.time_ns() // 1000, self.run_id)  # it comes up now
                async with open_token(bus, keys.queue_place(*self.place)):
                    task_status.started()
                    await self._wait_for_turn(deadline)
                    if not self._stop_requested:
                        await holding.enter_async_context(open_token(bus, self._token))
                        self._turn = "taken"
                        self.answering = not self.queued
                await self._wait_for_fish(deadline)
                started = time.perf_counter()
                if self.state_name == "waiting":  # a pause or a stop asked meanwhile stands
                    self.state_name = "running"
                try:
                    if not self._stop_requested:
                        async with trio.open_nursery() as nursery:
                            nursery.start_soon(self._pulse, bus)
                            await self._loop(bus)
                            nursery.cancel_scope.cancel()
                finally:
                    self.wall_time = time.perf_counter() - started
                    if not self._differences_named:  # the run ended before its first answer
                        self._name_differing_fish()
                    if self.mismatched:
                        # Every fish that differed in any way, counted once.
                        log.warning(
                            "%d fish ran with other settings than this world's: %s",
                            len(self.mismatched),
                            ids_text(sorted(self.mismatched)),
                        )
                    # The fish stop watching for this run's perceptions: none will come, at
                    # its end as when the world is interrupted (Ctrl-C) or fails.
                    self._put(
                        bus, keys.world_pulse, encode(WorldPulse(self.run_id, self.tick, "ended"))
                    )
        finally:
            self.roster.close()
        self.state_name = "stopped" if self._stop_requested else "finished"

    async def _pulse(self, bus: Bus) -> None:
        """Say that the world is alive, every ``pulse_period``, until the run ends."""
        while True:
            await trio.sleep(self.settings.pulse_period)
            state = self.state_name if self.state_name in ("paused", "stopping") else "running"
            self._put(bus, self.keys.world_pulse, encode(WorldPulse(self.run_id, self.tick, state)))

    async def _compute(self, step: Callable[[], T]) -> T:
        """Run one step of the simulation; in a worker thread when the last run took long
        enough that the world would otherwise hear nothing meanwhile."""
        name = step.__name__
        last = self._step_times.get(name)
        started = time.perf_counter()
        if last is None and self.sim.ids.size >= OFFLOAD_FISH:
            # The compiled kernels load now. In a thread that ends with the step: one kept
            # in trio's cache would lead an OpenMP team of its own for the rest of the run,
            # beside the event loop's, and with more OpenMP threads than cores every parallel
            # loop of every tick waits for a sleeping worker (in_thread_at_once).
            thread = f"fishswarm world {name}"
            result = await in_thread_at_once(step, name=thread, passing=True)
        elif last is not None and last > OFFLOAD_AFTER:
            # A step this long (a school in a tank too small for it) keeps a thread of
            # trio's, whose memory is then at hand for the next: a new thread's first step
            # at 10 000 fish took 70–100 ms instead of 20, its heap's pages touched anew.
            result = await trio.to_thread.run_sync(step)
        else:
            result = step()
        self._step_times[name] = took = time.perf_counter() - started
        if name in STEP_PHASES:
            self._phase_times[STEP_PHASES[name]].append(took)
        return result

    def _subscribe_commands(self, key: str, kind: str) -> Declared:
        # One exact subscription per fish or school, not one on fish/*/command: a router
        # matches a wildcard for every message (measured: 155 µs per command against 22 µs).
        assert self._bus is not None, "commands are subscribed only while the world runs"
        events = self._events
        return self._bus.subscribe(key, lambda k, payload: events.push((kind, k, payload)))

    def control(self, request: ControlRequest) -> ControlReply:
        """Answer a control request: status, pause, resume, stop or a formation switch (a
        run that has ended only reports its status; a switch it cannot make says why)."""
        ended = self.state_name in ("finished", "stopped")
        action = "status" if ended else request.action
        refused = None
        if request.action == "formation" and ended:
            refused = f"the run has {self.state_name}"
        elif request.action == "formation" and self.scenario.behavior != "formation":
            refused = f"the fish run {self.scenario.behavior}, not a formation"
            action = "status"
        if action in ("pause", "resume") and self._stop_requested:
            action = "status"  # a stopping run stays stopping
        if action == "pause":
            if self._resume.is_set():  # pausing twice is pausing once
                self._resume = trio.Event()
            # Before the run starts, its first tick is held already; once it runs, the tick
            # under way is answered first, and the run is paused at the next snapshot.
            if self.state_name == "running":
                self.state_name = "pausing"
            elif self.state_name == "waiting":
                self.state_name = "paused"
        elif action == "resume" and not self._resume.is_set():
            self._resume.set()
            self.state_name = "running"
        elif action == "formation":
            self._formation = request.formation
        elif action == "stop":
            self._stop_requested = True
            self._resume.set()
            self._waiting.cancel()
            self.state_name = "stopping"
        return ControlReply(self.state_name, self.tick, self.time, len(self.roster.alive), refused)

    def control_payload(self, key: str, payload: bytes) -> bytes | None:
        """Answer an encoded control request; None (counted and logged) if it is not one."""
        try:
            request = decode(payload, ControlRequest)
        except MessageError as error:
            self.intake.reject(key, "malformed", str(error))
            return None
        return encode(self.control(request))

    def _held_back(self, key: str, alive: bool) -> bool:
        """Whether a fish's liveliness token waits for its vouching instead of reaching the
        roster: a token nobody vouched for neither adds a fish nor takes one away (a token
        naming a real fish under another school would otherwise re-route or drop it)."""
        try:
            member = self.keys.parse_alive(key)
        except ValueError:
            return False
        fish_id = fish_id_of(member.member_id)
        if member.role != "fish" or fish_id is None:
            return False
        pair = (fish_id, member.school)
        if pair in self.vouched:
            return False
        if alive:
            self._unvouched[pair] = key
        else:
            self._unvouched.pop(pair, None)
        return True

    def _admissible(self) -> set[int]:
        """Live fish the world may admit: all of them, or (``vouched_only``) those vouched
        for under the school their liveliness token names."""
        if not self.settings.vouched_only:
            return self.roster.alive
        return {i for i in self.roster.alive if (i, self.roster.school_of.get(i)) in self.vouched}

    @property
    def other_worlds(self) -> set[str]:
        """Liveliness tokens of the other worlds of this swarm that have taken their turn."""
        return self.roster.worlds - {self._token}

    @property
    def ahead(self) -> list[str]:
        """The liveliness tokens of the worlds of this swarm this one waits for, in order.

        A queued world waits for every world that has taken its turn and for those whose
        place comes before its own. A world that has taken its turn waits only for one that
        took it in the same instant (neither saw the other's place first): the lower run id
        goes first. A started world waits for none.
        """
        if self._turn == "started":
            return []
        worlds = sorted(self.other_worlds)
        if self._turn == "taken":
            return [w for w in worlds if self._run_id_of(w) < self.run_id]
        before = [
            key
            for key, place in sorted(self.roster.queue.items(), key=lambda item: item[1])
            if place < self.place
        ]
        return worlds + before

    def _run_id_of(self, token: str) -> int:
        run = run_id_of(self.keys.parse_alive(token).member_id)
        return -1 if run is None else run  # a token naming no run: taken as first

    @property
    def queued(self) -> bool:
        """Whether this world waits for other worlds of its swarm before it starts: it then
        answers no queries (an operator's and a view's are another world's) and takes no
        commands (its fish answer another world)."""
        return bool(self.ahead)

    async def _wait_for_turn(self, deadline: float) -> None:
        """Wait until no world of the swarm runs or waits ahead of this one (fish serve one
        run at a time: two worlds would take turns starting them afresh), and at least
        ``turn_delay`` since this world came up (so that the places of those up before it
        have reached it)."""
        said = False

        def nobody_ahead() -> bool:
            nonlocal said
            if self.ahead and not said:
                log.warning("%s: waiting for its run to end (fish serve one world at a "
                            "time)", self._who_is_ahead())  # fmt: skip
                said = True
            return not self.ahead

        await self._wait_until(
            nobody_ahead, not_before=trio.current_time() + self.settings.turn_delay,
            deadline=deadline,
        )  # fmt: skip
        if self.ahead and not self._stop_requested:
            self._ahead_for_too_long()

    async def _wait_until(
        self, ready: Callable[[], bool], *, not_before: float, deadline: float
    ) -> None:
        """Take in events until ``ready()`` holds and ``not_before`` has passed, the
        deadline passes, or a stop is asked for."""
        with trio.move_on_at(deadline), self._stoppable():
            while True:
                self._drain()  # all that is in (a token of another world too), first
                if not ready():
                    self._handle(await self._events.receive())
                elif trio.current_time() >= not_before:
                    return
                else:
                    with trio.move_on_at(not_before):  # woken by what comes meanwhile
                        self._handle(await self._events.receive())

    async def _say_who_is_missing(self, expected: set[int], deadline: float) -> None:
        """Every ``MISSING_NOTE_EVERY`` s of the wait for the fish, say which are not up,
        or which world holds this one up (an operator would otherwise hear nothing until
        the start timeout)."""
        started = trio.current_time()
        while True:
            await trio.sleep(MISSING_NOTE_EVERY)
            waited, left = trio.current_time() - started, deadline - trio.current_time()
            missing = sorted(expected - self._admissible())
            if missing:
                log.warning(
                    "%d of %d fish up after %.0f s; waiting for fish %s (for %.0f s more)",
                    len(expected) - len(missing), len(expected), waited, ids_text(missing),
                    left,
                )  # fmt: skip
            elif self.ahead:
                log.warning("its fish are up after %.0f s; %s: waiting for its run to end "
                            "(for %.0f s more)", waited, self._who_is_ahead(), left)  # fmt: skip

    def _warn_of_robots_in_lockstep(self) -> None:
        """Robots swim in real time: a lockstep run goes as fast as the machine allows, and
        is over before they have moved (a mock robot's body would move in bursts)."""
        robots = sorted(self.roster.robots)
        if robots and self.scenario.time_mode != "realtime":
            log.warning(
                "robots %s are up on this swarm, and this run is in %s time: robots swim in "
                "real time; give --time realtime for a run with them",
                ids_text(robots), self.scenario.time_mode,
            )  # fmt: skip

    def _who_is_ahead(self) -> str:
        if self.other_worlds:
            return f"another world runs swarm {self.keys.swarm!r} on this router"
        return f"another world of swarm {self.keys.swarm!r} came up first on this router"

    def _ahead_for_too_long(self) -> None:
        waited = f"{self.settings.start_timeout:g} s"
        if self.other_worlds:
            which = (
                f"another world ran swarm {self.keys.swarm!r} on this router for all of {waited}"
            )
        else:
            which = (
                f"another world of swarm {self.keys.swarm!r}, up before this one, still waited "
                f"for its turn after {waited}"
            )
        raise StartTimeout(
            f"{which}: stop it ('fishswarm control stop --swarm {self.keys.swarm}'), or give "
            "this run another swarm name (--swarm). If 'fishswarm control status' finds no "
            "world there, a client that is not a world shows its token (in a secured swarm "
            "any certificate can: README, 'Securing a swarm')"
        )

    async def _wait_for_fish(self, deadline: float) -> None:
        """Wait until the expected fish are up (and a world that took its turn in the same
        instant, with a lower run, has run)."""
        if self._stop_requested:
            return
        expected = set(self.settings.expected_fish)

        def ready() -> bool:
            return expected <= self._admissible() and not self.ahead

        async with trio.open_nursery() as nursery:
            nursery.start_soon(self._say_who_is_missing, expected, deadline)
            await self._wait_until(ready, not_before=trio.current_time(), deadline=deadline)
            nursery.cancel_scope.cancel()
        if self._stop_requested:
            return
        if ready():
            self._turn = "started"
            self.answering = True
            self._warn_of_robots_in_lockstep()
        elif self.ahead:
            self._ahead_for_too_long()
        missing = sorted(expected - self._admissible())
        if missing:
            raise StartTimeout(
                f"{len(missing)} of {len(expected)} fish did not come up within "
                f"{self.settings.start_timeout:g} s (missing ids: {ids_text(missing)})"
            )
        await trio.sleep(self.settings.admit_delay)

    async def _loop(self, bus: Bus) -> None:
        realtime = self.scenario.time_mode == "realtime"
        period = self.scenario.control_period
        tick_start = trio.current_time()
        while True:
            self._drain()
            self._leave()
            event = await self._compute(self.sim.next_event)
            self._admit(self.tick if event.snapshot is None else event.snapshot)
            perceived = await self._compute(self.sim.sense)
            deferred: IntArray | None = None
            lights: IntArray | None = None
            # The shape told with this tick, fixed as its tick becomes the one a control
            # reply names: a switch answered from now on (while paused here, say) counts
            # from the next tick, as the reply says, and snapshot and perceptions agree.
            told = self._told(event.time)
            if event.snapshot is not None:
                self.tick = event.snapshot
                broadcasts = values_at(self._broadcasters, self._broadcasts, self.sim.ids)
                # The channel delivers what the snapshot announces, and reports only then:
                # the fish's broadcasts, and the flags of robots whose LEDs flash, which it
                # shows the simulated fish that see them. The lights go into the snapshot
                # as they are now, even when it is sent later.
                lights = self._lights_now()
                self._awaits_report = bool(broadcasts.any()) or self._shows_flashes(lights)
                if self._defers(event):
                    # Built, too, once the perceptions are out: nothing it shows changes
                    # before the fins are held (0.15 ms off the fish's wait at 1 000 fish).
                    deferred = broadcasts
                else:
                    self._send_snapshot(bus, event.time, perceived.counts, broadcasts, lights, told)
                if event.last or self._stop_requested:
                    return
            if not event.deciding:
                continue
            paused = not self._resume.is_set()
            if paused:
                self.state_name = "paused"  # held here, at this snapshot, until resumed
            held = trio.current_time()
            try:
                await self._resume.wait()
            finally:  # a pause cut short by the run's end (Ctrl-C) is a pause too
                if paused:
                    self.paused_time += trio.current_time() - held
            if self._stop_requested:
                # Stopped while paused (or in the moment the wait yields): the run ends at
                # this snapshot, without asking the fish for one more tick.
                if deferred is not None:
                    self._send_snapshot(bus, event.time, perceived.counts, deferred, lights, told)
                return
            if realtime and trio.current_time() - tick_start > period:
                tick_start = trio.current_time()  # after a pause: pace from now on
            with self._stoppable():
                inbox_counts = await self._inbox_counts(event)
            if self._stop_requested:
                return
            sending = time.perf_counter()
            # Fish lost while the world waited for the channel decide no more.
            due_ids, rows = self.sim.due()
            if self._leaving:
                staying = ~among(self._leaving_ids(), due_ids)
                due_ids, rows = due_ids[staying], rows[staying]
            self._previous = self._current
            self._current = TickCommands.of(event.number, due_ids)
            for key, message in perception_messages(
                self.keys,
                ids=self.sim.ids,
                schools=self.roster.schools(self.sim.ids),
                depth=self.sim.state.position[:, 2],
                perceived=perceived,
                landmarks=self.sim.sense_landmarks(),
                inbox_counts=inbox_counts,
                tick=event.number,
                time=event.time,
                run=self.run_id,
                heading=self.sim.state.yaw,  # the simulated fish's compass
                formation=told,
                rows=rows,
            ):
                # A batch's readers may be here (the fish in the launcher's process); a fish
                # on its own keys (a robot, a `fishswarm fish` process) is elsewhere.
                self._put(bus, key, encode(message, reuse=isinstance(message, PerceptionBatch)))
            self._phase_times["perceptions"].append(time.perf_counter() - sending)
            if deferred is not None:
                self._send_snapshot(bus, event.time, perceived.counts, deferred, lights, told)
            with self._stoppable():
                if realtime:
                    tick_start += period
                    await self._collect_until(tick_start)
                else:
                    await self._collect()
            if self._stop_requested:
                # Stopped while the fish decide: the run ends at the snapshot last sent,
                # without waiting for a slow or silent fish (up to the command timeout), and
                # the fish yet to answer are not lost for it.
                return
            self._hold()
            if not self._differences_named:
                # Every fish has said what it runs by its first answer: name them together.
                self._name_differing_fish()

    def _stoppable(self) -> trio.CancelScope:
        """A scope for one of the world's waits, cancelled by a stop (at once if one was
        asked already)."""
        self._waiting = scope = trio.CancelScope()
        if self._stop_requested:
            scope.cancel()
        return scope

    def _send_snapshot(
        self,
        bus: Bus,
        time: float,
        seen: IntArray,
        broadcasts: IntArray,
        lights: IntArray | None,
        told: str | None,
    ) -> None:
        """Send the swarm as it is now: this tick's snapshot (``lights``: the fish's LEDs
        as :meth:`_lights_now` told them when the tick's deliveries were announced;
        ``told``: the shape the fish are told with this tick)."""
        state = self.sim.state
        forming = self.scenario.behavior == "formation"
        snapshot = Snapshot(
            self.tick,
            time,
            self.sim.ids,
            state.position,
            state.tank_velocity(),
            state.yaw,
            seen,
            broadcasts,
            self.sim.effort,
            told if forming else None,
            self.run_id,
            lights,
        )
        self._put(bus, self.keys.snapshot, encode(snapshot, reuse=True))

    def _lights_now(self) -> IntArray | None:
        """Each fish's LEDs, as a snapshot tells them (None: all steady)."""
        if not self._lights:
            return None
        ids = np.array(sorted(self._lights), dtype=np.int64)
        said = np.array([self._lights[i] for i in ids.tolist()], dtype=np.int64)
        # values_at gives 0 for the fish that said nothing: steady, once shifted back.
        lights = values_at(ids, said - STEADY, self.sim.ids) + STEADY
        # Only the lights of fish not in the world (yet): the snapshot says nothing.
        return None if (lights == STEADY).all() else lights

    def _shows_flashes(self, lights: IntArray | None) -> bool:
        """Whether a channel shows robots' flashes in ``lights`` (their fish hold their
        places in a formation) to simulated fish this tick, so that the world waits for
        its report: not without a channel, without simulated fish (robots see each other
        flash with their cameras), or in jitter mode, which delivers nothing."""
        if not flashes_shown(lights, time_mode=self.scenario.time_mode):
            return False
        if not self.roster.channels:
            return False
        return bool(set(self.sim.ids.tolist()) - self.roster.robots)

    def _told(self, time: float) -> str | None:
        """The formation the fish are told to take at ``time``: an operator's switch, else
        the scenario's own (None: as configured)."""
        return self._formation or self.params.formation_at(time)

    def _defers(self, event: Event) -> bool:
        """Whether this tick's snapshot can wait until the perceptions are out, so that it
        is built, encoded and sent while the fish decide: not when the channel needs it
        first (it announces broadcasts or robots' flashes to deliver), when the run ends or
        pauses here, or when no fish decide this tick."""
        return (
            not self._awaits_report
            and event.deciding
            and not event.last
            and not self._stop_requested
            and self._resume.is_set()
        )

    def _hold(self) -> None:
        """Hand the fins of the fish that answered (and are still here) to the simulation."""
        current = self._current
        held = current.answered & among(self.sim.ids, current.ids)
        if self._leaving:
            held &= ~among(self._leaving_ids(), current.ids)
        answered = current.ids[held]
        self.sim.hold(answered, current.fins[held])
        self._broadcasts_sent += int(current.broadcasts[held].sum())
        if self.scenario.time_mode == "jitter":
            return  # broadcasts are not delivered in jitter mode: nothing to announce
        self._broadcasters, self._broadcasts = answered, current.broadcasts[held]

    def _leaving_ids(self) -> IntArray:
        """The fish lost this tick, about to leave the world, ascending."""
        return np.array(sorted(self._leaving), dtype=np.int64)

    def _put(self, bus: Bus, key: str, payload: bytes) -> None:
        bus.put(key, payload)
        self._messages_out += 1

    async def _inbox_counts(self, event: Event) -> np.ndarray:
        """How many deliveries each fish in the world waits for at this event."""
        counts = np.zeros(self.sim.ids.size, dtype=np.int64)
        if event.snapshot in (None, 0) or not self._awaits_report:
            return counts
        if not self.roster.channels:
            if not self._said_no_channel:  # once until a channel comes: not every tick
                log.warning(
                    "broadcasts at tick %d but no channel is running: not delivered until one "
                    "comes up (fishswarm channel)",
                    self.tick,
                )
                self._said_no_channel = True
            return counts
        self._said_no_channel = False
        with trio.move_on_after(self.settings.channel_timeout):
            while self._report is None or self._report.tick != self.tick:
                self._handle(await self._events.receive())
        report = self._report
        if report is None or report.tick != self.tick:
            log.warning("no channel report for tick %d: deliveries not announced", self.tick)
            return counts
        return values_at(report.ids, report.inbox_counts, self.sim.ids)

    async def _collect_until(self, deadline: float) -> None:
        """Realtime mode: take commands until the tick's wall-clock end (noting how long the
        fish took, when every one answered by then)."""
        asked = trio.current_time()
        with trio.move_on_at(deadline):
            while True:
                waiting = self._current.left
                self._handle(await self._events.receive())
                if waiting and not self._current.left:
                    self._answer_times.append(trio.current_time() - asked)
        self.late_commands += self._current.left

    async def _collect(self) -> None:
        asked = trio.current_time()
        deadline = asked + self.settings.command_timeout
        with trio.move_on_at(deadline):
            while self._current.left:
                self._handle(await self._events.receive())
        if not self._current.left:
            self._answer_times.append(trio.current_time() - asked)
        for fish_id in self._current.waiting_ids():
            self._lose(fish_id, f"no command within {self.settings.command_timeout:g} s")

    def _drain(self) -> None:
        for event in self._events.drain():
            self._handle(event)

    def _handle(self, event: BusEvent) -> None:
        kind, key, payload = event
        if kind == "alive":
            assert isinstance(payload, bool)
            if self.settings.vouched_only and self._held_back(key, payload):
                return
            left = self.roster.on_alive(key, payload, trio.current_time())
            if left is not None and left in self.sim.ids:
                self._lose(left, self.roster.why_gone(left))
            self.answering = not self.queued
            return
        assert isinstance(payload, bytes)
        if kind in ("command", "batch") and not self.answering:  # queued (a flag: per event)
            return  # another world's run, answered by its fish: not this world's to count
        if kind == "report":
            report = self.intake.decode(key, payload, ChannelReport)
            if report is not None:
                self._report = report
        elif kind == "about":
            self._take_about(key, payload)
        elif kind == "batch":
            self._take_batch(key, payload)
        else:
            self._take_command(key, payload)

    def _take_about(self, key: str, payload: bytes) -> None:
        """Note the fish vouched for; warn, once for each kind of difference, about fish
        that run another behaviour, version, rules, control period or decision parameters
        than this world's."""
        about = self.intake.decode(key, payload, FishAbout)
        if about is None:
            return
        school = self.keys.school_of_key(key)
        if key == self.keys.about(int(about.ids[0]), school) and (
            school is not None or about.ids.size == 1
        ):
            for fish_id in about.ids.tolist():
                self.vouched.add((fish_id, school))
                held = self._unvouched.pop((fish_id, school), None)
                if held is not None:
                    self.roster.on_alive(held, True, trio.current_time())
        # Run 0 is what fish say as they come up: a robot's fish serves its driver's runs,
        # never the world's, so it says what it runs only so. Fish this world does not
        # expect count too: they join its run (robots, a `fishswarm fish --id` by hand).
        if about.run not in (0, self.run_id):
            return
        ids = about.ids.tolist()
        differences = []
        if about.behavior != self.scenario.behavior:
            differences.append(
                f"run {about.behavior!r}, but this world's scenario says {self.scenario.behavior!r}"
            )
        if about.version != __version__:
            differences.append(f"run fishswarm {about.version}, this world {__version__}")
        if about.rules != self._fish_rules:
            differences.append(
                f"follow the {about.rules!r} rules, but this world's scenario says "
                f"{self._fish_rules!r} (--profile, --study-code)"
            )
        period = self.scenario.control_period
        if about.control_period is not None and not math.isclose(about.control_period, period):
            differences.append(
                f"decide every {about.control_period:g} s, but this world's scenario says "
                f"{period:g} s (--period)"
            )
        if about.settings is not None and about.settings != self._fish_settings and not differences:
            # Said only when nothing named above explains it.
            behavior = self.scenario.behavior
            hint = (
                "a formation's map is made for --fish fish: give them the world's --config, "
                "--fish included"
                if behavior == "formation"
                else "give them the world's --config and flags"
            )
            named = "" if about.parts is None else _parts_named(self._fish_parts, about.parts)
            differences.append(
                f"decide with other {behavior} parameters than this world's scenario "
                f"({named}{hint})"
            )
        if not differences:
            return
        self.mismatched.update(ids)
        for difference in differences:
            differing = self._warned.setdefault(difference, {})  # an ordered set
            new = [fish_id for fish_id in ids if fish_id not in differing]
            differing.update(dict.fromkeys(new))
            late = self._late_warnings.get(difference, 0)
            if new and self._differences_named and late < MISMATCH_NAMED:
                # Fish that come after the first tick (robots, fish joining), named as they
                # come: a school in one warning, MISMATCH_NAMED warnings at most.
                self._late_warnings[difference] = late + 1
                _warn_of_difference(new, difference)

    def _name_differing_fish(self) -> None:
        """Name, for each difference, every fish that said so (at the end of the first
        tick, and at the run's end if it had none)."""
        for difference, differing in self._warned.items():
            _warn_of_difference(sorted(differing), difference)
        self._differences_named = True

    def _take_command(self, key: str, payload: bytes) -> None:
        sender, _ = self.keys.member_of(key)
        command = self.intake.decode_addressed(
            key, payload, Command, field="fish_id", owner=int(sender)
        )
        if command is not None:
            # A robot's LEDs are its own, whatever tick its command answers: the cameras of
            # the other robots see them so from now on.
            light = FLASHING if command.flashing else STEADY if command.led else DARK
            if light == STEADY:
                self._lights.pop(command.fish_id, None)
            else:
                self._lights[command.fish_id] = light
            self._accept(
                key,
                command.tick,
                np.array([command.fish_id], dtype=np.int64),
                command.fins[None],
                [command.broadcasts],
                # A watchdog's stop repeats the fish's last tick: a second answer, no twin's.
                twins=not command.watchdog,
            )

    def _take_batch(self, key: str, payload: bytes) -> None:
        batch = self.intake.decode(key, payload, CommandBatch)
        if batch is None:
            return
        if not self.roster.all_on(key, batch.ids):
            self.intake.refuse(
                key,
                "misaddressed",
                f"fish {ids_text(batch.ids.tolist())} are not all of this school",
            )
            return
        # A watchdog's stop repeats the school's last tick: a second answer, no twin's.
        self._accept(
            key, batch.tick, batch.ids, batch.fins, batch.broadcasts, twins=not batch.watchdog
        )

    def _accept(
        self,
        key: str,
        tick: int,
        ids: IntArray,
        fins: FloatArray,
        broadcasts: ArrayLike,
        *,
        twins: bool = True,
    ) -> None:
        """Take the commands of fish ``ids`` (distinct) for ``tick``, unless late or stale;
        with ``twins``, a second answer to a tick is taken for another process's."""
        current = self._current
        if self.scenario.time_mode == "realtime" and tick < current.tick:
            # A command for a tick already integrated came late: normal in realtime mode
            # (counted in late_commands when its tick closed), not bad input.
            return
        rows = current.rows_awaited(ids) if tick == current.tick else None
        if rows is None:
            # A second answer to this tick, or to the one just closed (a slower twin's).
            answers = {current.tick: current, self._previous.tick: self._previous}.get(tick)
            twice = answers.answered_before(ids) if twins and answers is not None else []
            if twice:
                self.intake.refuse(key, "duplicate", f"a second answer to tick {tick}")
                self._warn_of_twins(twice, tick)
                return
            self.intake.refuse(key, "stale", f"commands for tick {tick} at {current.tick}")
            return
        current.take(rows, fins, broadcasts)

    def _warn_of_twins(self, fish_ids: list[int], tick: int) -> None:
        """Say, once for each fish, that two processes answer for it: its first answer of
        a tick counts, the other's moves nothing, and the run is not what either decided."""
        new = [fish_id for fish_id in fish_ids if fish_id not in self._twins]
        if not new:
            return
        self._twins.update(new)
        log.warning(
            "fish %s answered tick %d twice: two processes serve %s (robots, or 'fishswarm "
            "fish', started with one --id?); the first answer of each tick counts: give each "
            "process its own ids",
            ids_text(new),
            tick,
            "it" if len(new) == 1 else "them",
        )

    def explain_loss(self, fish_ids: Iterable[int], reason: str) -> None:
        """Say why fish leave or left: their process failed (``reason``, e.g. ``failed:
        BehaviorError``), as the roster then records it (:meth:`Roster.explain_loss`)."""
        self.roster.explain_loss(fish_ids, reason)

    def _lose(self, fish_id: int, reason: str) -> None:
        self._lights.pop(fish_id, None)
        if self.roster.mark_lost(fish_id, self.tick, reason, trio.current_time()):
            self._leaving.add(fish_id)
        self._current.give_up(fish_id)

    def _leave(self) -> None:
        """Lost fish leave the world."""
        if self._leaving:
            self.sim.leave(sorted(self._leaving))
            self._leaving.clear()

    def _admit(self, tick: int) -> None:
        """Fish that came up (and whose commands are subscribed) enter the world now, at
        ``tick``."""
        present = set(self.sim.ids.tolist())
        new = self.roster.ready(present, trio.current_time(), self.settings.admit_delay)
        admissible = self._admissible()
        new = [fish_id for fish_id in new if fish_id in admissible]
        if not new:
            return
        if tick > 0:
            lost_at = {lost.fish_id: lost.tick for lost in self.lost}
            for fish_id in new:
                self.joined.append((fish_id, tick))
                if fish_id in lost_at:
                    # Said as loudly as its loss: a robot that surfaced and came back.
                    log.warning("fish %d back at tick %d (lost at tick %d)", fish_id, tick,
                                lost_at[fish_id])  # fmt: skip
                else:
                    log.info("fish %d joined at tick %d", fish_id, tick)
        expected = self.settings.expected_fish
        unexpected = sorted(set(new).difference(expected, self.unexpected))
        if unexpected:
            # Robots join a run by design; fish processes of an earlier, larger run left up
            # on the swarm join it as well, and the run is then not the scenario's.
            self.unexpected.update(unexpected)
            log.warning(
                "fish %s, up on swarm %r beyond the %d fish of this world's scenario (%s), "
                "join its run at tick %d: stop them, or give this run another --swarm, to run "
                "without them",
                ids_text(unexpected),
                self.scenario.swarm,
                len(expected),
                ids_text(sorted(expected)),
                tick,
            )
        self.sim.join(new)


def _warn_of_difference(ids: list[int], difference: str) -> None:
    """Say that fish ``ids`` run with a setting other than this world's (``difference``)."""
    log.warning("fish %s %s (started with other settings?)", ids_text(ids), difference)


PARTS_NAMED = 4
"""Most differing parameters a warning names; it counts the rest."""


def _parts_named(ours: dict[str, str], theirs: dict[str, str]) -> str:
    """Which decision parameters a fish's fingerprints (``theirs``) differ in from this
    world's, said for a warning: ``"their count differs; "``, empty when none can be named
    (the digests differ, their parts not)."""
    names = differing_parts(ours, theirs)
    if not names:
        return ""
    shown = names[:PARTS_NAMED]
    if len(names) > len(shown):
        listed = f"{', '.join(shown)} and {len(names) - len(shown)} more"
    elif len(shown) > 1:
        listed = f"{', '.join(shown[:-1])} and {shown[-1]}"
    else:
        listed = shown[0]
    verb = "differs" if len(names) == 1 else "differ"
    return f"their {listed} {verb}; "


def _quantile(values: list[float], share: float) -> float:
    """The ``share`` quantile of ``values`` (0 when there are none)."""
    return float(np.quantile(values, share)) if values else 0.0
