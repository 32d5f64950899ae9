"""The world actor with fish, channel and observer on the in-memory Bus under trio's
MockClock: the tick barrier, lost and late fish, control, realtime pacing, broadcasts —
and the same trajectories as the batch engine."""

from __future__ import annotations

import collections
import contextlib
import logging
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from contextlib import asynccontextmanager
from typing import Any, cast

import numpy as np
import pytest
import trio

from fishswarm import __version__
from fishswarm.actors.bus import Declared, MemoryBus, open_token
from fishswarm.actors.channel import Channel
from fishswarm.actors.fish import Fish, FishSettings
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.observer import Observer
from fishswarm.actors.world import MISMATCH_NAMED, StartTimeout, World, WorldSettings
from fishswarm.bluebot.vision import to_body
from fishswarm.protocols import codec
from fishswarm.protocols.codec import decode, encode
from fishswarm.protocols.messages import (
    DARK,
    FLASHING,
    FORMATION_SHAPES,
    STEADY,
    Broadcast,
    Command,
    CommandBatch,
    ControlReply,
    ControlRequest,
    Delivery,
    FishAbout,
    FormationFlag,
    Message,
    Perception,
    PerceptionBatch,
    Snapshot,
    WorldPulse,
)
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario
from tests.behaviors.signal_behavior import registered
from tests.conftest import run_mock, subscription


async def _swarm(scenario: Scenario, *, schools: int) -> tuple[World, list[Snapshot]]:
    """Run a whole swarm in this process on a MemoryBus to the end of its scenario: the
    world, the channel, and the fish spread over ``schools`` fish actors (a school each, or
    a fish on its own keys)."""
    bus = MemoryBus()
    world = World(WorldSettings(scenario, expected_fish=tuple(range(scenario.fish))))
    params = scenario.fish_params()
    ids = list(range(scenario.fish))
    async with (
        subscription(bus, scenario.keys.snapshot) as snapshots,
        trio.open_nursery() as nursery,
    ):
        await nursery.start(Channel(scenario).run, bus)
        for n in range(min(schools, len(ids))):
            group = tuple(ids[n::schools])
            school = f"s{n}" if len(group) > 1 else None
            fish = Fish(FishSettings(group, params, scenario.keys, school=school))
            await nursery.start(fish.run, bus)
        await world.run(bus)
        nursery.cancel_scope.cancel()
    return world, [decode(payload, Snapshot) for _, payload in snapshots.drain()]


@pytest.mark.parametrize(
    "changes",
    [
        {"behavior": "aggregation"},
        {"behavior": "milling", "controller": "pid"},
        {"behavior": "waltz", "fish": 2},
        {"behavior": "dispersion", "time_mode": "jitter", "vision_noise": 0.05},
        {"behavior": "aggregation", "profile": "study-code"},
        {"behavior": "dispersion", "profile": "study-code", "time_mode": "jitter"},
        {
            "behavior": "formation",
            "formation": "pyramid",
            "switch_formation": "diamond",
            "switch_at": 3.0,
            "controller": "pid",
            "spawn_radius": 0.4,
            "spacing": 0.25,
        },
        {
            # A formation in jitter mode (without flags: not delivered in this mode).
            "behavior": "formation",
            "formation": "column",
            "time_mode": "jitter",
            "flags": False,
            "controller": "pid",
            "spawn_radius": 0.3,
            "spacing": 0.25,
        },
        {
            # Flags flowing, a fifth of them lost, efforts in them.
            "behavior": "formation",
            "formation": "column",
            "channel_loss": 0.2,
            "controller": "pid",
            "spawn_radius": 0.3,
            "spacing": 0.25,
            "rotate_effort": True,
            "effort_margin": 1.0,
        },
        {
            # Flags by light: only "I hold my place", to the fish that see the sender. They
            # change no trajectory (test_medium.py); here the channel's reports of them
            # must match what it delivers, or the fish would wait for them.
            "behavior": "formation",
            "formation": "column",
            "flag_medium": "light",
            "channel_loss": 0.2,
            "controller": "pid",
            "spawn_radius": 0.3,
            "spacing": 0.25,
        },
        {
            # Flags by beacon: that one bit to every fish within range, a fifth of them lost
            # (it changes the trajectory: test_medium.py).
            "behavior": "formation",
            "formation": "column",
            "flag_medium": "beacon",
            "channel_loss": 0.2,
            "controller": "pid",
            "spawn_radius": 0.3,
            "spacing": 0.25,
        },
    ],
)
def test_the_actors_give_the_batch_engines_trajectory(changes: dict[str, object]) -> None:
    scenario = Scenario(fish=7, duration=6.0, seed=5).replace(**changes)
    world, snapshots = run_mock(lambda: _swarm(scenario, schools=3))
    assert world.state_name == "finished" and world.lost == []
    reference = simulate_batch(scenario)
    np.testing.assert_array_equal(np.array([s.position for s in snapshots]), reference.position)
    np.testing.assert_array_equal(np.array([s.yaw for s in snapshots]), reference.yaw)
    # Each snapshot names the shape the fish are told to take once the scenario switches.
    switched = scenario.switch_formation
    assert [s.formation for s in snapshots] == [
        switched if switched is not None and s.time >= scenario.switch_at else None
        for s in snapshots
    ]
    if switched is not None:
        assert snapshots[-1].formation == switched
    assert {s.run for s in snapshots} == {world.run_id}  # as its perceptions carry it


OTHER_WORLD = (
    "stop it ('fishswarm control stop --swarm default'), or give this run another swarm name "
    "(--swarm). If 'fishswarm control status' finds no world there, a client that is not a "
    "world shows its token (in a secured swarm any certificate can: README, 'Securing a swarm')"
)
"""How a world that waited for another for all of its start timeout says what to do."""


def test_a_tick_in_one_process_hands_its_messages_over_instead_of_decoding_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # One school beside the world and the channel, as in the launcher's process: the
    # school's perception batches, its command batches and the snapshots the channel reads
    # are the messages their senders built.
    handed: collections.Counter[tuple[str, bool]] = collections.Counter()
    look_up = codec._reused_message

    def counted(payload: bytes, expected: type[Message]) -> Message | None:
        message = look_up(payload, expected)
        handed[expected.__name__, message is not None] += 1
        return message

    monkeypatch.setattr(codec, "_reused_message", counted)
    scenario = Scenario(fish=6, duration=4.0, seed=2, behavior="aggregation")
    world, snapshots = run_mock(lambda: _swarm(scenario, schools=1))
    assert world.state_name == "finished" and world.lost == []
    ticks = len(snapshots)
    assert handed["PerceptionBatch", True] == ticks - 1  # the last snapshot asks for nothing
    assert handed["CommandBatch", True] == ticks - 1
    assert handed["Snapshot", True] >= ticks  # the channel's (and this test's own reading)
    assert handed["PerceptionBatch", False] == handed["CommandBatch", False] == 0
    reference = simulate_batch(scenario)
    np.testing.assert_array_equal(np.array([s.position for s in snapshots]), reference.position)


