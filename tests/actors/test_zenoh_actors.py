"""Single actors over real Zenoh on 127.0.0.1: the channel's situated deliveries, and the
world's control and scenario queryables."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
import trio

from fishswarm.actors.channel import Channel
from fishswarm.actors.control import UnreadableSettings, ask_scenario, run_control
from fishswarm.actors.fish import Fish, FishSettings
from fishswarm.actors.session import SessionSettings, open_session
from fishswarm.actors.world import World, WorldSettings
from fishswarm.actors.zenoh_bus import ZenohBus, open_queryable, query, reply
from fishswarm.protocols.codec import decode, encode
from fishswarm.protocols.messages import (
    Broadcast,
    ChannelReport,
    ControlReply,
    ControlRequest,
    Delivery,
    RunSettings,
    Snapshot,
)
from fishswarm.sim.scenario import ConfigError, Scenario
from tests.conftest import run_trio, subscription

pytestmark = pytest.mark.integration


def _snapshot(
    tick: int, position: list[list[float]], yaw: list[float], sent: list[int]
) -> Snapshot:
    count = len(position)
    return Snapshot(
        tick,
        float(tick),
        np.arange(count),
        np.array(position),
        np.zeros((count, 3)),
        np.array(yaw),
        np.zeros(count, dtype=np.int64),
        np.array(sent),
    )


def test_channel_delivers_in_range_with_sender_position_in_receiver_frame(endpoint: str) -> None:
    scenario = Scenario(fish=4, channel_range=1.0)
    keys = scenario.keys

    async def main() -> tuple[list[Delivery], ChannelReport, int]:
        router = SessionSettings(mode="router", listen=[endpoint])
        channel = Channel(scenario)
        async with open_session(router) as session:
            bus = ZenohBus(session)
            async with (
                subscription(bus, f"{keys.prefix}/fish/*/inbox") as inboxes,
                subscription(bus, keys.channel_report) as reports,
                trio.open_nursery() as nursery,
            ):
                await nursery.start(channel.run, bus)
                # A key whose fish id is not a number: rejected, and the channel goes on.
                bus.put(f"{keys.prefix}/fish/abc/outbox", b"\x00")
                bus.put(f"{keys.prefix}/fish/²/outbox", b"\x00")
                # Fish 0 at (1, 1) sends at tick 0; fish 1 (0.5 m ahead of 0, facing +y) and
                # fish 2 (right behind 0) are in range; fish 3 is 1.5 m away.
                bus.put(keys.outbox(0), encode(Broadcast(0, 0, "signal", np.array([7]))))
                snapshot = _snapshot(
                    1,
                    [[1.0, 1.0, 0.5], [1.5, 1.0, 0.5], [0.8, 1.0, 0.5], [2.5, 1.0, 0.5]],
                    [0.0, math.pi / 2, 0.0, 0.0],
                    [1, 0, 0, 0],
                )
                bus.put(keys.snapshot, encode(snapshot))
                with trio.fail_after(10):
                    report = decode((await reports.receive())[1], ChannelReport)
                    deliveries = [decode((await inboxes.receive())[1], Delivery) for _ in range(2)]
                nursery.cancel_scope.cancel()
        return deliveries, report, channel.statistics().rejected

    deliveries, report, rejected = run_trio(main)
    assert rejected == 2
    assert report.tick == 1
    assert report.inbox_counts.tolist() == [0, 1, 1, 0]
    by_receiver = {d.receiver_id: d for d in deliveries}
    assert set(by_receiver) == {1, 2}
    assert by_receiver[1].kind == "signal" and by_receiver[1].values.tolist() == [7]
    # Fish 1 faces +y; with z down its right side points to −x of the tank, where the sender
    # is, 0.5 m away: body (0, +0.5, 0).
    np.testing.assert_allclose(by_receiver[1].sender_position, [0.0, 0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(by_receiver[2].sender_position, [0.2, 0.0, 0.0], atol=1e-12)


def test_world_answers_control_queries_over_zenoh(endpoint: str) -> None:
    scenario = Scenario(fish=2, duration=100_000.0)

    async def main() -> tuple[list[ControlReply], int]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1)))
        params = scenario.fish_params()
        answers: list[ControlReply] = []
        async with (
            open_session(router) as hub,
            open_session(client) as other,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(
                Fish(FishSettings((0, 1), params, scenario.keys)).run, ZenohBus(other)
            )
            await nursery.start(run_control, hub, world)
            nursery.start_soon(world.run, ZenohBus(hub))

            async def ask(payload: bytes) -> list[bytes]:
                with trio.fail_after(10):
                    while True:  # until the queryable is known to the asker's router
                        replies = await query(other, scenario.keys.control, payload, timeout=1.0)
                        if replies or payload == b"garbage":
                            return replies

            for action in ("pause", "status", "stop"):
                (answer,) = await ask(encode(ControlRequest(action)))
                answers.append(decode(answer, ControlReply))
            assert await ask(b"garbage") == []
            with trio.fail_after(10):
                while world.state_name != "stopped":
                    await trio.sleep(0.01)
            nursery.cancel_scope.cancel()
        return answers, world.statistics().rejected["malformed"]

    (pause, status, stop), malformed = run_trio(main)
    assert (pause.state, status.state, stop.state) == ("paused", "paused", "stopping")
    assert status.live_fish == 2 and status.tick in (pause.tick, pause.tick + 1)
    assert malformed == 1


def test_a_world_waiting_its_turn_answers_no_query_until_its_turn(endpoint: str) -> None:
    """A world waiting for its fish answers the scenario and control queries; behind another
    world of its swarm it answers neither (they are the running world's: its settings, its
    pause or stop); when that world has left, it answers again."""
    scenario = Scenario(fish=2, duration=100_000.0)
    keys = scenario.keys
    status = encode(ControlRequest("status"))

    async def main() -> list[tuple[bool, list[str]]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1), start_timeout=60.0))
        answered: list[tuple[bool, list[str]]] = []
        async with (
            open_session(router) as hub,
            open_session(client) as other,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(run_control, hub, world)
            nursery.start_soon(world.run, ZenohBus(hub))

            async def until(queued: bool) -> None:
                with trio.fail_after(10):
                    while world.queued != queued:
                        await trio.sleep(0.01)

            async def ask() -> None:
                told = await ask_scenario(other, keys, timeout=1.0)
                replies = await query(other, keys.control, status, timeout=1.0)
                answered.append(
                    (told is not None, [decode(r, ControlReply).state for r in replies])
                )

            with trio.fail_after(10):
                while await ask_scenario(other, keys, timeout=1.0) is None:
                    pass  # until the queryable is known to the asker's router
            await ask()
            running = ZenohBus(other).declare_token(keys.alive("world", 12345))
            await until(queued=True)
            await ask()
            running.undeclare()
            await until(queued=False)
            await ask()
            nursery.cancel_scope.cancel()
        return answered

    assert run_trio(main) == [(True, ["waiting"]), (False, []), (True, ["waiting"])]


def test_a_view_learns_the_runs_settings_from_the_worlds_scenario_queryable(
    endpoint: str,
) -> None:
    scenario = Scenario(
        fish=3,
        behavior="formation",
        formation="diamond",
        tank=(2.0, 1.5, 1.0),
        landmark=(0.5, 0.25, 0.5),
        study_code=("lennard-jones",),
        swarm="lab-a",
        duration=100_000.0,
    )

    async def main() -> tuple[Scenario | None, Scenario | None]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2)))
        async with (
            open_session(router) as hub,
            open_session(client) as other,
            trio.open_nursery() as nursery,
        ):
            # Asked before any world serves: no answer within the wait.
            nobody = await ask_scenario(other, scenario.keys, timeout=0.3)
            await nursery.start(run_control, hub, world)
            with trio.fail_after(10):
                told = None
                while told is None:  # until the queryable is known to the asker's router
                    told = await ask_scenario(other, scenario.keys, timeout=1.0)
            nursery.cancel_scope.cancel()
        return nobody, told

    nobody, told = run_trio(main)
    assert nobody is None
    assert told is not None and told.to_dict() == scenario.to_dict()


@pytest.mark.parametrize(
    ("answer", "reason"),
    [
        # What a world of the last schema answered: the settings as JSON text.
        (json.dumps(Scenario().to_dict()).encode(), "is no run settings: not msgpack"),
        (encode(ControlReply("running", 4, 4.0, 25)), "expected a run_settings message"),
        (
            encode(RunSettings({"behavior": "gone-fishing", "fish": 3})),
            r"^the world's run has the behaviour 'gone-fishing', which is not installed here: "
            r"another package's \(docs/behaviors.md\)\?",
        ),
    ],
)
def test_an_answer_on_the_scenario_key_that_is_no_run_settings_is_refused_with_why(
    endpoint: str, answer: bytes, reason: str
) -> None:
    keys = Scenario().keys

    async def main() -> None:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        async with (
            open_session(router) as hub,
            open_session(client) as other,
            open_queryable(hub, keys.scenario, lambda: True) as asked,
            trio.open_nursery() as nursery,
        ):

            async def answer_badly() -> None:
                async for request, _ in asked:
                    reply(request, answer)

            async def ask_until_answered() -> None:
                while True:  # until the queryable is known to the asker's router
                    await ask_scenario(other, keys, timeout=1.0)

            nursery.start_soon(answer_badly)
            with trio.fail_after(10), pytest.raises(ConfigError, match=reason) as caught:
                await ask_until_answered()
            nursery.cancel_scope.cancel()
            if "gone-fishing" in reason:  # said, with the settings as told, to record them
                assert isinstance(caught.value, UnreadableSettings)
                assert caught.value.settings == {"behavior": "gone-fishing", "fish": 3}

    run_trio(main)


@pytest.mark.slow
@pytest.mark.parametrize("pulse_period", [0.1, 60.0])
def test_a_slow_world_keeps_its_fish_swimming_by_its_pulse(
    endpoint: str, monkeypatch: pytest.MonkeyPatch, pulse_period: float
) -> None:
    """Every perception takes the world 0.7 s to compute — longer than the fish's 0.4 s
    watchdog. Pulsing every 0.1 s while it computes, no fish is stopped; with its pulse
    (nearly) silent, every fish is stopped at every slow tick."""
    scenario = Scenario(fish=3, duration=3.0, seed=4)

    async def main() -> tuple[World, int, int]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2), pulse_period=pulse_period))
        sense = world.sim.sense

        def slow_sense() -> object:
            time.sleep(0.7)  # a large swarm's vision, in the world's worker thread
            return sense()

        monkeypatch.setattr(world.sim, "sense", slow_sense)
        school = Fish(
            FishSettings(
                (0, 1, 2), scenario.fish_params(), scenario.keys, perception_timeout=0.4, school="s"
            )
        )
        async with (
            open_session(router) as hub,
            open_session(client) as other,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(school.run, ZenohBus(other))
            with trio.fail_after(30):
                await world.run(ZenohBus(hub))
            await trio.sleep(0.6)  # longer than the watchdog: the run's end is heard
            nursery.cancel_scope.cancel()
        return world, school.statistics().watchdog_stops, len(world.lost)

    world, stops, lost = run_trio(main, timeout=60)
    assert world.state_name == "finished" and world.tick == 3 and lost == 0
    # Ticks 1, 2 and 3 are computed slowly after the fish decided; at tick 0 they had not.
    assert stops == (0 if pulse_period < 1 else 3 * 3)
