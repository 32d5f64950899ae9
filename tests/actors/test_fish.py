"""The fish actor on the in-memory Bus with trio's MockClock: decisions, schools, the safety
watchdog, deliveries, broadcasts, LEDs and new runs — each in simulated seconds."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trio
import trio.testing

from fishswarm import __version__
from fishswarm.actors.bus import MemoryBus
from fishswarm.actors.fish import MAX_WAITING_DELIVERIES, Fish, FishSettings, FishStatistics
from fishswarm.actors.inbox import Inbox
from fishswarm.behaviors.core import FishMemory, Perception, decide, pad_rows
from fishswarm.behaviors.core import Inbox as CoreInbox
from fishswarm.protocols.codec import decode, encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import (
    FORMATION_SHAPES,
    Broadcast,
    Command,
    CommandBatch,
    Delivery,
    FishAbout,
    PerceptionBatch,
    WorldPulse,
)
from fishswarm.protocols.messages import Perception as PerceptionMessage
from fishswarm.sim.scenario import Scenario
from tests.behaviors.signal_behavior import registered
from tests.conftest import run_mock, subscription

KEYS = KeySpace()
AHEAD = np.array([[1.0, -0.1, 0.0]])


def _perception(fish_id: int, tick: int, **changes: object) -> bytes:
    fields: dict[str, object] = {
        "fish_id": fish_id,
        "tick": tick,
        "time": float(tick),
        "depth": 0.5,
        "neighbors": AHEAD,
        "landmarks": np.zeros((0, 3)),
        **changes,
    }
    return encode(PerceptionMessage(**fields))  # type: ignore[arg-type]


def _batch(run: int, tick: int, ids: list[int], inbox: list[int]) -> bytes:
    count = len(ids)
    return encode(
        PerceptionBatch(
            tick, float(tick), np.array(ids), np.full(count, 0.5),
            np.zeros(count, dtype=np.int64), np.zeros((0, 3)),
            np.zeros(count, dtype=np.int64), np.zeros((0, 3)), np.array(inbox), run,
        )
    )  # fmt: skip


def test_watchdog_is_armed_by_a_perception_stops_the_fins_and_takes_the_worlds_pulse() -> None:
    settings = FishSettings((3,), Scenario().fish_params(), KEYS, perception_timeout=5.0)

    async def main() -> tuple[list[tuple[float, Command]], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        got: list[tuple[float, Command]] = []
        async with subscription(bus, KEYS.command(3)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            started = trio.current_time()

            async def next_command() -> None:
                _, payload = await commands.receive()
                got.append((trio.current_time() - started, decode(payload, Command)))

            await trio.sleep(20.0)  # no perception yet: the fins never ran, nothing to stop
            bus.put(KEYS.perception(3), _perception(3, 1))
            await next_command()  # the answer, at once
            await next_command()  # the watchdog, 5 s after the perception
            await trio.sleep(1.0)
            bus.put(KEYS.perception(3), _perception(3, 2))
            await next_command()  # the answer: the fish swims again
            for second in range(1, 14):
                await trio.sleep(1.0)
                # The world of the fish's run pulses for 9 s (a slow tick); pulses of another
                # run and a malformed one do not count.
                run = 0 if second <= 9 else 77
                bus.put(KEYS.world_pulse, encode(WorldPulse(run, 2, "running")))
            bus.put(KEYS.world_pulse, b"\x81\xa1t\xabworld_pulse")
            await next_command()  # the watchdog, 5 s after the last pulse of its run
            bus.put(KEYS.perception(3), _perception(3, 3))
            await next_command()  # the answer to the run's last perception
            bus.put(KEYS.world_pulse, encode(WorldPulse(0, 3, "ended")))
            await trio.sleep(30.0)  # the run is over: nothing more is watched
            nursery.cancel_scope.cancel()
        return got, fish.statistics()

    got, statistics = run_mock(main)
    times = [at for at, _ in got]
    assert times == [20.0, 25.0, 26.0, 40.0, 40.0]
    (_, answer), (_, stop), (_, again), (_, last), _ = got
    # Dispersing from a neighbour ahead and a little left: turn away with the left pectoral.
    assert answer.tick == 1 and answer.fins.tolist() == [0.0, 0.0, 1.0, 0.0] and answer.led
    assert stop.tick == 1 and stop.fins.tolist() == [0.0, 0.0, 0.0, 0.0] and stop.led is False
    assert again.tick == 2 and again.fins.tolist() == [0.0, 0.0, 1.0, 0.0]
    assert last.tick == 2 and last.fins.tolist() == [0.0, 0.0, 0.0, 0.0]
    # The watchdog's stops say so (a robot's driver reports them); decisions do not.
    assert [c.watchdog for _, c in got[:4]] == [None, True, None, True]
    assert statistics.watchdog_stops == 2 and statistics.commands == 5
    assert statistics.perceptions == 3 and statistics.rejected == 1


def test_watchdog_says_once_which_fish_it_stopped(caplog: pytest.LogCaptureFixture) -> None:
    settings = FishSettings(tuple(range(14)), Scenario().fish_params(), KEYS, school="pond")
    count = 14
    batch = PerceptionBatch(
        1,
        1.0,
        np.arange(count),
        np.full(count, 0.5),
        np.zeros(count, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(count, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(count, dtype=np.int64),
    )

    async def main() -> FishStatistics:
        bus = MemoryBus()
        fish = Fish(settings)
        async with (
            subscription(bus, KEYS.school_commands("pond")) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, bus)
            bus.put(KEYS.school_perceptions("pond"), encode(batch))
            await commands.receive()  # the answer
            _, payload = await commands.receive()  # the watchdog's stop, for all 14 at once
            assert decode(payload, CommandBatch).ids.tolist() == list(range(count))
            nursery.cancel_scope.cancel()
        return fish.statistics()

    with caplog.at_level(logging.WARNING, logger="fishswarm.actors.fish"):
        statistics = run_mock(main)
    assert statistics.watchdog_stops == count
    lines = [r.getMessage() for r in caplog.records if "no perception" in r.getMessage()]
    assert lines == [
        "14 fish (0, 1, 2, 3, 4, 5, 6, 7, 8, 9 …): no perception for 5.0 s, "
        "fins off until one comes"
    ]


def test_school_answers_a_batch_as_each_fish_would_alone() -> None:
    params = Scenario().fish_params()
    settings = FishSettings((5, 2), params, KEYS, school="pond")
    near = np.array([[0.3, 0.0, 0.0]])
    far = np.array([[1.0, -0.1, 0.0], [-0.5, 0.5, 0.1]])
    batch = PerceptionBatch(
        4,
        4.0,
        np.array([2, 5]),
        np.array([0.5, 0.2]),
        np.array([1, 2]),
        np.concatenate([near, far]),
        np.zeros(2, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(2, dtype=np.int64),
    )
    stranger = PerceptionBatch(
        5,
        5.0,
        np.array([2, 7]),
        np.zeros(2),
        np.zeros(2, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(2, dtype=np.int64),
        np.zeros((0, 3)),
        np.zeros(2, dtype=np.int64),
    )

    async def main() -> tuple[CommandBatch, FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        async with (
            subscription(bus, KEYS.school_commands("pond")) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, bus)
            bus.put(KEYS.school_perceptions("pond"), encode(stranger))
            bus.put(KEYS.school_perceptions("pond"), encode(batch))
            answer = decode((await commands.receive())[1], CommandBatch)
            nursery.cancel_scope.cancel()
        return answer, fish.statistics()

    answer, statistics = run_mock(main)
    assert answer.tick == 4 and answer.ids.tolist() == [2, 5]
    for row, (neighbors, depth) in enumerate(((near, 0.5), (far, 0.2))):
        rows, mask = pad_rows(np.array([len(neighbors)]), neighbors)
        alone = Perception(
            np.array([4.0]),
            np.array([depth]),
            rows,
            mask,
            np.zeros((1, 0, 3)),
            np.zeros((1, 0), bool),
        )
        _, decision = decide(FishMemory.fresh(params, 1), alone, CoreInbox.empty(1), params=params)
        np.testing.assert_array_equal(answer.fins[row], decision.fins[0])
    assert answer.led.tolist() == [True, True]
    assert statistics.rejected == 1  # the batch naming fish 7, which the school lacks
    assert statistics.perceptions == 2 and statistics.commands == 2


def test_tasks_woken_with_a_fish_run_before_it_decides() -> None:
    # In the launcher's process one step of the world wakes the fish and the observer: the
    # observer must hand a large school's metrics to its thread before the fish's decision
    # holds the event loop (trio runs the tasks woken together in either order).
    settings = FishSettings((3,), Scenario().fish_params(), KEYS)

    async def main() -> list[str]:
        bus = MemoryBus()
        fish = Fish(settings)
        order: list[str] = []
        bus.subscribe(KEYS.command(3), lambda key, payload: order.append("command"))
        async with trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            # Woken as the observer is: by an inbox, right after the fish's perception.
            snapshots = Inbox[int]()

            async def other() -> None:
                async for _ in snapshots:
                    order.append("other")

            nursery.start_soon(other)
            for tick in range(1, 21):
                await trio.testing.wait_all_tasks_blocked()
                bus.put(KEYS.perception(3), _perception(3, tick))
                snapshots.push(tick)
            await trio.testing.wait_all_tasks_blocked()
            nursery.cancel_scope.cancel()
        return order

    assert run_mock(main) == ["other", "command"] * 20


def test_fish_waits_for_announced_deliveries_then_broadcasts_before_its_command() -> None:
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((4,), params, KEYS, inbox_timeout=2.0)

    async def main() -> tuple[list[tuple[float, str, bytes]], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        order: list[tuple[float, str, bytes]] = []
        seen: Inbox[None] = Inbox()

        def note(key: str, payload: bytes) -> None:
            order.append((trio.current_time(), key, payload))
            seen.push(None)

        bus.subscribe(f"{KEYS.prefix}/fish/4/*", note)
        async with trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            bus.put(KEYS.perception(4), _perception(4, 2, inbox_count=2))
            await trio.sleep(1.0)  # one delivery only: the fish waits
            delivery = Delivery(4, 2, "signal", np.array([3]), np.array([0.2, 0.1, 0.0]))
            bus.put(KEYS.inbox(4), encode(delivery))
            await trio.sleep(0.5)
            bus.put(KEYS.inbox(4), encode(delivery))
            while sum(key.endswith("/command") for _, key, _ in order) < 1:
                await seen.receive()
            # A perception announcing one delivery that never comes: decided at the timeout.
            bus.put(KEYS.perception(4), _perception(4, 3, inbox_count=1))
            while sum(key.endswith("/command") for _, key, _ in order) < 2:
                await seen.receive()
            nursery.cancel_scope.cancel()
        return order, fish.statistics()

    order, statistics = run_mock(main)
    sent = [
        (at, key.rsplit("/", 1)[1])
        for at, key, _ in order
        if not key.endswith(("perception", "inbox"))
    ]
    # Up, the fish vouches for itself (run 0); on the first perception of a run it says what
    # it runs; then it waits, broadcasts, and commands.
    assert sent == [
        (0.0, "about"),
        (0.0, "about"),
        (1.5, "outbox"),
        (1.5, "command"),
        (3.5, "outbox"),
        (3.5, "command"),
    ]
    hello, about = (decode(p, FishAbout) for _, k, p in order if k.endswith("about"))
    assert hello.run == 0 and hello.ids.tolist() == [4]
    assert about.ids.tolist() == [4] and about.behavior == "test-signal"
    assert about.version == __version__
    outputs = [payload for _, key, payload in order if key.endswith(("outbox", "command"))]
    broadcast, command = decode(outputs[0], Broadcast), decode(outputs[1], Command)
    # It heard two signals, from (0.2, 0.1, 0): it swims there, LEDs lit, and says so.
    assert broadcast.tick == 2 and broadcast.values[:2].tolist() == [2, 0]
    assert command.broadcasts == 1 and command.led is True
    late = decode(outputs[3], Command)
    assert late.led is False  # heard nothing in time
    assert statistics.deliveries == 2 and statistics.deliveries_missed == 1
    assert statistics.broadcasts == 2


def test_a_fish_that_joins_a_run_keeps_the_deliveries_that_came_before_its_perception() -> None:
    # A fish that joins a run under way (a robot, a fish started by hand) may hear its
    # first tick's deliveries before its first perception: the world sends perceptions
    # only once the channel has delivered. Before, starting the run threw that mail away
    # and the fish waited the whole inbox timeout (here 5 s) for it, missing ticks.
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((4,), params, KEYS, inbox_timeout=5.0)

    async def main() -> tuple[float, Command, FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        async with subscription(bus, KEYS.command(4)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            await trio.sleep(1.0)
            delivery = Delivery(4, 3, "signal", np.array([3]), np.array([0.2, 0.1, 0.0]))
            bus.put(KEYS.inbox(4), encode(delivery))
            bus.put(KEYS.perception(4), _perception(4, 3, inbox_count=1, run=2))
            with trio.fail_after(10.0):
                _, payload = await commands.receive()
            answered = trio.current_time()
            nursery.cancel_scope.cancel()
        return answered, decode(payload, Command), fish.statistics()

    answered, command, statistics = run_mock(main)
    assert answered == 1.0  # at once, not at the inbox timeout
    assert command.tick == 3 and command.led is True  # it heard the signal
    assert statistics.deliveries == 1 and statistics.deliveries_missed == 0


def test_a_fish_in_its_first_run_drops_mail_of_other_ticks_it_heard_before() -> None:
    # Mail for tick 9, heard while no run had reached this fish (another process spoke for
    # its id, say), is no mail of the run it joins at tick 3: at tick 9 the fish waits for
    # the delivery announced then, and decides without it at the timeout.
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((4,), params, KEYS, inbox_timeout=5.0, perception_timeout=20.0)

    def delivery(tick: int) -> bytes:
        return encode(Delivery(4, tick, "signal", np.array([3]), np.array([0.2, 0.1, 0.0])))

    async def main() -> list[tuple[float, Command]]:
        bus = MemoryBus()
        answers: list[tuple[float, Command]] = []
        async with subscription(bus, KEYS.command(4)) as commands, trio.open_nursery() as nursery:
            await nursery.start(Fish(settings).run, bus)
            bus.put(KEYS.inbox(4), delivery(9))
            bus.put(KEYS.inbox(4), delivery(3))
            for tick in (3, 9):
                bus.put(KEYS.perception(4), _perception(4, tick, inbox_count=1, run=2))
                with trio.fail_after(10.0):
                    _, payload = await commands.receive()
                answers.append((trio.current_time(), decode(payload, Command)))
            nursery.cancel_scope.cancel()
        return answers

    (first_at, first), (later_at, later) = run_mock(main)
    assert first_at == 0.0 and first.tick == 3 and first.led is True
    assert later_at == 5.0 and later.tick == 9 and later.led is False


def test_a_fish_from_an_earlier_run_keeps_the_mail_of_the_run_it_joins() -> None:
    # Fish 4 served run 2 to tick 1; run 5 is under way when it joins at tick 7, and its
    # first tick's delivery comes before its first perception of run 5. Deliveries name
    # their run: this one is kept (before, a fish with an earlier run dropped it all and
    # waited the inbox timeout). Mail of run 9, another world's, is never served.
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((4,), params, KEYS, inbox_timeout=5.0, perception_timeout=20.0)

    def delivery(tick: int, run: int) -> bytes:
        return encode(Delivery(4, tick, "signal", np.array([3]), np.array([0.2, 0.1, 0.0]), run))

    async def main() -> tuple[list[tuple[float, Command]], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        answers: list[tuple[float, Command]] = []
        async with subscription(bus, KEYS.command(4)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)

            async def tick(tick: int, run: int, mail: int) -> None:
                bus.put(KEYS.perception(4), _perception(4, tick, inbox_count=mail, run=run))
                with trio.fail_after(10.0):
                    _, payload = await commands.receive()
                answers.append((trio.current_time(), decode(payload, Command)))

            await tick(0, 2, 0)
            await tick(1, 2, 0)
            bus.put(KEYS.inbox(4), delivery(7, 9))
            bus.put(KEYS.inbox(4), delivery(7, 5))
            await tick(7, 5, 1)
            # Run 9's mail for tick 8 comes, run 5's never does: decided at the timeout,
            # having heard nothing.
            bus.put(KEYS.inbox(4), delivery(8, 9))
            await tick(8, 5, 1)
            nursery.cancel_scope.cancel()
        return answers, fish.statistics()

    answers, statistics = run_mock(main)
    (_, first), (_, second), (joined_at, joined), (late_at, late) = answers
    assert (first.tick, second.tick) == (0, 1)
    assert joined_at == 0.0 and joined.tick == 7 and joined.led is True
    assert late_at == 5.0 and late.tick == 8 and late.led is False
    assert statistics.deliveries == 1 and statistics.deliveries_missed == 1


def test_mail_of_a_run_that_has_ended_is_let_go() -> None:
    # Run 5 ends (the world's pulse says so): its mail, waiting or late, is never kept.
    settings = FishSettings((4,), Scenario(behavior=registered().name).fish_params(), KEYS)

    async def main() -> tuple[int, FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        async with subscription(bus, KEYS.command(4)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            bus.put(KEYS.perception(4), _perception(4, 0, run=5))
            with trio.fail_after(10.0):
                await commands.receive()
            late = Delivery(4, 3, "signal", np.array([3]), np.array([0.2, 0.1, 0.0]), 5)
            bus.put(KEYS.inbox(4), encode(late))
            bus.put(KEYS.world_pulse, encode(WorldPulse(5, 0, "ended")))
            await trio.sleep(0.1)
            waiting = sum(len(mail) for mail in fish._mail.values())
            # The channel delivers a run's last tick after its world ended it: let go, not
            # counted as a bad message.
            bus.put(KEYS.inbox(4), encode(late))
            await trio.sleep(0.1)
            waiting += sum(len(mail) for mail in fish._mail.values())
            nursery.cancel_scope.cancel()
        return waiting, fish.statistics()

    waiting, statistics = run_mock(main)
    assert waiting == 0
    assert statistics.rejected == 0


def test_a_new_run_starts_the_fish_afresh() -> None:
    settings = FishSettings((1,), Scenario().fish_params(), KEYS)

    async def main() -> tuple[list[int], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        ticks: list[int] = []
        async with subscription(bus, KEYS.command(1)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            for run, tick in ((7, 0), (7, 1), (7, 1), (8, 0), (8, 1)):
                bus.put(KEYS.perception(1), _perception(1, tick, run=run))
                with trio.move_on_after(0.5):
                    ticks.append(decode((await commands.receive())[1], Command).tick)
            nursery.cancel_scope.cancel()
        return ticks, fish.statistics()

    ticks, statistics = run_mock(main)
    assert ticks == [0, 1, 0, 1]  # the repeated tick 1 of run 7 is stale; run 8 starts at 0
    assert statistics.rejected == 1 and statistics.runs == 1


def test_a_new_run_frees_every_fish_of_a_batch_it_drops() -> None:
    settings = FishSettings((1, 2), Scenario().fish_params(), KEYS, school="pair")

    async def main() -> tuple[list[list[int]], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        answered: list[list[int]] = []
        async with (
            subscription(bus, KEYS.school_commands("pair")) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, bus)
            # Run 5: both fish wait for a delivery that never comes...
            bus.put(KEYS.school_perceptions("pair"), _batch(5, 3, [1, 2], [1, 1]))
            await trio.sleep(1.0)
            # ... when run 6 starts with fish 1 alone, then fish 2 (jitter-style subsets).
            bus.put(KEYS.school_perceptions("pair"), _batch(6, 1, [1], [0]))
            bus.put(KEYS.school_perceptions("pair"), _batch(6, 1, [2], [0]))
            for _ in range(2):
                with trio.fail_after(1.0):
                    answered.append(
                        decode((await commands.receive())[1], CommandBatch).ids.tolist()
                    )
            nursery.cancel_scope.cancel()
        return answered, fish.statistics()

    answered, statistics = run_mock(main)
    assert sorted(answered) == [[1], [2]]
    assert statistics.rejected == 0 and statistics.runs == 1


def test_deliveries_are_held_to_what_the_perceptions_announce() -> None:
    """A flood beyond the mailbox's bound, deliveries nobody announced or for a tick already
    decided, more deliveries than announced, and a perception that comes while the last one
    still waits for its deliveries: each is refused or left out, and counted."""
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((4,), params, KEYS, inbox_timeout=2.0)

    def delivery(tick: int) -> bytes:
        return encode(Delivery(4, tick, "signal", np.array([3]), np.array([0.2, 0.1, 0.0])))

    async def main() -> tuple[list[tuple[float, Command]], list[Broadcast], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        got: list[tuple[float, Command]] = []
        async with (
            subscription(bus, KEYS.command(4)) as commands,
            subscription(bus, KEYS.outbox(4)) as outbox,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, bus)
            started = trio.current_time()

            async def next_command() -> None:
                _, payload = await commands.receive()
                got.append((trio.current_time() - started, decode(payload, Command)))

            bus.put(KEYS.perception(4), _perception(4, 1))  # the run starts, mail empty
            await next_command()
            flood = delivery(2)
            for _ in range(MAX_WAITING_DELIVERIES + 1):  # the last one is one too many
                bus.put(KEYS.inbox(4), flood)
            # Tick 2 announces none: what waits for it is dropped with its decision.
            bus.put(KEYS.perception(4), _perception(4, 2))
            await next_command()
            bus.put(KEYS.inbox(4), delivery(2))  # for a tick decided: stale
            # Three for tick 3, which announces two: the third is not heard.
            for _ in range(3):
                bus.put(KEYS.inbox(4), delivery(3))
            bus.put(KEYS.perception(4), _perception(4, 3, inbox_count=2))
            await next_command()
            # Tick 4 waits for a delivery that never comes; tick 5 meanwhile is refused.
            bus.put(KEYS.perception(4), _perception(4, 4, inbox_count=1))
            await trio.sleep(0.5)
            bus.put(KEYS.perception(4), _perception(4, 5))
            await next_command()
            await trio.sleep(1.0)  # within the watchdog's 5 s: nothing more comes
            nursery.cancel_scope.cancel()
            leftover = commands.drain()
            broadcasts = [decode(payload, Broadcast) for _, payload in outbox.drain()]
        assert leftover == []  # nothing for tick 5
        return got, broadcasts, fish.statistics()

    got, broadcasts, statistics = run_mock(main)
    assert [(at, command.tick) for at, command in got] == [(0.0, 1), (0.0, 2), (0.0, 3), (2.0, 4)]
    # The test behaviour broadcasts how many signals it heard: none, none, two, none.
    assert [b.values[0] for b in broadcasts] == [0, 0, 2, 0]
    assert statistics.deliveries == 2 and statistics.deliveries_missed == 1
    assert statistics.perceptions == 4
    assert statistics.rejected == 3  # the flood's last, the stale delivery, tick 5


def test_a_school_waits_for_the_delivery_of_any_fish_that_announced_one() -> None:
    """Fish 1 waits for none, fish 2 for one: the batch is answered when fish 2's comes."""
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((1, 2), params, KEYS, school="pair", inbox_timeout=3.0)

    async def main() -> tuple[float, CommandBatch]:
        bus = MemoryBus()
        async with (
            subscription(bus, KEYS.school_commands("pair")) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(Fish(settings).run, bus)
            started = trio.current_time()
            bus.put(KEYS.school_perceptions("pair"), _batch(4, 1, [1, 2], [0, 1]))
            await trio.sleep(1.0)
            signal = Delivery(2, 1, "signal", np.array([1]), np.array([0.2, 0.1, 0.0]))
            bus.put(KEYS.inbox(2), encode(signal))
            _, payload = await commands.receive()
            nursery.cancel_scope.cancel()
        return trio.current_time() - started, decode(payload, CommandBatch)

    waited, answer = run_mock(main)
    assert waited == 1.0  # not at once, and not at the 3-s timeout
    assert answer.ids.tolist() == [1, 2]
    assert answer.led.tolist() == [False, True]  # only fish 2 heard a signal


def test_a_schools_watchdog_stops_its_fish_in_id_order_at_tick_zero() -> None:
    """Fish given as (5, 2), silent after a perception whose delivery never comes: the stop
    batch names them ascending, as a batch must, and repeats tick 0, not the −1 of no
    answer yet."""
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings(
        (5, 2), params, KEYS, school="pair", perception_timeout=1.0, inbox_timeout=4.0
    )

    async def main() -> tuple[float, CommandBatch, FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        async with (
            subscription(bus, KEYS.school_commands("pair")) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, bus)
            bus.put(KEYS.school_perceptions("pair"), _batch(4, 0, [2, 5], [1, 1]))
            _, payload = await commands.receive()
            at = trio.current_time()
            nursery.cancel_scope.cancel()
        return at, decode(payload, CommandBatch), fish.statistics()

    at, stop, statistics = run_mock(main)
    assert at == 1.0
    assert stop.tick == 0 and stop.ids.tolist() == [2, 5]
    assert stop.fins.tolist() == [[0.0] * 4] * 2
    assert stop.watchdog is True  # so that its world takes it for no second process's
    assert statistics.watchdog_stops == 2


def test_a_new_run_forgets_the_formation_an_operator_asked_for() -> None:
    """Run 7 is told to take a pyramid; run 8 says nothing and takes the configured column.
    Each formation fish's flag names the shape it holds."""
    params = Scenario(behavior="formation", formation="column").fish_params()
    settings = FishSettings((1,), params, KEYS)

    async def main() -> list[int]:
        bus = MemoryBus()
        shapes: list[int] = []
        async with (
            subscription(bus, KEYS.outbox(1)) as outbox,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(Fish(settings).run, bus)
            for run, formation in ((7, "column"), (7, "pyramid"), (8, None)):
                tick = 0 if run == 8 else len(shapes)
                bus.put(KEYS.perception(1), _perception(1, tick, run=run, formation=formation))
                flag = decode((await outbox.receive())[1], Broadcast)
                shapes.append(int(flag.values[0]))
            nursery.cancel_scope.cancel()
        return shapes

    column, pyramid = FORMATION_SHAPES.index("column"), FORMATION_SHAPES.index("pyramid")
    assert run_mock(main) == [column, pyramid, column]


def test_a_late_perception_of_an_ended_run_does_not_start_it_again() -> None:
    """Run 3 ends; run 4 begins and its tick 1 waits for a delivery when a late tick 5 of
    run 3 comes: that is refused, and run 4 goes on as if it had not come."""
    params = Scenario(behavior=registered().name).fish_params()
    settings = FishSettings((1,), params, KEYS, inbox_timeout=3.0)

    async def main() -> tuple[list[tuple[float, int]], FishStatistics]:
        bus = MemoryBus()
        fish = Fish(settings)
        got: list[tuple[float, int]] = []
        async with subscription(bus, KEYS.command(1)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            bus.put(KEYS.perception(1), _perception(1, 4, run=3))
            got.append((trio.current_time(), decode((await commands.receive())[1], Command).tick))
            bus.put(KEYS.world_pulse, encode(WorldPulse(3, 4, "ended")))
            bus.put(KEYS.perception(1), _perception(1, 0, run=4))
            got.append((trio.current_time(), decode((await commands.receive())[1], Command).tick))
            bus.put(KEYS.perception(1), _perception(1, 1, run=4, inbox_count=1))
            await trio.sleep(0.5)
            bus.put(KEYS.perception(1), _perception(1, 5, run=3))
            await trio.sleep(0.5)
            signal = Delivery(1, 1, "signal", np.array([2]), np.array([0.2, 0.1, 0.0]))
            bus.put(KEYS.inbox(1), encode(signal))
            answer = decode((await commands.receive())[1], Command)
            got.append((trio.current_time(), answer.tick))
            assert answer.led  # it heard run 4's signal
            nursery.cancel_scope.cancel()
        return got, fish.statistics()

    got, statistics = run_mock(main)
    assert got == [(0.0, 4), (0.0, 0), (1.0, 1)]
    assert statistics.rejected == 1 and statistics.runs == 1


def test_a_run_after_run_zero_is_counted_as_a_new_run() -> None:
    settings = FishSettings((1,), Scenario().fish_params(), KEYS)

    async def main() -> FishStatistics:
        bus = MemoryBus()
        fish = Fish(settings)
        async with subscription(bus, KEYS.command(1)) as commands, trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            for run in (0, 9):
                bus.put(KEYS.perception(1), _perception(1, 0, run=run))
                await commands.receive()
            nursery.cancel_scope.cancel()
        return fish.statistics()

    assert run_mock(main).runs == 1


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"fish_ids": ()}, "fish_ids must be distinct and not empty"),
        ({"fish_ids": (1, 2, 1)}, "fish_ids must be distinct and not empty"),
        ({"perception_timeout": 0.0}, "perception_timeout must be a positive"),
        ({"inbox_timeout": 0.0}, "inbox_timeout must be a positive"),
        ({"inbox_timeout": float("nan")}, "inbox_timeout must be a positive"),
    ],
)
def test_bad_fish_settings_say_what_is_wrong(changes: dict[str, object], message: str) -> None:
    fields: dict[str, object] = {"fish_ids": (1,), "params": Scenario().fish_params(), **changes}
    with pytest.raises(ValueError, match=message):
        FishSettings(**fields)  # type: ignore[arg-type]


def test_each_fish_of_an_actor_is_watched_from_its_own_last_perception() -> None:
    """Fish 1 perceives at 0 and 4 s, fish 2 at 3 s, each on its own keys: with a 5-s
    timeout fish 2 is stopped at 8 s and fish 1 at 9 s (not both at the later time)."""
    settings = FishSettings((1, 2), Scenario().fish_params(), KEYS, perception_timeout=5.0)

    async def main() -> list[tuple[float, int]]:
        bus = MemoryBus()
        stops: list[tuple[float, int]] = []
        async with (
            subscription(bus, f"{KEYS.prefix}/fish/*/command") as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(Fish(settings).run, bus)
            bus.put(KEYS.perception(1), _perception(1, 0))
            await commands.receive()
            await trio.sleep(3.0)
            bus.put(KEYS.perception(2), _perception(2, 0))
            await commands.receive()
            await trio.sleep(1.0)
            bus.put(KEYS.perception(1), _perception(1, 1))
            await commands.receive()
            for _ in range(2):
                _, payload = await commands.receive()
                stops.append((trio.current_time(), decode(payload, Command).fish_id))
            nursery.cancel_scope.cancel()
        return stops

    assert run_mock(main) == [(8.0, 2), (9.0, 1)]