def test_schools_whose_perceptions_come_in_parts_decide_as_with_one_batch(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Batches cut at 12 rows: a school of 7 aggregating fish gets its perception in several
    # parts a tick, decides each as it comes, and the run is the batch engine's.
    from fishswarm.actors import perceptions

    cut = perceptions.perception_messages
    parts: list[int] = []

    def small_parts(*args: object, **kwargs: object) -> list[tuple[str, object]]:
        messages = cut(*args, row_limit=12, **kwargs)  # type: ignore[arg-type]
        parts.append(len(messages))
        return messages  # type: ignore[return-value]

    monkeypatch.setattr("fishswarm.actors.world.perception_messages", small_parts)
    scenario = Scenario(fish=14, duration=5.0, seed=3, behavior="aggregation")
    world, snapshots = run_mock(lambda: _swarm(scenario, schools=2))
    assert world.state_name == "finished" and world.lost == []
    assert max(parts) > 2  # more than one part for a school of 7
    reference = simulate_batch(scenario)
    np.testing.assert_array_equal(np.array([s.position for s in snapshots]), reference.position)


def test_broadcasts_decided_at_a_tick_are_heard_at_the_next_and_match_the_batch_engine() -> None:
    behavior = registered().name
    scenario = Scenario(fish=5, duration=5.0, seed=2, behavior=behavior, channel_loss=0.3)

    async def main() -> tuple[list[Snapshot], list[Delivery], World, Channel]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=tuple(range(5))))
        medium = Channel(scenario)
        params = scenario.fish_params()
        async with (
            subscription(bus, scenario.keys.snapshot) as snapshots,
            subscription(bus, f"{scenario.keys.prefix}/fish/*/inbox") as inboxes,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(medium.run, bus)
            await nursery.start(
                Fish(FishSettings((0, 1, 2), params, scenario.keys, school="a")).run, bus
            )
            for fish_id in (3, 4):
                await nursery.start(Fish(FishSettings((fish_id,), params, scenario.keys)).run, bus)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return (
            [decode(p, Snapshot) for _, p in snapshots.drain()],
            [decode(p, Delivery) for _, p in inboxes.drain()],
            world,
            medium,
        )

    snapshots, deliveries, world, medium = run_mock(main)
    positions = np.array([s.position for s in snapshots])
    np.testing.assert_array_equal(positions, simulate_batch(scenario).position)
    # Every fish broadcasts at every decision (ticks 0–4); each is heard at the next tick.
    assert [s.broadcasts.tolist() for s in snapshots] == [[0] * 5] + [[1] * 5] * 5
    # The channel delivers at every snapshot after one with broadcasts; the last one (tick 5,
    # which nobody acts on) only if it gets to it before the run is torn down.
    acted_on = [d for d in deliveries if d.tick < 5]
    assert sorted({d.tick for d in acted_on}) == [1, 2, 3, 4]
    assert all(d.values[1] == d.tick - 1 for d in deliveries)  # sent at the tick before
    # 5 senders × 4 others × 4 ticks, all in range, about 30 % lost (seeded).
    assert 40 <= len(acted_on) < 80
    assert medium.statistics().delivered == len(deliveries)
    assert medium.statistics().missing_broadcasts == 0
    assert world.statistics().rejected_total == 0


class LosingBus:
    """A MemoryBus that loses one put: the first on ``lost_key`` after ``after`` of them."""

    def __init__(self, lost_key: str, *, after: int) -> None:
        self._bus = MemoryBus()
        self._lost_key = lost_key
        self._left = after
        self.lost = 0
        self.subscribe = self._bus.subscribe
        self.declare_token = self._bus.declare_token
        self.watch_alive = self._bus.watch_alive

    def put(self, key: str, payload: bytes) -> None:
        if key == self._lost_key and not self.lost:
            if self._left == 0:
                self.lost = 1
                return
            self._left -= 1
        self._bus.put(key, payload)


def test_a_broadcast_lost_on_the_way_costs_its_deliveries_not_the_tick(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # Fish 4's broadcast of tick 1 never reaches the channel. The channel gives up on it
    # before the world gives up on the channel, so tick 2 still has its report: the other
    # four broadcasts are delivered, announced and waited for, and nobody is lost.
    behavior = registered().name
    scenario = Scenario(fish=5, duration=4.0, seed=2, behavior=behavior)

    async def main() -> tuple[list[Delivery], World, Channel, LosingBus]:
        bus = LosingBus(scenario.keys.outbox(4), after=1)
        world = World(WorldSettings(scenario, expected_fish=tuple(range(5))))
        medium = Channel(scenario)
        params = scenario.fish_params()
        async with (
            subscription(bus, f"{scenario.keys.prefix}/fish/*/inbox") as inboxes,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(medium.run, bus)
            for fish_id in range(5):
                await nursery.start(Fish(FishSettings((fish_id,), params, scenario.keys)).run, bus)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return [decode(p, Delivery) for _, p in inboxes.drain()], world, medium, bus

    with caplog.at_level("WARNING"):
        deliveries, world, medium, bus = run_mock(main)
    assert bus.lost == 1
    assert medium.statistics().missing_broadcasts == 1
    assert "no channel report" not in caplog.text
    at_two = [d for d in deliveries if d.tick == 2]
    # Four senders, each heard by the four others (all in range, no loss): fish 4 hears
    # all four, every other fish the three senders besides itself.
    heard = [sum(d.receiver_id == fish_id for d in at_two) for fish_id in range(5)]
    assert heard == [3, 3, 3, 3, 4]
    assert world.lost == [] and world.statistics().rejected_total == 0


@pytest.mark.parametrize("broadcasting", [False, True])
def test_a_snapshot_goes_out_while_the_fish_decide_unless_the_channel_needs_it_first(
    broadcasting: bool,
) -> None:
    behavior = registered().name if broadcasting else "aggregation"
    scenario = Scenario(fish=3, duration=4.0, seed=2, behavior=behavior)
    keys = scenario.keys

    async def main() -> list[tuple[str, int]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2)))
        sent: list[tuple[str, int]] = []
        bus.subscribe(
            keys.snapshot, lambda k, p: sent.append(("snapshot", decode(p, Snapshot).tick))
        )
        bus.subscribe(
            keys.perception(0), lambda k, p: sent.append(("perception", decode(p, Perception).tick))
        )
        async with trio.open_nursery() as nursery:
            await nursery.start(Channel(scenario).run, bus)
            for fish_id in range(3):
                settings = FishSettings((fish_id,), scenario.fish_params(), keys)
                await nursery.start(Fish(settings).run, bus)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return sent

    sent = run_mock(main)
    if broadcasting:
        # From tick 1 on the channel delivers what the snapshot announces before the fish
        # perceive: the snapshot leads.
        expected = [("perception", 0), ("snapshot", 0)]
        for tick in range(1, 4):
            expected += [("snapshot", tick), ("perception", tick)]
    else:
        expected = []
        for tick in range(4):
            expected += [("perception", tick), ("snapshot", tick)]
    assert sent == [*expected, ("snapshot", 4)]  # the last one ends the run


def test_the_world_waits_for_a_slow_fish_at_every_tick() -> None:
    scenario = Scenario(fish=1, duration=3.0, seed=1)
    keys = scenario.keys

    async def main() -> list[float]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0, turn_delay=0.0))
        started = trio.current_time()
        snapshot_times: list[float] = []
        bus.subscribe(keys.snapshot, lambda k, p: snapshot_times.append(trio.current_time()))
        async with (
            subscription(bus, keys.perception(0)) as perceptions,
            open_token(bus, keys.alive("fish", 0)),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(world.run, bus)
            for _ in range(3):
                perception = decode((await perceptions.receive())[1], Perception)
                await trio.sleep(4.0)  # a fish that takes 4 s to decide
                command = Command(0, perception.tick, np.array([1.0, 0.0, 0.0, 0.0]))
                bus.put(keys.command(0), encode(command))
        return [at - started for at in snapshot_times]

    # Snapshots were taken as the world moved on: tick k+1 only after the answer to tick k.
    assert run_mock(main) == [0.0, 4.0, 8.0, 12.0]


def test_fish_up_beyond_the_scenarios_ids_join_the_run_and_are_named(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # A user's run of 1 fish on a swarm where an earlier run's fish 0 and 1 are still up:
    # both take part (robots join runs so), and the world says so and counts the extra one.
    scenario = Scenario(fish=1, duration=2.0, seed=1)
    keys = scenario.keys
    settings = WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0, turn_delay=0.0)
    world = World(settings)
    told: list[tuple[list[int], list[int] | None]] = []

    async def main() -> None:
        async with two_fish_world(settings, told, world) as (bus, first, second):
            for _ in range(2):
                for fish_id, perceptions in ((0, first), (1, second)):
                    perception = decode((await perceptions.receive())[1], Perception)
                    off = Command(fish_id, perception.tick, np.zeros(4))
                    bus.put(keys.command(fish_id), encode(off))
            with trio.fail_after(5):
                while world.state_name != "finished":
                    await trio.sleep(0.1)

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        run_mock(main)
    assert [ids for ids, _ in told] == [[0, 1], [0, 1], [0, 1]]
    assert world.statistics().unexpected_fish == 1
    said = [r.getMessage() for r in caplog.records if "beyond" in r.getMessage()]
    assert said == [
        "fish 1, up on swarm 'default' beyond the 1 fish of this world's scenario (0), join "
        "its run at tick 0: stop them, or give this run another --swarm, to run without them"
    ]


@asynccontextmanager
async def two_fish_world(
    settings: WorldSettings,
    told: list[tuple[list[int], list[int] | None]],
    world: World | None = None,
) -> AsyncIterator[tuple[MemoryBus, Inbox[tuple[str, bytes]], Inbox[tuple[str, bytes]]]]:
    """The world of ``settings`` (``world``, when the test keeps it) running with fish 0
    and 1 up, on an in-memory Bus; each snapshot's ids and lights noted in ``told``. The
    Bus and the two fish's perceptions."""
    bus = MemoryBus()
    keys = settings.scenario.keys

    def take(key: str, payload: bytes) -> None:
        snapshot = decode(payload, Snapshot)
        lights = snapshot.lights
        told.append((snapshot.ids.tolist(), None if lights is None else lights.tolist()))

    bus.subscribe(keys.snapshot, take)
    async with (
        subscription(bus, keys.perception(0)) as first,
        subscription(bus, keys.perception(1)) as second,
        open_token(bus, keys.alive("fish", 0)),
        open_token(bus, keys.alive("fish", 1)),
        trio.open_nursery() as nursery,
    ):
        nursery.start_soon((World(settings) if world is None else world).run, bus)
        yield bus, first, second
        nursery.cancel_scope.cancel()


def test_the_snapshot_tells_the_leds_of_robots_whose_commands_say_they_flash_or_are_dark() -> None:
    """A robot's LEDs are its own: the world tells them from its command that says so until
    one that says otherwise, whatever tick the command answers, so that other robots'
    cameras show them; with every fish's steady the snapshot says nothing of them."""
    scenario = Scenario(fish=2, duration=5.0, seed=1)
    keys = scenario.keys
    settings = WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0, turn_delay=0.0)
    told: list[tuple[list[int], list[int] | None]] = []

    async def main() -> None:
        async with two_fish_world(settings, told) as (bus, first, second):
            # Fish 1 flashes at ticks 1 and 2, goes dark at tick 3, steady at tick 4.
            for led, flashing in ((True, None), (True, True), (True, True), (False, None),
                                  (True, None)):  # fmt: skip
                for fish, perceptions in ((0, first), (1, second)):
                    tick = decode((await perceptions.receive())[1], Perception).tick
                    said = (led, flashing) if fish == 1 else (True, None)
                    command = Command(fish, tick, np.zeros(4), led=said[0], flashing=said[1])
                    bus.put(keys.command(fish), encode(command))
            await trio.sleep(0.01)

    run_mock(main)
    lights = [said for _, said in told]
    assert lights[:6] == [None, None, [STEADY, FLASHING], [STEADY, FLASHING], [STEADY, DARK], None]


@pytest.mark.parametrize("robots", [(), (1,), (0, 1)])
def test_a_simulated_fish_that_sees_a_flashing_robot_waits_for_its_flag(
    robots: tuple[int, ...],
) -> None:
    """Fish 0 simulated, fish 1 a robot whose fish holds its place (its command says its
    LEDs flash) and which fish 0 sees: the world announces the robot's light to the
    channel, waits for the channel's report, and tells fish 0 in its next perception that
    one delivery comes; the channel delivers it, a formation flag from where fish 0 sees
    fish 1. Whether the robot shows its driver's token or not; but when fish 0 is a robot
    too (``robots`` (0, 1)) its cameras see the flashes, and nothing is announced."""
    scenario = Scenario(fish=2, behavior="formation", duration=5.0, seed=1, spawn_radius=0.3)
    keys = scenario.keys
    settings = WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0, turn_delay=0.0)
    snapshots: list[Snapshot] = []
    reports: list[bytes] = []
    order: list[str] = []

    async def main() -> tuple[list[int], list[Delivery], float]:
        bus = MemoryBus()
        bus.subscribe(keys.snapshot, lambda _, payload: snapshots.append(decode(payload, Snapshot)))
        bus.subscribe(keys.channel_report, lambda _, payload: reports.append(payload))
        bus.subscribe(keys.snapshot, lambda _, payload: order.append("snapshot"))
        bus.subscribe(keys.perception(0), lambda _, payload: order.append("perception"))
        started = trio.current_time()
        counts: list[int] = []
        async with (
            subscription(bus, keys.perception(0)) as first,
            subscription(bus, keys.perception(1)) as second,
            subscription(bus, keys.inbox(0)) as inbox,
            open_token(bus, keys.alive("fish", 0)),
            open_token(bus, keys.alive("fish", 1)),
            contextlib.AsyncExitStack() as stack,
            trio.open_nursery() as nursery,
        ):
            for robot in robots:
                await stack.enter_async_context(open_token(bus, keys.alive("robot", robot)))
            await nursery.start(Channel(scenario).run, bus)
            nursery.start_soon(World(settings).run, bus)
            for _ in range(3):
                perception = decode((await first.receive())[1], Perception)
                counts.append(perception.inbox_count)
                bus.put(keys.command(0), encode(Command(0, perception.tick, np.zeros(4))))
                tick = decode((await second.receive())[1], Perception).tick
                flashes = Command(1, tick, np.zeros(4), led=True, flashing=True)
                bus.put(keys.command(1), encode(flashes))
            nursery.cancel_scope.cancel()
        delivered = [decode(payload, Delivery) for _, payload in inbox.drain()]
        return counts, delivered, trio.current_time() - started

    counts, deliveries, took = run_mock(main)
    assert took < 1.0  # no wait for a channel report that does not come (6 s each)
    assert len(reports) == 2  # ticks 1 and 2, where the robot flashed
    # Tick 1: a world that waits for the channel sends its snapshot before the
    # perceptions; one of robots only sends it while they decide.
    tick_1 = order[2:4]
    if robots == (0, 1):
        assert counts == [0, 0, 0] and deliveries == []
        assert tick_1 == ["perception", "snapshot"]
        return
    assert tick_1 == ["snapshot", "perception"]
    # The robot's first command (answering tick 0) makes its LEDs flash from tick 1 on.
    assert counts == [0, 1, 1]
    first = snapshots[1]
    assert first.lights is not None and first.lights.tolist() == [STEADY, FLASHING]
    told = [(d.receiver_id, d.tick, d.kind) for d in deliveries]
    assert told == [(0, 1, "formation"), (0, 2, "formation")]
    flag = FormationFlag.from_values(deliveries[0].values)
    assert flag.joined and flag.slot == -1 and flag.shape == FORMATION_SHAPES.index("pyramid")
    seen = to_body((first.position[1] - first.position[0])[None, None], first.yaw[:1])[0, 0]
    np.testing.assert_allclose(deliveries[0].sender_position, seen, atol=1e-9)


def test_the_snapshot_tells_each_robots_leds_whatever_order_their_commands_came_in() -> None:
    """Three robots: robot 2 starts flashing at tick 1, robot 0 goes dark at tick 2 (a
    later command for a lower id): the snapshot tells each its own, in the rows of its
    ids."""
    scenario = Scenario(fish=3, duration=5.0, seed=1)
    keys = scenario.keys
    said: dict[int, dict[int, tuple[bool, bool | None]]] = {
        1: {2: (True, True)},
        2: {0: (False, None), 2: (True, True)},
    }

    async def main() -> list[list[int] | None]:
        bus = MemoryBus()
        world = World(
            WorldSettings(scenario, expected_fish=(0, 1, 2), admit_delay=0.0, turn_delay=0.0)
        )
        told: list[list[int] | None] = []

        def take(key: str, payload: bytes) -> None:
            lights = decode(payload, Snapshot).lights
            told.append(None if lights is None else lights.tolist())

        bus.subscribe(keys.snapshot, take)
        async with contextlib.AsyncExitStack() as stack:
            perceptions = [
                await stack.enter_async_context(subscription(bus, keys.perception(fish)))
                for fish in range(3)
            ]
            for fish in range(3):
                await stack.enter_async_context(open_token(bus, keys.alive("fish", fish)))
            nursery = await stack.enter_async_context(trio.open_nursery())
            nursery.start_soon(world.run, bus)
            for step in range(3):
                for fish in range(3):
                    tick = decode((await perceptions[fish].receive())[1], Perception).tick
                    led, flashing = said.get(step, {}).get(fish, (True, None))
                    command = Command(fish, tick, np.zeros(4), led=led, flashing=flashing)
                    bus.put(keys.command(fish), encode(command))
            await trio.sleep(0.01)
            nursery.cancel_scope.cancel()
        return told

    told = run_mock(main)
    assert told[2] == [STEADY, STEADY, FLASHING]
    assert told[3] == [DARK, STEADY, FLASHING]


def test_a_lost_robots_leds_are_forgotten() -> None:
    """Robot 1 flashes, then falls silent and is lost: the world forgets its LEDs with it,
    so that its snapshots say nothing of them again (every fish left is steady), and a
    robot that comes back under its id is not shown flashing before it says so."""
    scenario = Scenario(fish=2, duration=5.0, seed=1)
    keys = scenario.keys
    settings = WorldSettings(
        scenario, expected_fish=(0, 1), admit_delay=0.0, turn_delay=0.0, command_timeout=1.0
    )
    told: list[tuple[list[int], list[int] | None]] = []

    async def main() -> None:
        async with two_fish_world(settings, told) as (bus, first, second):
            # Robot 1 steady at tick 0, flashing at tick 1, silent from tick 2 on.
            for step in range(4):
                for fish, perceptions in ((0, first), (1, second)):
                    if fish == 1 and step >= 2:
                        continue
                    tick = decode((await perceptions.receive())[1], Perception).tick
                    flashing = True if fish == 1 and step == 1 else None
                    command = Command(fish, tick, np.zeros(4), flashing=flashing)
                    bus.put(keys.command(fish), encode(command))
            await trio.sleep(0.01)

    run_mock(main)
    assert told[2] == ([0, 1], [STEADY, FLASHING])
    gone = [lights for ids, lights in told if ids == [0]]
    assert gone and gone == [None] * len(gone)


def test_a_schools_commands_are_taken_only_for_its_own_awaited_fish() -> None:
    # School "t" holds fish 0, 1 and 2; fish 3 is on its own keys. At tick 0 the school
    # sends a batch naming fish 3 (misaddressed), one for tick 1 (stale), fish 0 and 2
    # (taken), fish 2 again (a duplicate: answered already), then fish 1 (taken): the world
    # moves on to tick 1 holding the fins of the batches it took, row by row.
    scenario = Scenario(fish=4, duration=1.0, seed=2, behavior="aggregation")
    keys = scenario.keys

    def batch(tick: int, ids: list[int], gains: list[float]) -> bytes:
        fins = np.zeros((len(ids), 4))
        fins[:, 0] = gains  # caudal only
        return encode(
            CommandBatch(
                tick,
                np.array(ids),
                fins,
                np.zeros(len(ids), dtype=bool),
                np.zeros(len(ids), dtype=np.int64),
            )
        )

    async def main() -> tuple[World, Snapshot]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2, 3), admit_delay=0.0))
        async with (
            subscription(bus, keys.school_perceptions("t")) as school,
            subscription(bus, keys.perception(3)) as alone,
            subscription(bus, keys.snapshot) as snapshots,
            open_token(bus, keys.alive("fish", 0, "t")),
            open_token(bus, keys.alive("fish", 1, "t")),
            open_token(bus, keys.alive("fish", 2, "t")),
            open_token(bus, keys.alive("fish", 3)),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(world.run, bus)
            perceived = decode((await school.receive())[1], PerceptionBatch)
            assert perceived.ids.tolist() == [0, 1, 2]
            await alone.receive()
            to_world = keys.school_commands("t")
            bus.put(to_world, batch(0, [2, 3], [0.5, 0.5]))
            bus.put(to_world, batch(1, [0, 1, 2], [0.5, 0.5, 0.5]))
            bus.put(to_world, batch(0, [0, 2], [0.2, 0.6]))
            bus.put(to_world, batch(0, [2], [1.0]))
            bus.put(to_world, batch(0, [1], [0.4]))
            bus.put(keys.command(3), encode(Command(3, 0, np.zeros(4))))
            while world.state_name != "finished":
                await trio.sleep(0.1)
            nursery.cancel_scope.cancel()
        return world, decode(snapshots.drain()[-1][1], Snapshot)

    world, last = run_mock(main)
    assert world.statistics().rejected == {"misaddressed": 1, "stale": 1, "duplicate": 1}
    assert world.lost == []
    np.testing.assert_array_equal(world.sim.fins[:, 0], [0.2, 0.4, 0.6, 0.0])
    assert last.tick == 1


def test_silent_and_departed_fish_are_lost_and_the_run_goes_on() -> None:
    scenario = Scenario(fish=3, duration=20.0, seed=1)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2), command_timeout=10.0))
        observer = Observer(keys)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0,), params, keys)).run, bus)
            departing = trio.CancelScope()

            async def fish_that_leaves() -> None:
                with departing:
                    await Fish(FishSettings((1,), params, keys)).run(bus)

            nursery.start_soon(fish_that_leaves)
            silent = bus.declare_token(keys.alive("fish", 2))  # alive, never answers
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(5)  # fish 2 was lost at tick 0, 10 s in
            departing.cancel()
            while world.state_name != "finished":
                await trio.sleep(1.0)
            silent.undeclare()
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    assert world.tick == 20
    lost = {f.fish_id: (f.tick, f.reason) for f in world.lost}
    assert lost[2] == (0, "no command within 10 s")
    # It left after the observer saw tick 5, while the world was at tick 5 or 6.
    assert lost[1][0] in (5, 6) and lost[1][1] == "left (liveliness token gone)"
    assert world.statistics().live_fish == 1


def test_a_late_fish_joins_at_a_later_tick() -> None:
    scenario = Scenario(fish=3, duration=8.0, seed=4)
    keys = scenario.keys

    async def main() -> tuple[World, list[int]]:
        bus = MemoryBus()
        # In lockstep on a MockClock no time passes between ticks: admit at once.
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2), admit_delay=0.0))
        observer = Observer(keys)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0, 1, 2), params, keys, school="t")).run, bus)
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(3)
            await nursery.start(Fish(FishSettings((9,), params, keys)).run, bus)
            await observer.wait_for_tick(8)
            nursery.cancel_scope.cancel()
        return world, [p.fish for p in observer.history]

    world, counts = run_mock(main)
    # It came up after the observer saw tick 3, while the world was at tick 3 or 4 (trio
    # schedules ready tasks in no fixed order): it enters at the next snapshot.
    assert len(world.joined) == 1 and world.joined[0][0] == 9
    joined_tick = world.joined[0][1]
    assert joined_tick in (4, 5)
    assert counts[:joined_tick] == [3] * joined_tick
    assert counts[joined_tick:] == [4] * (9 - joined_tick)  # in the snapshot it joined at


def test_the_broadcasts_of_a_fish_that_joined_are_counted_too() -> None:
    # Every fish of the tests' signal behaviour broadcasts at every decision; the world
    # counts what the commands it holds say, a late fish's too (the launcher's summary
    # once counted only its own fish's).
    from tests.behaviors.signal_behavior import registered

    scenario = Scenario(fish=3, duration=6.0, seed=4, behavior=registered().name)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2), admit_delay=0.0))
        observer = Observer(keys)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Channel(scenario).run, bus)
            await nursery.start(Fish(FishSettings((0, 1, 2), params, keys, school="t")).run, bus)
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(2)
            await nursery.start(Fish(FishSettings((9,), params, keys)).run, bus)
            await observer.wait_for_tick(6)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    joined = world.joined[0][1]
    # Decisions at ticks 0–5: three fish at each, fish 9 from the tick it joined at.
    assert world.statistics().broadcasts == 3 * 6 + (6 - joined)


def test_broadcasts_without_a_channel_are_warned_of_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    from tests.behaviors.signal_behavior import registered

    scenario = Scenario(fish=2, duration=5.0, seed=4, behavior=registered().name)

    async def main() -> None:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        observer = Observer(scenario.keys)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0, 1), params, scenario.keys)).run, bus)
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(5)
            nursery.cancel_scope.cancel()

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        run_mock(main)
    # Broadcasts at ticks 1-4, no channel: said once, not at every tick.
    assert caplog.text.count("no channel is running") == 1


Ask = Callable[[str], None]


async def _under_control(
    scenario: Scenario, script: Callable[[Ask, Observer, World], Awaitable[None]]
) -> tuple[list[tuple[str, int]], World]:
    """A world and its fish on the in-memory Bus, ``script`` asking the world's control;
    its answers (state, tick) and the world."""
    bus = MemoryBus()
    fish = tuple(range(scenario.fish))
    world = World(WorldSettings(scenario, expected_fish=fish))
    observer = Observer(scenario.keys)
    answers = []

    def ask(action: str) -> None:
        reply = world.control(ControlRequest(action))
        answers.append((reply.state, reply.tick))

    async with trio.open_nursery() as nursery:
        await nursery.start(observer.run, bus)
        await nursery.start(
            Fish(FishSettings(fish, scenario.fish_params(), scenario.keys)).run, bus
        )
        nursery.start_soon(world.run, bus)
        await script(ask, observer, world)
        nursery.cancel_scope.cancel()
    return answers, world


def test_a_run_interrupted_while_paused_counts_its_pause() -> None:
    """Cancelled while paused (Ctrl-C in `fishswarm run`), the world still counts the
    pause so far: the run's real-time factor leaves it out (it counted it as running)."""

    async def script(ask: Ask, observer: Observer, world: World) -> None:
        await observer.wait_for_tick(2)
        ask("pause")
        await _until_state(world, "paused")
        await trio.sleep(50.0)

    _, world = run_mock(lambda: _under_control(Scenario(fish=2, duration=1000.0), script))
    assert world.state_name == "paused"
    assert 50.0 <= world.paused_time < 50.1  # from the snapshot it holds at


async def _until_state(world: World, state: str) -> None:
    with trio.fail_after(10.0):
        while world.state_name != state:
            await trio.sleep(0.01)


def test_control_pauses_resumes_and_stops_the_world() -> None:
    async def script(ask: Ask, observer: Observer, world: World) -> None:
        await observer.wait_for_tick(2)
        ask("pause")
        await trio.sleep(100.0)  # paused: no tick goes by, however long
        ask("status")
        ask("resume")
        await observer.wait_for_tick(5)
        ask("stop")
        await _until_state(world, "stopped")
        ask("status")

    answers, world = run_mock(lambda: _under_control(Scenario(fish=2, duration=1000.0), script))
    # Held from the snapshot of tick 3 until the resume, 100 s after the pause was asked.
    assert 99.0 < world.paused_time <= 100.0
    # Asked during tick 2, after its perceptions went out: the world is pausing, tick 2
    # completes, then the world holds after the snapshot of tick 3, for as long as it is
    # paused. Asked during tick 5, a stop ends the run at once, at the snapshot of tick 5.
    assert answers == [
        ("pausing", 2),
        ("paused", 3),
        ("running", 3),
        ("stopping", 5),
        ("stopped", 5),
    ]


def test_a_formation_switch_the_world_cannot_make_is_refused_with_why() -> None:
    world = World(WorldSettings(Scenario(fish=2, behavior="aggregation"), expected_fish=(0, 1)))
    reply = world.control(ControlRequest("formation", formation="diamond"))
    assert reply.refused == "the fish run aggregation, not a formation"
    forming = World(WorldSettings(Scenario(fish=2, behavior="formation"), expected_fish=(0, 1)))
    assert forming.control(ControlRequest("formation", formation="diamond")).refused is None
    forming.state_name = "finished"
    reply = forming.control(ControlRequest("formation", formation="column"))
    assert reply.refused == "the run has finished"
    # Other requests to an ended run only report its state, as before.
    assert forming.control(ControlRequest("stop")).refused is None


def test_realtime_keeps_wall_clock_pace_and_a_silent_fish_keeps_its_last_command() -> None:
    # One fish answered by hand: full caudal for ticks 0 and 1, then silence. In realtime
    # mode the world goes on at one tick per 0.1 s, the silent fish keeps swimming on its
    # last command, and nobody is lost.
    scenario = Scenario(fish=1, duration=1.2, control_period=0.1, time_mode="realtime", seed=3)
    keys = scenario.keys

    async def main() -> tuple[World, list[Snapshot], float]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.05))
        async with (
            subscription(bus, keys.perception(0)) as perceptions,
            subscription(bus, keys.snapshot) as snapshot_inbox,
            open_token(bus, keys.alive("fish", 0)),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(world.run, bus)
            for _ in range(2):
                perception = decode((await perceptions.receive())[1], Perception)
                command = Command(0, perception.tick, np.array([1.0, 0.0, 0.0, 0.0]))
                bus.put(keys.command(0), encode(command))
            started = trio.current_time()
            # The answer to tick 1 again, a tick late: normal in realtime, not bad input.
            await perceptions.receive()
            bus.put(keys.command(0), encode(command))
            while world.state_name != "finished":
                await trio.sleep(0.01)
            elapsed = trio.current_time() - started
            snapshots = [decode(p, Snapshot) for _, p in snapshot_inbox.drain()]
            nursery.cancel_scope.cancel()
        return world, snapshots, elapsed

    world, snapshots, elapsed = run_mock(main)
    assert world.tick == 12 and world.lost == []
    assert world.late_commands == 10  # ticks 2–11 had no answer
    assert world.statistics().rejected_total == 0
    assert elapsed == pytest.approx(1.1, abs=0.011)  # 11 periods after the answer to tick 1
    speeds = [float(np.linalg.norm(s.velocity[0, :2])) for s in snapshots]
    assert speeds[-1] > speeds[2] > 0  # still accelerating on the last command: caudal on


def test_pausing_twice_is_pausing_once_and_a_finished_run_only_reports() -> None:
    async def script(ask: Ask, observer: Observer, world: World) -> None:
        await observer.wait_for_tick(1)
        ask("pause")
        await trio.sleep(50.0)  # the world now waits to be resumed
        ask("pause")  # while it waits: it must still hear the one resume
        await trio.sleep(50.0)
        ask("resume")
        await observer.wait_for_tick(6)
        await _until_state(world, "finished")
        ask("pause")  # too late: the run is over

    answers, world = run_mock(lambda: _under_control(Scenario(fish=1, duration=6.0), script))
    assert [a[0] for a in answers] == ["pausing", "paused", "running", "finished"]
    assert answers[-1][1] == 6 and world.state_name == "finished"


def test_a_stop_reaches_a_paused_world_and_a_resume_does_not_undo_it() -> None:
    async def script(ask: Ask, observer: Observer, world: World) -> None:
        await observer.wait_for_tick(1)
        ask("pause")
        await trio.sleep(50.0)  # the world waits to be resumed
        ask("stop")
        ask("resume")  # too late: the world is stopping
        await _until_state(world, "stopped")

    answers, world = run_mock(lambda: _under_control(Scenario(fish=1, duration=1000.0), script))
    assert [a[0] for a in answers] == ["pausing", "stopping", "stopping"]
    # Held at the snapshot of tick 2 (asked during tick 1): the run ends there, the fish
    # asked for no more.
    assert world.state_name == "stopped" and world.tick == 2


def test_liveliness_tokens_no_fish_could_have_leave_the_world_running() -> None:
    scenario = Scenario(fish=1, duration=3.0)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,)))
        for token in ("fish/²", "fish/3/bad.name", "fish/12345678901234567890", "fish/-4"):
            bus.declare_token(f"{keys.prefix}/alive/{token}")
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    assert world.state_name == "finished" and world.tick == 3
    assert world.roster.alive == {0} and world.lost == []


def test_an_operators_formation_switch_reaches_every_fish() -> None:
    scenario = Scenario(fish=4, duration=20.0, behavior="formation", formation="pyramid")
    keys = scenario.keys

    async def main() -> dict[int, set[int]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2, 3)))
        observer = Observer(keys)
        shapes: dict[int, set[int]] = {}

        def note(key: str, payload: bytes) -> None:
            broadcast = decode(payload, Broadcast)
            flag = FormationFlag.from_values(broadcast.values)
            shapes.setdefault(broadcast.tick, set()).add(flag.shape)

        bus.subscribe(f"{keys.prefix}/fish/*/outbox", note)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0, 1), params, keys, school="a")).run, bus)
            await nursery.start(Fish(FishSettings((2, 3), params, keys, school="b")).run, bus)
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(5)
            reply = world.control(ControlRequest("formation", formation="diamond"))
            assert reply.state == "running"
            await observer.wait_for_tick(12)
            nursery.cancel_scope.cancel()
        return shapes

    shapes = run_mock(main)
    pyramid, diamond = FORMATION_SHAPES.index("pyramid"), FORMATION_SHAPES.index("diamond")
    assert shapes[0] == {pyramid}
    assert shapes[11] == {diamond}  # every fish, in both schools
    switched = min(tick for tick, seen in shapes.items() if diamond in seen)
    assert 5 <= switched <= 7 and all(shapes[t] == {diamond} for t in shapes if t > switched)


def test_a_switch_while_paused_counts_from_the_tick_after_the_held_one_as_the_reply_says() -> None:
    # The world holds at tick N's snapshot; a switch answered there is "from tick N + 1".
    # The fish decided tick N under the new shape while the snapshot and the reply said the
    # old one (a live switch was a tick earlier than a scheduled switch_at at N + 1).
    scenario = Scenario(fish=2, duration=20.0, behavior="formation", formation="pyramid")
    keys = scenario.keys

    async def main() -> tuple[ControlReply, dict[int, set[int]], dict[int, str | None]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1)))
        observer = Observer(keys)
        flags: dict[int, set[int]] = {}
        told: dict[int, str | None] = {}

        def note(key: str, payload: bytes) -> None:
            broadcast = decode(payload, Broadcast)
            flags.setdefault(broadcast.tick, set()).add(
                FormationFlag.from_values(broadcast.values).shape
            )

        bus.subscribe(f"{keys.prefix}/fish/*/outbox", note)
        bus.subscribe(keys.snapshot, lambda key, payload: told.update(
            {decode(payload, Snapshot).tick: decode(payload, Snapshot).formation}))  # fmt: skip
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            params = scenario.fish_params()
            await nursery.start(Fish(FishSettings((0, 1), params, keys, school="a")).run, bus)
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(3)
            world.control(ControlRequest("pause"))
            await _until_state(world, "paused")
            reply = world.control(ControlRequest("formation", formation="diamond"))
            world.control(ControlRequest("resume"))
            await observer.wait_for_tick(reply.tick + 3)
            nursery.cancel_scope.cancel()
        return reply, flags, told

    reply, flags, told = run_mock(main)
    pyramid, diamond = FORMATION_SHAPES.index("pyramid"), FORMATION_SHAPES.index("diamond")
    held = reply.tick
    assert reply.state == "paused" and held >= 4
    assert flags[held] == {pyramid} and told[held] is None  # None: as configured
    assert flags[held + 1] == {diamond} and told[held + 1] == "diamond"


def test_a_fish_lost_and_back_is_said_to_be_back_as_loudly_as_it_was_lost(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # A robot that surfaces: its fish leaves the world (its token gone), then comes back.
    from fishswarm.cli.swarm import _lost_text

    scenario = Scenario(fish=2, duration=1000.0)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1)))
        observer = Observer(keys)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0,), params, keys)).run, bus)
            async with trio.open_nursery() as surfacing:
                await surfacing.start(Fish(FishSettings((1,), params, keys)).run, bus)
                nursery.start_soon(world.run, bus)
                await observer.wait_for_tick(3)
                surfacing.cancel_scope.cancel()
            # Tick by tick (the world's own pace, its steps in threads): a poll that slept
            # would let the mock clock run ahead of them.
            for _ in range(50):
                if world.lost:
                    break
                await observer.wait_for_tick(observer.history[-1].tick + 1)
            await nursery.start(Fish(FishSettings((1,), params, keys)).run, bus)
            for _ in range(50):
                if world.joined:
                    break
                await observer.wait_for_tick(observer.history[-1].tick + 1)
            nursery.cancel_scope.cancel()
        return world

    with caplog.at_level("INFO", logger="fishswarm.actors.world"):
        world = run_mock(main)
    ((lost_id, lost_tick),) = [(f.fish_id, f.tick) for f in world.lost]
    ((back_id, back_tick),) = world.joined
    assert lost_id == back_id == 1 and back_tick > lost_tick
    said = [r for r in caplog.records if "back at tick" in r.getMessage()]
    assert [(r.levelname, r.getMessage()) for r in said] == [
        ("WARNING", f"fish 1 back at tick {back_tick} (lost at tick {lost_tick})")
    ]
    assert _lost_text([(1, lost_tick, "left")], world.joined) == (
        f"1 at tick {lost_tick} (left; back at tick {back_tick})"
    )
    assert _lost_text([(1, 4, "left"), (2, 6, "silent")], [(2, 5)]) == (
        "1 at tick 4 (left), 2 at tick 6 (silent)"  # back before it was lost: not back
    )


def test_fish_that_run_another_behaviour_are_named_once_and_counted(
    caplog: pytest.LogCaptureFixture,
) -> None:
    scenario = Scenario(fish=4, duration=3.0, seed=1)  # dispersion
    other = scenario.replace(behavior="aggregation")
    keys = scenario.keys

    # A school of three and one fish alone, all started with aggregation.
    school = FishSettings((0, 1, 2), other.fish_params(), keys, school="s")
    alone = FishSettings((3,), other.fish_params(), keys)
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(scenario, [school, alone], expected=(0, 1, 2, 3))
    assert world.statistics().mismatched_fish == 4
    # One warning for the difference as the run starts, naming every fish that said so (a
    # school's and a fish's own), not one per fish.
    warnings = [r.getMessage() for r in caplog.records if "this world's scenario says" in r.message]
    assert warnings == [
        "fish 0, 1, 2, 3 run 'aggregation', but this world's scenario says 'dispersion' "
        "(started with other settings?)"
    ]
    # At the end, every fish that differed, by id.
    assert caplog.records[-1].getMessage() == (
        "4 fish ran with other settings than this world's: 0, 1, 2, 3"
    )


def test_fish_that_say_they_differ_after_the_first_tick_are_named_one_by_one(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Robots (fish alone) that come up during the run, each deciding every 0.5 s in a world
    of 1-s ticks: each is named as it says so, MISMATCH_NAMED of them at most; the run's
    end counts them all."""
    scenario = Scenario(fish=1, duration=4.0, seed=1)
    keys = scenario.keys
    late = range(100, 100 + MISMATCH_NAMED + 3)

    def say_at_tick_2(bus: MemoryBus) -> None:
        def said(key: str, payload: bytes) -> None:
            if decode(payload, Snapshot).tick == 2:
                for fish_id in late:
                    about = FishAbout(np.array([fish_id]), "dispersion", __version__, 0,
                                      "paper", 0.5)  # fmt: skip
                    bus.put(keys.about(fish_id), encode(about))

        bus.subscribe(keys.snapshot, said)

    ours = FishSettings((0,), scenario.fish_params(), keys)
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(scenario, [ours], expected=(0,), on_bus=say_at_tick_2)
    assert world.mismatched == set(late)
    named = [r.getMessage() for r in caplog.records if "decide every 0.5 s" in r.getMessage()]
    assert [message.split()[1] for message in named] == [str(i) for i in late][:MISMATCH_NAMED]
    assert caplog.records[-1].getMessage().startswith(f"{len(late)} fish ran with other")


def _world_with_fish(
    scenario: Scenario,
    fish: Sequence[FishSettings],
    *,
    expected: tuple[int, ...],
    said: Sequence[tuple[str, bytes]] = (),
    on_bus: Callable[[MemoryBus], None] = lambda bus: None,
) -> World:
    """A world that expects ``expected`` run to its end beside fish actors of ``fish`` on
    the in-memory bus, with ``said`` put on the bus once all are up (what other fish say);
    ``on_bus`` is given the bus first (to subscribe to what the test watches)."""

    async def main() -> World:
        bus = MemoryBus()
        on_bus(bus)
        world = World(WorldSettings(scenario, expected_fish=expected))
        async with trio.open_nursery() as nursery:
            for settings in fish:
                await nursery.start(Fish(settings).run, bus)
            await nursery.start(world.run, bus)
            for key, payload in said:
                bus.put(key, payload)
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world

    return run_mock(main)


def test_a_robots_fish_is_named_by_what_it_says_as_it_comes_up(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A robot's fish serves its driver's runs, never the world's: it says what it runs
    only as it comes up (run 0). Fish 1 says aggregation so, in a dispersion world: named
    and counted. Fish 9, a robot this world does not expect (it would join the run), says
    it decides every 0.5 s in a world of 1-s ticks: named too. Fish 7 runs what the world
    does, and fish 8 (an older fishswarm) does not say its period: neither is named."""
    scenario = Scenario(fish=2, duration=2.0, seed=1)
    keys = scenario.keys

    def hello(fish_id: int, behavior: str, period: float | None) -> bytes:
        return encode(FishAbout(np.array([fish_id]), behavior, __version__, 0, "paper", period))

    ours = FishSettings((0, 1), scenario.fish_params(), keys, school="s")
    hellos = [
        (keys.about(1), hello(1, "aggregation", 1.0)),
        (keys.about(9), hello(9, "dispersion", 0.5)),
        (keys.about(7), hello(7, "dispersion", 1.0)),
        (keys.about(8), hello(8, "dispersion", None)),
    ]
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(scenario, [ours], expected=(0, 1), said=hellos)
    assert world.mismatched == {1, 9}
    said = [r.getMessage() for r in caplog.records if "scenario says" in r.getMessage()]
    assert said == [
        "fish 1 run 'aggregation', but this world's scenario says 'dispersion' "
        "(started with other settings?)",
        "fish 9 decide every 0.5 s, but this world's scenario says 1 s (--period) "
        "(started with other settings?)",
    ]


def test_fish_whose_formation_map_is_made_for_another_school_are_named(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The world runs 6 fish in a formation; fish 2 and 3 were started without --fish (or
    with a file that says 15): their map has 15 slots. Behaviour, version, rules and period
    agree, so only their settings' fingerprints tell: named, with the parameter that
    differs and what to do. Fish 4 was given another spacing and no flags: its three
    parameters named (the tolerance follows the spacing). Fish 5, an older fishswarm, says
    only its digest: named without parameters. Fish 0 and 1 have the world's settings:
    not named."""
    scenario = Scenario(fish=6, behavior="formation", duration=2.0, seed=1)
    keys = scenario.keys

    ours = FishSettings((0, 1), scenario.fish_params(), keys, school="a")
    theirs = FishSettings((2, 3), scenario.replace(fish=15).fish_params(), keys, school="b")
    other = FishSettings((4,), scenario.replace(spacing=0.25, flags=False).fish_params(), keys)
    older = FishAbout(np.array([5]), "formation", __version__, 0, "paper", 1.0, "0" * 16)
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(
            scenario,
            [ours, theirs, other],
            expected=(0, 1, 2, 3, 4),
            said=[(keys.about(5), encode(older))],
        )
    assert world.mismatched == {2, 3, 4, 5}
    said = [r.getMessage() for r in caplog.records if "scenario" in r.getMessage()]
    hint = (
        "a formation's map is made for --fish fish: give them the world's --config, --fish "
        "included) (started with other settings?)"
    )
    assert sorted(said) == [
        "fish 2, 3 decide with other formation parameters than this world's scenario "
        f"(their count differs; {hint}",
        "fish 4 decide with other formation parameters than this world's scenario (their "
        f"spacing, tolerance and flags differ; {hint}",
        f"fish 5 decide with other formation parameters than this world's scenario ({hint}",
    ]


def test_two_processes_answering_for_one_fish_are_named_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Two 'fishswarm fish --id 1' (or two robots given one id): both answer each of fish
    1's ticks. The first answer counts; the world says once what is wrong and what to do
    (it said only 'rejected a stale message', at every tick)."""
    scenario = Scenario(fish=2, duration=4.0, seed=1)
    keys = scenario.keys

    fish = [FishSettings(ids, scenario.fish_params(), keys) for ids in ((0,), (1,), (1,))]
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(scenario, fish, expected=(0, 1))
    assert world.tick == 4
    assert world.intake.rejected["duplicate"] == 4 and world.intake.rejected["stale"] == 0
    said = [r.getMessage() for r in caplog.records if "twice" in r.getMessage()]
    assert said == [
        "fish 1 answered tick 0 twice: two processes serve it (robots, or 'fishswarm fish', "
        "started with one --id?); the first answer of each tick counts: give each process "
        "its own ids"
    ]


def test_a_twins_answer_after_its_tick_closed_is_named_too(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Two processes serving one fish, the second slower: the first answer closes tick 0,
    and the twin's comes once tick 1 is asked. It was refused as stale, its process never
    named."""
    scenario = Scenario(fish=1, duration=2.0, seed=1)
    keys = scenario.keys
    fins = np.array([1.0, 0.0, 0.0, 0.0])

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0))
        async with (
            subscription(bus, keys.perception(0)) as perceptions,
            open_token(bus, keys.alive("fish", 0)),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(world.run, bus)
            await perceptions.receive()
            bus.put(keys.command(0), encode(Command(0, 0, fins)))
            await perceptions.receive()  # tick 1 asked: tick 0 is closed
            bus.put(keys.command(0), encode(Command(0, 0, fins)))  # the twin's, late
            bus.put(keys.command(0), encode(Command(0, 1, fins)))
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world

    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = run_mock(main)
    assert world.tick == 2 and world.statistics().rejected == {"duplicate": 1}
    said = [r.getMessage() for r in caplog.records if "twice" in r.getMessage()]
    assert said == [
        "fish 0 answered tick 0 twice: two processes serve it (robots, or 'fishswarm fish', "
        "started with one --id?); the first answer of each tick counts: give each process "
        "its own ids"
    ]


def test_a_fishs_watchdog_stop_for_a_tick_it_answered_is_no_twins_answer(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # Fish 0 answers tick 0; its watchdog then stops its fins, repeating tick 0 (so that a
    # driver acts at once) while the world still waits for fish 1: a second answer from
    # the same process, not a second process's.
    scenario = Scenario(fish=2, duration=1.0, seed=1)
    keys = scenario.keys
    fins = np.array([1.0, 0.0, 0.0, 0.0])

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        async with (
            subscription(bus, keys.perception(1)) as perceptions,
            open_token(bus, keys.alive("fish", 0)),
            open_token(bus, keys.alive("fish", 1)),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(world.run, bus)
            await perceptions.receive()
            bus.put(keys.command(0), encode(Command(0, 0, fins)))
            bus.put(keys.command(0), encode(Command(0, 0, np.zeros(4), watchdog=True)))
            await trio.sleep(0.01)
            bus.put(keys.command(1), encode(Command(1, 0, fins)))
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world

    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = run_mock(main)
    assert world.tick == 1 and world.statistics().rejected == {"stale": 1}
    assert not [r for r in caplog.records if "twice" in r.getMessage()]


def test_a_schools_watchdog_stop_in_real_time_is_no_twins_answer(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # `run --perception-timeout 0.8 --time realtime`: the school's watchdog fires between
    # the 1-s ticks and repeats the tick it answered; the world warned that two processes
    # served the fish.
    scenario = Scenario(fish=3, duration=4.0, seed=1, time_mode="realtime")
    keys = scenario.keys
    school = FishSettings((0, 1, 2), scenario.fish_params(), keys, school="s",
                          perception_timeout=0.8)  # fmt: skip

    async def main() -> tuple[World, Fish]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2)))
        fish = Fish(school)
        async with trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            nursery.start_soon(world.run, bus)
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world, fish

    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world, fish = run_mock(main)
    assert fish.statistics().watchdog_stops >= 3  # it fired, as in the run that warned
    assert not [r for r in caplog.records if "twice" in r.getMessage()]
    assert "duplicate" not in world.statistics().rejected


def test_fish_started_with_other_study_code_rules_are_named(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # The world runs the study's code; the fish were started with the paper's rules.
    scenario = Scenario(fish=2, duration=2.0, seed=1, profile="study-code")
    paper = scenario.replace(profile="paper")

    fish = FishSettings((0, 1), paper.fish_params(), scenario.keys)
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(scenario, [fish], expected=(0, 1))
    assert world.statistics().mismatched_fish == 2
    (warning,) = [r.getMessage() for r in caplog.records if "rules" in r.getMessage()]
    assert warning.endswith(
        "follow the 'paper' rules, but this world's scenario says 'lennard-jones,homing' "
        "(--profile, --study-code) (started with other settings?)"
    )


def test_fish_that_run_the_worlds_behaviour_raise_no_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    scenario = Scenario(fish=2, duration=2.0, seed=1)

    fish = FishSettings((0, 1), scenario.fish_params(), scenario.keys)
    with caplog.at_level("WARNING", logger="fishswarm.actors.world"):
        world = _world_with_fish(scenario, [fish], expected=(0, 1))
    assert world.statistics().mismatched_fish == 0
    assert not [r for r in caplog.records if r.name == "fishswarm.actors.world"]


def test_a_step_runs_in_a_worker_thread_only_while_its_last_run_took_long(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import threading
    import time

    from fishswarm.actors import world as world_module

    monkeypatch.setattr(world_module, "OFFLOAD_AFTER", 0.05)
    world = World(WorldSettings(Scenario(fish=3, duration=1.0)))
    durations = iter([0.0, 0.1, 0.0, 0.0])
    threads: list[threading.Thread] = []

    def step() -> None:
        threads.append(threading.current_thread())
        time.sleep(next(durations))

    async def main() -> None:
        for _ in range(4):
            await world._compute(step)

    trio.run(main)
    # Runs 1 and 2 in the event loop (no run before; a quick one before), run 2 slow: run 3
    # goes to a worker thread; it was quick, so run 4 is back in the loop.
    loop = threading.main_thread()
    assert [thread is loop for thread in threads] == [True, True, False, True]


def test_a_large_schools_first_step_runs_in_a_thread_that_ends_with_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """From OFFLOAD_FISH fish on, the first run of a step (the compiled kernels load then)
    goes to a thread of its own, gone with the step and the OpenMP team it led; later runs
    stay in the event loop unless the last took long, and then go to one of trio's."""
    import threading
    import time

    from fishswarm.actors import world as world_module

    monkeypatch.setattr(world_module, "OFFLOAD_FISH", 3)
    monkeypatch.setattr(world_module, "OFFLOAD_AFTER", 0.05)
    world = World(WorldSettings(Scenario(fish=3, duration=1.0)))
    world.sim.join([0, 1, 2])
    durations = iter([0.0, 0.0, 0.1, 0.0, 0.0])
    threads: list[threading.Thread] = []

    def step() -> None:
        threads.append(threading.current_thread())
        time.sleep(next(durations))

    async def main() -> None:
        for _ in range(5):
            await world._compute(step)

    trio.run(main)
    first, second, third, fourth, fifth = threads
    first.join(timeout=10.0)
    assert first.name == "fishswarm world step" and not first.is_alive()
    loop = threading.main_thread()
    assert second is loop and third is loop and fifth is loop
    assert fourth is not loop and fourth.name.startswith("Trio thread")


def test_the_worlds_statistics_say_where_its_ticks_went(monkeypatch: pytest.MonkeyPatch) -> None:
    import time

    from fishswarm.actors import world as world_module
    from fishswarm.actors.perceptions import perception_messages
    from fishswarm.sim.tick import WorldSim

    # Each part made to take at least a known wall time, one apart from the other: physics
    # 6 ms a step, vision 2 ms, building the perceptions 3 ms. (Only lower bounds: a loaded
    # machine makes any step longer, never shorter.)
    def slowed(step: Any, seconds: float) -> Any:
        def run(*args: Any, **kwargs: Any) -> Any:
            until = time.perf_counter() + seconds
            result = step(*args, **kwargs)
            while time.perf_counter() < until:
                pass
            return result

        run.__name__ = step.__name__
        return run

    monkeypatch.setattr(WorldSim, "next_event", slowed(WorldSim.next_event, 0.006))
    monkeypatch.setattr(WorldSim, "sense", slowed(WorldSim.sense, 0.002))
    monkeypatch.setattr(world_module, "perception_messages", slowed(perception_messages, 0.003))
    scenario = Scenario(fish=4, duration=4.0, seed=2)
    world, _ = run_mock(lambda: _swarm(scenario, schools=2))
    statistics = world.statistics()
    assert statistics.physics_time_median >= 0.006
    assert statistics.vision_time_median >= 0.002
    assert statistics.perceptions_time_median >= 0.003
    # One physics and one vision step a tick (and one for the first look), perceptions at
    # every tick but the last.
    assert len(world._phase_times["physics"]) == len(world._phase_times["vision"]) == 5
    assert len(world._phase_times["perceptions"]) == 4
    # Five snapshots, a batch for each of the two schools at four ticks, the last pulse
    # (and any pulses the run lasted long enough for).
    assert statistics.messages_out >= 5 + 2 * 4 + 1


async def _answer_after(
    bus: MemoryBus, keys: Any, fish_id: int, delays: list[float], on_perception: Any = None
) -> None:
    """A hand-driven fish on its own keys: it answers its n-th perception after
    ``delays[n]`` s with its fins off, and no more perceptions once the delays run out."""
    async with subscription(bus, keys.perception(fish_id)) as perceptions:
        bus.declare_token(keys.alive("fish", fish_id))
        for delay in delays:
            perception = decode((await perceptions.receive())[1], Perception)
            if on_perception is not None:
                await on_perception(perception.tick)
            await trio.sleep(delay)
            bus.put(keys.command(fish_id), encode(Command(fish_id, perception.tick, np.zeros(4))))
        await trio.sleep_forever()


def test_answer_times_are_taken_over_the_ticks_every_fish_answered() -> None:
    """Fish 1 answers after 1, 2, 4 and 8 s, then not at all: the fifth tick is its timeout
    (it is lost) and is left out. Median of (1, 2, 4, 8): 3 s; 90th percentile, between the
    third and fourth values at 0.7 of the way: 4 + 0.7 × 4 = 6.8 s."""
    scenario = Scenario(fish=2, duration=5.0, seed=3)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), command_timeout=10.0))
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            nursery.start_soon(_answer_after, bus, keys, 1, [1.0, 2.0, 4.0, 8.0])
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    statistics = world.statistics()
    assert [(f.fish_id, f.tick) for f in world.lost] == [(1, 4)]
    assert statistics.answer_time_median == pytest.approx(3.0)
    assert statistics.answer_time_p90 == pytest.approx(6.8)


def test_a_fish_that_comes_up_during_tick_zero_joins_at_tick_one() -> None:
    scenario = Scenario(fish=1, duration=3.0, seed=3)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0))
        async with trio.open_nursery() as nursery:

            async def late_fish_comes_up(tick: int) -> None:
                if tick == 0:
                    fish = Fish(FishSettings((9,), scenario.fish_params(), keys))
                    await nursery.start(fish.run, bus)

            nursery.start_soon(_answer_after, bus, keys, 0, [0.5] * 3, late_fish_comes_up)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    assert world.joined == [(9, 1)] and world.lost == []


def test_a_fish_vouches_only_for_itself_or_its_school_on_its_own_about_key() -> None:
    """In a secured run a forged word on fish 0's about key naming fish 0 and 4 must not let
    fish 4 in (a fish on its own keys speaks for itself alone); a school's word on its first
    fish's key speaks for the school."""
    scenario = Scenario(fish=1, duration=4.0, seed=3)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(
            WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0, vouched_only=True)
        )
        observer = Observer(keys)
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0,), params, keys)).run, bus)
            nursery.start_soon(world.run, bus)
            await observer.wait_for_tick(0)
            bus.declare_token(keys.alive("fish", 4))
            forged = FishAbout(np.array([0, 4]), params.behavior.name, __version__, 0, "paper")
            bus.put(keys.about(0), encode(forged))
            school = FishAbout(np.array([5, 6]), params.behavior.name, __version__, 0, "paper")
            bus.put(keys.about(5, "s"), encode(school))
            await observer.wait_for_tick(4)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    assert world.vouched == {(0, None), (5, "s"), (6, "s")}
    assert world.joined == [] and world.roster.alive == {0}


def test_a_world_must_pulse() -> None:
    with pytest.raises(ValueError, match="pulse_period must be positive"):
        WorldSettings(Scenario(), pulse_period=0.0)


def test_the_world_pulses_its_state_while_it_waits_and_says_when_the_run_ended() -> None:
    """A fish that answers 2.4 s after each perception; paused at 3.5 s (during tick 1),
    stopped at 7.5 s. Pulses every second say running, then paused — the tick under way is
    answered, and the world holds at the snapshot of tick 2 — and the stop ends the run there
    at once, without a perception more."""
    scenario = Scenario(fish=1, duration=1000.0, seed=3)
    keys = scenario.keys

    async def main() -> tuple[list[tuple[float, str, int]], World]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0, turn_delay=0.0))
        heard: list[tuple[float, str, int]] = []

        def pulse(key: str, payload: bytes) -> None:
            message = decode(payload, WorldPulse)
            assert message.run == world.run_id
            heard.append((trio.current_time(), message.state, message.tick))

        bus.subscribe(keys.world_pulse, pulse)
        bus.subscribe(
            keys.perception(0),
            lambda key, payload: heard.append((trio.current_time(), "perception", -1)),
        )
        async with trio.open_nursery() as nursery:
            nursery.start_soon(_answer_after, bus, keys, 0, [2.4] * 10)
            nursery.start_soon(world.run, bus)
            await trio.sleep(3.5)
            world.control(ControlRequest("pause"))
            await trio.sleep(4.0)
            world.control(ControlRequest("stop"))
            await _until_state(world, "stopped")
            nursery.cancel_scope.cancel()
        return heard, world

    heard, world = run_mock(main)
    assert heard == [
        (0.0, "perception", -1),
        (1.0, "running", 0),
        (2.0, "running", 0),
        (2.4, "perception", -1),
        (3.0, "running", 1),
        (4.0, "running", 1),  # pausing: tick 1 answered at 4.8, held at the snapshot of tick 2
        (5.0, "paused", 2),
        (6.0, "paused", 2),
        (7.0, "paused", 2),
        (7.5, "ended", 2),
    ]
    assert world.tick == 2


def test_a_world_told_to_stop_while_it_waits_for_its_fish_stops_waiting() -> None:
    scenario = Scenario(fish=2, duration=10.0)

    async def main() -> tuple[World, float, str]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), start_timeout=60.0))
        async with trio.open_nursery() as nursery:
            nursery.start_soon(world.run, bus)
            await trio.sleep(5.0)  # no fish come
            reply = world.control(ControlRequest("stop"))
            await _until_state(world, "stopped")
            nursery.cancel_scope.cancel()
        return world, trio.current_time(), reply.state

    world, ended_at, replied = run_mock(main)
    assert replied == "stopping" and ended_at < 5.1  # not the 60-s start timeout's error
    assert world.tick == 0 and world.statistics().ticks == 0


def test_a_world_told_to_stop_before_its_run_does_not_wait_for_its_fish() -> None:
    """A stop asked before the world starts waiting (a control served before the run) ends
    the run as soon as it starts: the wait for its fish is cancelled at once."""
    scenario = Scenario(fish=2, duration=10.0)

    async def main() -> tuple[World, float, str]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), start_timeout=60.0))
        reply = world.control(ControlRequest("stop"))
        await world.run(bus)  # no fish come
        return world, trio.current_time(), reply.state

    world, ended_at, replied = run_mock(main)
    assert replied == "stopping" and world.state_name == "stopped"
    assert ended_at < 0.1  # not the 60-s start timeout's error
    assert world.tick == 0 and world.statistics().ticks == 0


def test_a_pause_asked_while_the_world_waits_for_its_fish_holds_its_first_tick() -> None:
    """Paused before its fish come up, the world says so (status and pulses) and sends no
    perception until resumed."""
    scenario = Scenario(fish=1, duration=3.0)
    keys = scenario.keys

    async def main() -> tuple[list[str], list[tuple[float, str]], World]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0))
        heard: list[tuple[float, str]] = []
        bus.subscribe(
            keys.world_pulse,
            lambda key, payload: heard.append(
                (trio.current_time(), decode(payload, WorldPulse).state)
            ),
        )
        bus.subscribe(
            keys.perception(0),
            lambda key, payload: heard.append((trio.current_time(), "perception")),
        )
        states = []
        async with trio.open_nursery() as nursery:
            nursery.start_soon(world.run, bus)
            states.append(world.control(ControlRequest("pause")).state)
            await trio.sleep(0.5)
            nursery.start_soon(_answer_after, bus, keys, 0, [0.0] * 3)
            await trio.sleep(2.2)
            states.append(world.control(ControlRequest("status")).state)
            states.append(world.control(ControlRequest("resume")).state)
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return states, heard, world

    states, heard, world = run_mock(main)
    assert states == ["paused", "paused", "running"]
    assert heard[:3] == [(1.5, "paused"), (2.5, "paused"), (2.7, "perception")]
    assert world.tick == 3


def test_a_world_waits_for_another_world_of_its_swarm_to_end(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Fish serve one world at a time (two would take turns starting them afresh): a world
    that finds another of its swarm up waits, says so once, and runs when that one leaves;
    one that waits in vain for all of its start timeout says what to do."""
    scenario = Scenario(fish=1, duration=2.0)
    keys = scenario.keys

    async def main(leaves_at: float | None) -> tuple[World, list[float], str]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
        perceived: list[float] = []
        bus.subscribe(
            keys.perception(0), lambda key, payload: perceived.append(trio.current_time())
        )
        other = bus.declare_token(keys.alive("world", 12345))
        refused = ""
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            if leaves_at is not None:

                async def other_world_ends() -> None:
                    await trio.sleep(leaves_at)
                    other.undeclare()

                nursery.start_soon(other_world_ends)
            try:
                await world.run(bus)
            except StartTimeout as error:
                refused = f"{trio.current_time():g} s: {error}"
            nursery.cancel_scope.cancel()
        return world, perceived, refused

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        world, perceived, refused = run_mock(lambda: main(leaves_at=7.0))
    assert world.state_name == "finished" and world.tick == 2 and refused == ""
    assert perceived[0] == pytest.approx(7.0 + world.settings.admit_delay)
    warnings = [r.getMessage() for r in caplog.records if "another world" in r.getMessage()]
    assert warnings == [
        "another world runs swarm 'default' on this router: waiting for its run to end "
        "(fish serve one world at a time)"
    ]
    _, perceived, refused = run_mock(lambda: main(leaves_at=None))
    assert perceived == []
    assert refused == (
        "20 s: another world ran swarm 'default' on this router for all of 20 s: " + OTHER_WORLD
    )


def _world_of_fish_0(bus: MemoryBus, scenario: Scenario) -> tuple[World, list[float]]:
    """A world that waits up to 20 s for fish 0, and the times fish 0 is sent perceptions."""
    world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
    perceived: list[float] = []
    bus.subscribe(scenario.keys.perception(0), lambda k, p: perceived.append(trio.current_time()))
    return world, perceived


def test_two_worlds_that_come_up_together_run_one_after_the_other_first_come_first() -> None:
    """Two worlds of one swarm up at the same instant, both waiting for the same fish: the
    one whose place in the queue comes first runs, the other waits behind it and runs
    after (before, each waited for the other until both timed out)."""
    scenario = Scenario(fish=1, duration=2.0)
    keys = scenario.keys

    async def main() -> tuple[list[World], list[tuple[int, int]]]:
        bus = MemoryBus()
        worlds = [
            World(WorldSettings(scenario, expected_fish=(0,), start_timeout=30.0)) for _ in range(2)
        ]
        perceptions: list[tuple[int, int]] = []  # (run, tick) in the order the fish got them
        bus.subscribe(
            keys.perception(0),
            lambda key, payload: perceptions.append(
                (decode(payload, Perception).run, decode(payload, Perception).tick)
            ),
        )
        async with trio.open_nursery() as nursery:
            for world in worlds:
                nursery.start_soon(world.run, bus)
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            for world in worlds:
                await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return worlds, perceptions

    worlds, perceptions = run_mock(main)
    first, second = sorted(worlds, key=lambda world: world.place)
    assert [world.tick for world in worlds] == [2, 2]
    # Ticks 0 and 1 perceived: the snapshot of tick 2 ends a run of 2 s.
    assert perceptions == [(first.run_id, 0), (first.run_id, 1), (second.run_id, 0),
                           (second.run_id, 1)]  # fmt: skip


@pytest.mark.parametrize("earlier", [True, False])
def test_a_world_waits_behind_a_world_that_came_up_before_it_and_only_such_a_one(
    earlier: bool, caplog: pytest.LogCaptureFixture
) -> None:
    """A place in the swarm's queue taken before this world's holds it until that world
    goes (here at 5 s); one taken after does not (the world starts after its turn delay and
    its fish's admission)."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[World, list[float], list[bool]]:
        bus = MemoryBus()
        world, perceived = _world_of_fish_0(bus, scenario)
        queued = []
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await nursery.start(world.run, bus)  # its place taken now
            arrived, _ = world.place
            other = bus.declare_token(keys.queue_place(arrived + (-1 if earlier else 1), 7))
            await trio.sleep(1.0)
            queued.append(world.queued)
            await trio.sleep(4.0)
            other.undeclare()
            await _until_state(world, "finished")
            queued.append(world.queued)
            nursery.cancel_scope.cancel()
        return world, perceived, queued

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        world, perceived, queued = run_mock(main)
    delays = world.settings.admit_delay
    said = [r.getMessage() for r in caplog.records if "another world" in r.getMessage()]
    if earlier:
        assert perceived[0] == pytest.approx(5.0 + delays) and queued == [True, False]
        assert said == [
            "another world of swarm 'default' came up first on this router: waiting for its "
            "run to end (fish serve one world at a time)"
        ]
    else:
        assert perceived[0] == pytest.approx(world.settings.turn_delay + delays)
        assert queued == [False, False] and said == []


def test_a_world_behind_one_that_never_takes_its_turn_says_so_at_its_start_timeout() -> None:
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> str:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
        bus.declare_token(keys.queue_place(world.place[0] - 1, 7))
        try:
            await world.run(bus)
        except StartTimeout as error:
            return f"{trio.current_time():g} s: {error}"
        return "no timeout"

    assert run_mock(main) == (
        "20 s: another world of swarm 'default', up before this one, still waited for its "
        "turn after 20 s: " + OTHER_WORLD
    )


def test_a_start_timeout_shorter_than_the_turn_delay_names_the_missing_fish_not_a_world() -> None:
    scenario = Scenario(fish=1, duration=1.0)

    async def main() -> str:
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=0.05))
        try:
            await world.run(MemoryBus())
        except StartTimeout as error:
            return f"{trio.current_time():g} s: {error}"
        return "no timeout"

    assert run_mock(main) == "0.05 s: 1 of 1 fish did not come up within 0.05 s (missing ids: 0)"


class _LateWorlds:
    """A MemoryBus on which the liveliness of worlds (their places and tokens) reaches the
    watchers ``lag`` s late: each world on its own machine, the fish beside the router."""

    def __init__(self, bus: MemoryBus, nursery: trio.Nursery, lag: float) -> None:
        self._bus, self._nursery, self._lag = bus, nursery, lag

    def put(self, key: str, payload: bytes) -> None:
        self._bus.put(key, payload)

    def subscribe(self, key_expr: str, on_sample: Callable[[str, bytes], None]) -> Declared:
        return self._bus.subscribe(key_expr, on_sample)

    def declare_token(self, key: str) -> Declared:
        return self._bus.declare_token(key)

    def watch_alive(self, key_expr: str, on_change: Callable[[str, bool], None]) -> Declared:
        async def later(key: str, alive: bool) -> None:
            await trio.sleep(self._lag)
            on_change(key, alive)

        def changed(key: str, alive: bool) -> None:
            if "/alive/fish/" in key:
                on_change(key, alive)
            else:
                self._nursery.start_soon(later, key, alive)

        return self._bus.watch_alive(key_expr, changed)


def test_two_worlds_whose_places_cross_late_but_within_the_turn_delay_take_turns() -> None:
    """Two worlds up in the same instant, their fish up already, each seeing the other's
    place 50 ms late (less than the turn delay, 0.1 s): at their turn delay each has seen
    the other, and the first place runs first, then the other; the fish never hears the two
    runs interleaved. (With a lag longer than the turn delay neither would see the other in
    time: docs/architecture.md says so.)"""
    scenario = Scenario(fish=1, duration=2.0)
    keys = scenario.keys

    async def main() -> tuple[list[World], list[int]]:
        bus = MemoryBus()
        runs: list[int] = []
        bus.subscribe(keys.perception(0), lambda k, p: runs.append(decode(p, Perception).run))
        worlds = [World(WorldSettings(scenario, expected_fish=(0,))) for _ in range(2)]
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            late = _LateWorlds(bus, nursery, lag=0.05)
            for world in worlds:
                nursery.start_soon(world.run, late)
            for world in worlds:
                await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return worlds, runs

    worlds, runs = run_mock(main)
    first, second = sorted(worlds, key=lambda world: world.place)
    assert runs == [first.run_id] * 2 + [second.run_id] * 2


def test_of_two_worlds_that_took_their_turn_at_once_the_lower_run_goes_first() -> None:
    """Two worlds that each took their turn before the other's place reached it (a race
    shorter than the turn delay): the world whose run id is lower runs first; a later run
    id does not hold this world up."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main(offset: int) -> tuple[World, list[bool]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,)))
        queued = []
        async with trio.open_nursery() as nursery:
            nursery.start_soon(world.run, bus)
            await trio.sleep(1.0)  # its turn taken, no fish yet
            other = bus.declare_token(keys.alive("world", world.run_id + offset))
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await trio.sleep(1.0)
            queued.append(world.queued)
            queued.append(world.state_name == "waiting")
            other.undeclare()
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world, queued

    assert run_mock(lambda: main(-1))[1] == [True, True]
    assert run_mock(lambda: main(+1))[1] == [False, False]


def _watch_turns(bus: MemoryBus, keys: Any) -> list[tuple[float, str, bool]]:
    """The comings and goings of the swarm's places and world tokens, with their times."""
    seen: list[tuple[float, str, bool]] = []

    def note(key: str, alive: bool) -> None:
        if keys.parse_alive(key).role in ("queue", "world"):
            seen.append((trio.current_time(), key, alive))

    bus.watch_alive(keys.alive_all(), note)
    return seen


def test_a_world_shows_its_place_until_its_turn_then_its_token_until_its_run_ends() -> None:
    """Alone, its fish up, default settings: the world shows its place as it comes up (the
    µs it came up at, since the epoch, and its run); 0.1 s later (its turn delay) it shows
    its world token and only then drops its place, so that one of the two is always up for
    a world that comes up meanwhile; its token goes when its run has ended."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[World, tuple[int, int], list[tuple[float, str, bool]]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,)))
        seen = _watch_turns(bus, keys)
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            before = time.time_ns() // 1000
            await nursery.start(world.run, bus)
            made = (before, time.time_ns() // 1000)
            await _until_state(world, "finished")
            ended = trio.current_time()
            nursery.cancel_scope.cancel()
        seen.append((ended, "run ended", True))
        return world, made, seen

    world, (before, after), seen = run_mock(main)
    arrived, run = world.place
    assert before <= arrived <= after and run == world.run_id
    place, token = keys.queue_place(arrived, run), keys.alive("world", world.run_id)
    assert world.settings.turn_delay == 0.1 and world.state_name == "finished"
    assert seen[:3] == [(0.0, place, True), (pytest.approx(0.1), token, True),
                        (pytest.approx(0.1), place, False)]  # fmt: skip
    (gone_at, gone, up), (ended_at, _, _) = seen[3:]
    assert (gone, up) == (token, False) and gone_at == pytest.approx(ended_at)


def test_a_world_stopped_while_it_waits_its_turn_drops_its_place_and_never_shows_a_token() -> None:
    """Behind an earlier place, a world told to stop (at 3 s) drops its place then and ends
    stopped, without ever showing its world token: it took no turn (other worlds would wait
    for that token, and fish greet it)."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[World, list[tuple[float, str, bool]]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
        seen = _watch_turns(bus, keys)
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await nursery.start(world.run, bus)
            earlier = bus.declare_token(keys.queue_place(world.place[0] - 1, 7))
            await trio.sleep(3.0)
            await _stop(world)
            earlier.undeclare()
            nursery.cancel_scope.cancel()
        return world, seen

    world, seen = run_mock(main)
    place, earlier = keys.queue_place(*world.place), keys.queue_place(world.place[0] - 1, 7)
    assert [(at, key, up) for at, key, up in seen if key != earlier] == [
        (0.0, place, True),
        (3.0, place, False),
    ]
    assert world.state_name == "stopped" and world.tick == 0


def test_a_world_waiting_its_turn_says_so_once_whatever_it_hears_meanwhile(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Behind a running world, the world hears its fish come up (1 s) and a later world's
    place come (2 s) and go (3 s) while it waits: it says that it waits once, not at each
    of them; it runs when the other world has gone (4 s)."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
        running = bus.declare_token(keys.alive("world", 12345))
        async with trio.open_nursery() as nursery:
            nursery.start_soon(world.run, bus)
            await trio.sleep(1.0)
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await trio.sleep(1.0)
            later = bus.declare_token(keys.queue_place(world.place[0] + 1, 7))
            await trio.sleep(1.0)
            later.undeclare()
            await trio.sleep(1.0)
            running.undeclare()
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        world = run_mock(main)
    assert world.tick == 1
    assert [r.getMessage() for r in caplog.records if "another world" in r.getMessage()] == [
        "another world runs swarm 'default' on this router: waiting for its run to end "
        "(fish serve one world at a time)"
    ]


def test_a_worlds_start_timeout_runs_from_when_it_came_up_its_wait_for_its_turn_included() -> None:
    """A 20-s start timeout: behind another world for 15 s, then no fish come: the world
    gives up at 20 s (not 20 s after its turn), for its missing fish."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> str:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
        running = bus.declare_token(keys.alive("world", 12345))
        async with trio.open_nursery() as nursery:

            async def other_world_ends() -> None:
                await trio.sleep(15.0)
                running.undeclare()

            nursery.start_soon(other_world_ends)
            try:
                await world.run(bus)
            except StartTimeout as error:
                return f"{trio.current_time():g} s: {error}"
        return "no timeout"

    assert run_mock(main) == "20 s: 1 of 1 fish did not come up within 20 s (missing ids: 0)"


def test_a_world_held_by_a_lower_run_that_never_starts_gives_up_at_its_start_timeout() -> None:
    """The world took its turn (no fish yet); a world that took its own in the same instant,
    with a lower run id, goes first, but never starts: at its start timeout (20 s) the
    world says so, its fish up all along, and it has sent them nothing (it does not run
    alongside that world)."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[str, list[float]]:
        bus = MemoryBus()
        world, perceived = _world_of_fish_0(bus, scenario)
        async with trio.open_nursery() as nursery:

            async def first_run_and_fish() -> None:
                await trio.sleep(1.0)  # the world's turn taken
                bus.declare_token(keys.alive("world", world.run_id - 1))
                await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)

            nursery.start_soon(first_run_and_fish)
            try:
                await world.run(bus)
                refused = "no timeout"
            except StartTimeout as error:
                refused = f"{trio.current_time():g} s: {error}"
            nursery.cancel_scope.cancel()
        return refused, perceived

    assert run_mock(main) == (
        "20 s: another world ran swarm 'default' on this router for all of 20 s: " + OTHER_WORLD,
        [],
    )


def test_a_world_token_that_names_no_run_goes_before_a_world_that_took_its_turn() -> None:
    """A world token whose id is no run id (not a fishswarm world's, or a garbled one) counts
    as a world that took its turn first: a world that took its own is held while it is up
    (from 1 s to 3 s, its fish up at 2 s), and runs when it has gone."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[World, list[bool], list[float]]:
        bus = MemoryBus()
        world, perceived = _world_of_fish_0(bus, scenario)
        queued = []
        async with trio.open_nursery() as nursery:
            nursery.start_soon(world.run, bus)
            await trio.sleep(1.0)
            stray = bus.declare_token(keys.alive("world", "stray"))
            await trio.sleep(1.0)
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await trio.sleep(1.0)
            queued.append(world.queued)
            stray.undeclare()
            await _until_state(world, "finished")
            queued.append(world.queued)
            nursery.cancel_scope.cancel()
        return world, queued, perceived

    world, queued, perceived = run_mock(main)
    assert queued == [True, False] and world.tick == 1
    assert perceived[0] == pytest.approx(3.0 + world.settings.admit_delay)


def test_a_queued_world_lists_the_worlds_that_run_then_the_earlier_places_earliest_first() -> None:
    """What a queued world waits for, in order: the worlds that took their turn, then the
    places before its own from the earliest, whatever order they came in; neither its own
    place nor a later one."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[World, list[str]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), start_timeout=20.0))
        async with trio.open_nursery() as nursery:
            await nursery.start(world.run, bus)
            arrived, run = world.place
            for token in (
                keys.queue_place(arrived, run + 1),
                keys.queue_place(arrived - 1, 9),
                keys.queue_place(arrived - 2, 5),
                keys.queue_place(arrived, run - 1),
                keys.alive("world", 12345),
            ):
                bus.declare_token(token)
            await trio.sleep(1.0)
            ahead = world.ahead
            nursery.cancel_scope.cancel()
        return world, ahead

    world, ahead = run_mock(main)
    arrived, run = world.place
    assert ahead == [
        keys.alive("world", 12345),
        keys.queue_place(arrived - 2, 5),
        keys.queue_place(arrived - 1, 9),
        keys.queue_place(arrived, run - 1),
    ]


def test_a_world_whose_turn_comes_first_takes_in_all_that_came_with_it() -> None:
    """Behind a running world: in the instant that world goes (5 s), the place of a world up
    before this one reaches it too (it came late): the world waits behind that place as
    well, and runs only when it has gone (8 s), not when the running world went."""
    scenario = Scenario(fish=1, duration=1.0)
    keys = scenario.keys

    async def main() -> tuple[World, list[float], list[bool]]:
        bus = MemoryBus()
        world, perceived = _world_of_fish_0(bus, scenario)
        running = bus.declare_token(keys.alive("world", 12345))
        queued = []
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            nursery.start_soon(world.run, bus)
            await trio.sleep(5.0)
            running.undeclare()
            earlier = bus.declare_token(keys.queue_place(world.place[0] - 1, 7))
            await trio.sleep(1.0)
            queued.append(world.queued)
            await trio.sleep(2.0)
            earlier.undeclare()
            await _until_state(world, "finished")
            nursery.cancel_scope.cancel()
        return world, perceived, queued

    world, perceived, queued = run_mock(main)
    assert queued == [True] and world.tick == 1
    assert perceived[0] == pytest.approx(8.0 + world.settings.admit_delay)


@pytest.mark.parametrize("time_mode", ["lockstep", "realtime"])
def test_a_lockstep_world_warns_that_the_robots_up_on_its_swarm_swim_in_real_time(
    time_mode: str, caplog: pytest.LogCaptureFixture
) -> None:
    """Robots 3 and 4 are up (their drivers' tokens): a lockstep run is over before they
    have moved, so the world says to run in real time; a realtime run says nothing."""
    scenario = Scenario(fish=1, duration=1.0, time_mode=time_mode)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,)))
        robots = [bus.declare_token(keys.alive("robot", robot)) for robot in (3, 4)]
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0,), scenario.fish_params(), keys)).run, bus)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        for robot in robots:
            robot.undeclare()
        return world

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        world = run_mock(main)
    said = [r.getMessage() for r in caplog.records if "robots" in r.getMessage()]
    assert world.state_name == "finished"
    if time_mode == "lockstep":
        assert said == [
            "robots 3, 4 are up on this swarm, and this run is in lockstep time: robots swim "
            "in real time; give --time realtime for a run with them"
        ]
    else:
        assert said == []


def test_a_world_waiting_for_its_fish_says_every_10_s_which_are_not_up(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Fish 0 and 1 are up, fish 2 comes at 25 s: the world says at 10 and 20 s which fish
    it waits for, and nothing more once they are all up."""
    scenario = Scenario(fish=3, duration=1.0)
    keys = scenario.keys

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2), start_timeout=60.0))
        params = scenario.fish_params()
        async with trio.open_nursery() as nursery:
            await nursery.start(Fish(FishSettings((0, 1), params, keys)).run, bus)
            nursery.start_soon(world.run, bus)
            await trio.sleep(25.0)
            await nursery.start(Fish(FishSettings((2,), params, keys)).run, bus)
            await _until_state(world, "finished")
            await trio.sleep(30.0)
            nursery.cancel_scope.cancel()
        return world

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.world"):
        world = run_mock(main)
    said = [r.getMessage() for r in caplog.records if "fish up after" in r.getMessage()]
    assert world.state_name == "finished"
    assert said == [
        "2 of 3 fish up after 10 s; waiting for fish 2 (for 50 s more)",
        "2 of 3 fish up after 20 s; waiting for fish 2 (for 40 s more)",
    ]


async def _stop(world: World) -> tuple[float, float]:
    """Ask ``world`` to stop: when it was asked, and when it had stopped."""
    asked = trio.current_time()
    world.control(ControlRequest("stop"))
    await _until_state(world, "stopped")
    return asked, trio.current_time()


def test_a_stop_while_a_fish_is_slow_to_answer_ends_the_run_at_once() -> None:
    """Fish 1 takes 8 s over tick 1 (the command timeout is 10 s): a stop asked 2 s into
    that wait ends the run then, at the snapshot of tick 1, and fish 1 is not lost for it.
    Its fish hear the run end in the same instant (a robot would stop swimming)."""
    scenario = Scenario(fish=2, duration=100.0, seed=3)
    keys = scenario.keys

    async def main() -> tuple[World, float, float, list[tuple[float, str]]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        pulses: list[tuple[float, str]] = []
        bus.subscribe(
            keys.world_pulse,
            lambda key, payload: pulses.append(
                (trio.current_time(), decode(payload, WorldPulse).state)
            ),
        )
        asked = trio.Event()

        async def on_perception(tick: int) -> None:
            if tick == 1:
                asked.set()

        async with trio.open_nursery() as nursery:
            nursery.start_soon(_answer_after, bus, keys, 0, [0.0] * 10)
            nursery.start_soon(_answer_after, bus, keys, 1, [0.0, 8.0, 0.0], on_perception)
            nursery.start_soon(world.run, bus)
            await asked.wait()
            await trio.sleep(2.0)
            stopped_at, ended_at = await _stop(world)
            nursery.cancel_scope.cancel()
        return world, stopped_at, ended_at, pulses

    world, stopped_at, ended_at, pulses = run_mock(main)
    assert ended_at - stopped_at < 0.02  # not the 6 s left of fish 1's answer
    assert world.tick == 1 and world.lost == []
    assert pulses[-1][1] == "ended" and pulses[-1][0] - stopped_at < 0.02
    assert world.statistics().answer_time_median == 0.0  # only tick 0 was answered


def test_a_stop_while_the_world_waits_for_the_channel_ends_the_run_at_once() -> None:
    """Broadcasting fish and a channel whose token is up but which never reports: from
    tick 1 the world waits ``channel_timeout`` (100 s here) for each report. A stop asked
    5 s into the first wait ends the run then, before the fish are asked for tick 1."""
    behavior = registered().name
    scenario = Scenario(fish=2, duration=100.0, seed=2, behavior=behavior)
    keys = scenario.keys

    async def main() -> tuple[World, float, list[int]]:
        bus = MemoryBus()
        world = World(
            WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0, channel_timeout=100.0)
        )
        params = scenario.fish_params()
        async with (
            subscription(bus, keys.perception(0)) as perceptions,
            open_token(bus, keys.alive("channel", "mute")),
            trio.open_nursery() as nursery,
        ):
            nursery.start_soon(world.run, bus)
            for fish_id in range(2):
                await nursery.start(Fish(FishSettings((fish_id,), params, keys)).run, bus)
            await trio.sleep(5.0)
            world.control(ControlRequest("stop"))
            await _until_state(world, "stopped")
            ended_at = trio.current_time()
            ticks = [decode(p, Perception).tick for _, p in perceptions.drain()]
            nursery.cancel_scope.cancel()
        return world, ended_at, ticks

    world, ended_at, ticks = run_mock(main)
    assert ended_at < 5.02  # not the 95 s left of the channel timeout
    assert world.tick == 1 and ticks == [0]  # no perception of tick 1 went out


def test_a_stop_in_realtime_ends_the_run_without_waiting_out_the_period() -> None:
    """In realtime mode the world takes commands until the tick's wall-clock end: with a
    10-s period, a stop asked 1 s into tick 1 ends the run then, not 9 s later, and the
    command that did not come by then is not counted late."""
    scenario = Scenario(fish=1, duration=100.0, control_period=10.0, time_mode="realtime")
    keys = scenario.keys

    async def main() -> tuple[World, float, float]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0))
        asked = trio.Event()

        async def on_perception(tick: int) -> None:
            if tick == 1:
                asked.set()

        async with trio.open_nursery() as nursery:
            nursery.start_soon(_answer_after, bus, keys, 0, [0.0, 5.0], on_perception)
            nursery.start_soon(world.run, bus)
            await asked.wait()
            await trio.sleep(1.0)
            stopped_at, ended_at = await _stop(world)
            nursery.cancel_scope.cancel()
        return world, stopped_at, ended_at

    world, stopped_at, ended_at = run_mock(main)
    assert ended_at - stopped_at < 0.02
    assert world.tick == 1 and world.late_commands == 0


def test_an_interrupted_world_tells_its_fish_the_run_has_ended() -> None:
    """A world cancelled in mid-run (Ctrl-C on ``fishswarm world``) still says its run has
    ended: its fish stop watching for perceptions instead of counting their silence as a
    fault (their watchdog would turn the fins off 5 s later and count it)."""
    scenario = Scenario(fish=2, duration=100.0)
    keys = scenario.keys

    async def main() -> tuple[list[str], int]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        observer = Observer(keys)
        fish = Fish(FishSettings((0, 1), scenario.fish_params(), keys))
        heard: list[str] = []
        bus.subscribe(
            keys.world_pulse, lambda key, payload: heard.append(decode(payload, WorldPulse).state)
        )
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(fish.run, bus)
            async with trio.open_nursery() as world_nursery:
                world_nursery.start_soon(world.run, bus)
                await observer.wait_for_tick(3)
                world_nursery.cancel_scope.cancel()
            await trio.sleep(20.0)  # four watchdog periods
            nursery.cancel_scope.cancel()
        return heard, fish.statistics().watchdog_stops

    heard, stops = run_mock(main)
    assert stops == 0
    assert heard == ["ended"]  # the ticks took no simulated time: no pulse before


def test_a_stop_just_before_the_fish_are_asked_sends_the_ticks_snapshot() -> None:
    """The world sends a tick's snapshot after its perceptions (so that it is built while
    the fish decide). A stop that comes in the instant the world yields before asking ends
    the run at that tick: its snapshot goes out all the same, and the run's last pulse and
    last snapshot name the same tick."""
    scenario = Scenario(fish=2, duration=100.0)
    keys = scenario.keys

    class StopWhileYielding:
        """The world's resume event, never cleared, whose wait lets a stop in at tick 3 (as
        a control request handled in that instant would)."""

        def __init__(self, world: World) -> None:
            self.world = world

        def is_set(self) -> bool:
            return True

        def set(self) -> None:
            pass

        async def wait(self) -> None:
            if self.world.tick == 3 and self.world.state_name == "running":
                self.world.control(ControlRequest("stop"))
            await trio.lowlevel.checkpoint()

    async def main() -> tuple[World, Observer]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        world._resume = cast(trio.Event, StopWhileYielding(world))
        observer = Observer(keys)
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            await nursery.start(Fish(FishSettings((0, 1), scenario.fish_params(), keys)).run, bus)
            nursery.start_soon(world.run, bus)
            await _until_state(world, "stopped")
            await trio.sleep(1.0)
            nursery.cancel_scope.cancel()
        return world, observer

    world, observer = run_mock(main)
    assert world.tick == 3
    assert [p.tick for p in observer.history] == [0, 1, 2, 3]


def test_realtime_answer_times_are_taken_over_the_ticks_every_fish_answered_in_time() -> None:
    """Realtime, 1-s periods: the fish answers after 0.2, 0.4, 0.6 and 0.8 s, then too late
    (1.5 s). The median of the four in time is 0.5 s; the late one is not an answer time."""
    scenario = Scenario(fish=1, duration=5.0, control_period=1.0, time_mode="realtime")

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.0))
        async with trio.open_nursery() as nursery:
            nursery.start_soon(_answer_after, bus, scenario.keys, 0, [0.2, 0.4, 0.6, 0.8, 1.5])
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    statistics = world.statistics()
    assert statistics.answer_time_median == pytest.approx(0.5)
    assert statistics.late_commands == 1


def test_a_world_waiting_its_turn_takes_none_of_the_running_worlds_commands() -> None:
    """A world alone, waiting for its fish, is not queued; behind another world of its swarm
    (here one that took its turn in the same instant, with a lower run id) it is, and the
    commands and school batches of that world's run are not its own to count (nothing is
    rejected); once it has started, a later world that comes up does not queue it again."""
    scenario = Scenario(fish=2, duration=2.0, control_period=1.0, time_mode="realtime")
    keys = scenario.keys
    params = scenario.fish_params()
    batch = CommandBatch(
        5, np.array([1]), np.zeros((1, 4)), np.zeros(1, dtype=bool), np.zeros(1, dtype=np.int64)
    )

    async def main() -> tuple[World, list[bool], list[bool]]:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        queued = []
        answering = []  # the flag queries read as they come
        async with trio.open_nursery() as nursery:
            nursery.start_soon(world.run, bus)
            await trio.sleep(1.0)  # no fish yet, no other world
            queued.append(world.queued)
            answering.append(world.answering)
            other = bus.declare_token(keys.alive("world", 12345))
            await nursery.start(Fish(FishSettings((0,), params, keys)).run, bus)
            await nursery.start(Fish(FishSettings((1,), params, keys, school="t")).run, bus)
            await trio.sleep(1.0)
            queued.append(world.queued)
            answering.append(world.answering)
            # The other world's run, answered by the fish: a command and a batch of its tick 5.
            bus.put(keys.command(0), encode(Command(0, 5, np.zeros(4))))
            bus.put(keys.school_commands("t"), encode(batch))
            await trio.sleep(1.0)
            queued.append(world.queued)
            answering.append(world.answering)
            other.undeclare()
            await _until_state(world, "running")
            later = bus.declare_token(keys.alive("world", 54321))
            await trio.sleep(0.1)
            queued.append(world.queued)
            answering.append(world.answering)
            await _until_state(world, "finished")
            later.undeclare()
            nursery.cancel_scope.cancel()
        return world, queued, answering

    world, queued, answering = run_mock(main)
    assert queued == [False, True, True, False]
    assert answering == [True, False, False, True]
    assert world.tick == 2 and world.lost == []
    assert world.statistics().rejected == {}


def test_realtime_answer_times_run_until_the_last_fish_of_the_tick_answered() -> None:
    """Realtime, 1-s periods, two fish: fish 0 answers after 0.2 s (and repeats itself at
    0.8 s), fish 1 after 0.6 s. Each tick's answer time is 0.6 s: neither the first answer
    nor a message after the last one makes one."""
    scenario = Scenario(fish=2, duration=4.0, control_period=1.0, time_mode="realtime")
    keys = scenario.keys

    async def fish_zero(bus: MemoryBus) -> None:
        async with subscription(bus, keys.perception(0)) as perceptions:
            bus.declare_token(keys.alive("fish", 0))
            while True:
                perception = decode((await perceptions.receive())[1], Perception)
                command = encode(Command(0, perception.tick, np.zeros(4)))
                await trio.sleep(0.2)
                bus.put(keys.command(0), command)
                await trio.sleep(0.6)
                bus.put(keys.command(0), command)  # again: a duplicate, no answer time

    async def main() -> World:
        bus = MemoryBus()
        world = World(WorldSettings(scenario, expected_fish=(0, 1), admit_delay=0.0))
        async with trio.open_nursery() as nursery:
            nursery.start_soon(fish_zero, bus)
            nursery.start_soon(_answer_after, bus, keys, 1, [0.6] * 4)
            await world.run(bus)
            nursery.cancel_scope.cancel()
        return world

    world = run_mock(main)
    statistics = world.statistics()
    assert statistics.late_commands == 0 and world.lost == []
    assert statistics.rejected == {"duplicate": 4}
    assert statistics.answer_time_median == pytest.approx(0.6)
    assert statistics.answer_time_p90 == pytest.approx(0.6)


def test_a_warning_names_at_most_four_differing_parameters() -> None:
    from fishswarm.actors.world import _parts_named

    ours = {name: "0" for name in "abcdef"}
    assert _parts_named(ours, ours) == ""
    assert _parts_named(ours, {**ours, "c": "1"}) == "their c differs; "
    assert _parts_named(ours, {**ours, "b": "1", "e": "1"}) == "their b and e differ; "
    every = {name: "1" for name in ours}
    assert _parts_named(ours, every) == "their a, b, c, d and 2 more differ; "
