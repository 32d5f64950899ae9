"""Single actors over real Zenoh: the channel's deliveries, the fish's safety watchdog and the
world's control queryable."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio
import zenoh

from fishswarm.actors.bridge import (
    SessionSettings,
    open_session,
    open_subscription,
    open_token,
    publisher,
    query,
)
from fishswarm.actors.channel import Channel
from fishswarm.actors.fish import Fish, FishSettings
from fishswarm.actors.world import World, WorldSettings
from fishswarm.behaviors.policy import Memory, act
from fishswarm.protocols.codec import decode, encode
from fishswarm.protocols.messages import (
    Broadcast,
    ChannelReport,
    Command,
    CommandBatch,
    ControlReply,
    ControlRequest,
    Delivery,
    Perception,
    PerceptionBatch,
    Snapshot,
)
from fishswarm.scenario import Scenario
from fishswarm.simulation import policy_of
from tests.conftest import run_trio

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

    async def main() -> tuple[list[Delivery], ChannelReport]:
        router = SessionSettings(mode="router", listen=[endpoint])
        async with (
            open_session(router) as session,
            open_subscription(session, f"{keys.prefix}/fish/*/inbox") as inboxes,
            open_subscription(session, keys.channel_report) as reports,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(Channel(scenario).run, session)
            put = publisher(session)
            # Fish 0 at (1, 1) sends at tick 0; fish 1 (0.5 m ahead of 0, facing +y) and fish 2
            # (right behind 0) are in range; fish 3 is 1.5 m away.
            put(keys.outbox(0), encode(Broadcast(0, 0, "formation", 7)))
            snapshot = _snapshot(
                1,
                [[1.0, 1.0, 0.5], [1.5, 1.0, 0.5], [0.8, 1.0, 0.5], [2.5, 1.0, 0.5]],
                [0.0, math.pi / 2, 0.0, 0.0],
                [1, 0, 0, 0],
            )
            put(keys.snapshot, encode(snapshot))
            report = decode((await reports.receive())[1], ChannelReport)
            deliveries = [decode((await inboxes.receive())[1], Delivery) for _ in range(2)]
            nursery.cancel_scope.cancel()
        return deliveries, report

    deliveries, report = run_trio(main)
    assert report.tick == 1
    assert report.inbox_counts.tolist() == [0, 1, 1, 0]
    by_receiver = {d.receiver_id: d for d in deliveries}
    assert set(by_receiver) == {1, 2}
    assert by_receiver[1].kind == "formation" and by_receiver[1].value == 7
    # Fish 1 faces +y; with z down its right side points to −x of the tank, where the sender
    # is, 0.5 m away: body (0, +0.5, 0).
    np.testing.assert_allclose(by_receiver[1].sender_position, [0.0, 0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(by_receiver[2].sender_position, [0.2, 0.0, 0.0], atol=1e-12)


def test_fish_turns_fins_off_when_perceptions_stop_and_resumes(endpoint: str) -> None:
    scenario = Scenario()
    keys = scenario.keys
    settings = FishSettings((3,), policy_of(scenario), keys, perception_timeout=0.3)

    async def main() -> tuple[Command, Command, dict[str, int]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        fish = Fish(settings)
        async with (
            open_session(router) as session,
            open_subscription(session, keys.command(3)) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, session)
            with trio.fail_after(3):
                stop = decode((await commands.receive())[1], Command)
            perception = Perception(3, 1, 1.0, 0.5, np.array([[1.0, -0.1, 0.0]]), np.zeros((0, 3)))
            publisher(session)(keys.perception(3), encode(perception))
            with trio.fail_after(3):
                answer = decode((await commands.receive())[1], Command)
            nursery.cancel_scope.cancel()
        return stop, answer, fish.statistics()

    stop, answer, statistics = run_trio(main)
    assert stop.fins.tolist() == [0.0, 0.0, 0.0, 0.0] and stop.led is False
    # Dispersing from a neighbour ahead and a little left: the target lies behind to the right
    # (bearing ≈ 174°), so the left pectoral runs at min(1, 0.6 + 174/180) = 1, caudal off.
    assert answer.tick == 1
    assert answer.fins.tolist() == [0.0, 0.0, 1.0, 0.0]
    assert statistics["watchdog_stops"] >= 1


def test_school_answers_a_perception_batch_with_one_command_batch(endpoint: str) -> None:
    scenario = Scenario()
    keys = scenario.keys
    policy = policy_of(scenario)
    settings = FishSettings((5, 2), policy, keys, school="pond")
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

    async def main() -> tuple[CommandBatch, dict[str, int]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        fish = Fish(settings)
        async with (
            open_session(router) as session,
            open_subscription(session, keys.school_commands("pond")) as commands,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, session)
            put = publisher(session)
            put(keys.school_perceptions("pond"), encode(stranger))
            put(keys.school_perceptions("pond"), encode(batch))
            with trio.fail_after(3):
                answer = decode((await commands.receive())[1], CommandBatch)
            nursery.cancel_scope.cancel()
        return answer, fish.statistics()

    answer, statistics = run_trio(main)
    assert answer.tick == 4
    assert answer.ids.tolist() == [2, 5]
    for row, (neighbors, depth) in enumerate(((near, 0.5), (far, 0.2))):
        alone, _ = act(
            policy,
            neighbors[None],
            np.ones((1, len(neighbors)), bool),
            np.array([depth]),
            Memory.fresh(1),
        )
        np.testing.assert_array_equal(answer.fins[row], alone[0])
    assert answer.led.tolist() == [True, True]
    assert statistics["rejected"] == 1  # the batch naming fish 7, which the school lacks
    assert statistics["perceptions"] == 2 and statistics["commands"] == 2


def test_world_answers_status_pause_resume_and_stop(endpoint: str) -> None:
    scenario = Scenario(fish=2, duration=100_000.0)

    async def ask(session: zenoh.Session, action: str) -> ControlReply:
        request = encode(ControlRequest(action))
        replies = await query(session, scenario.keys.control, request, timeout=5.0)
        assert len(replies) == 1
        return decode(replies[0], ControlReply)

    async def main() -> list[ControlReply]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1)))
        policy = policy_of(scenario)
        answers = []
        async with (
            open_session(router) as hub,
            open_session(client) as other,
            trio.open_nursery() as nursery,
        ):
            for fish_id in (0, 1):
                await nursery.start(
                    Fish(FishSettings((fish_id,), policy, scenario.keys)).run, other
                )
            await nursery.start(world.run, hub)
            with trio.fail_after(10):
                while world.tick < 2:
                    await trio.sleep(0.01)
            answers.append(await ask(other, "pause"))
            paused_tick = world.tick
            await trio.sleep(0.3)
            answers.append(await ask(other, "status"))
            assert world.tick <= paused_tick + 1
            answers.append(await ask(other, "resume"))
            answers.append(await ask(other, "stop"))
            with trio.fail_after(10):
                while world.state_name != "stopped":
                    await trio.sleep(0.01)
            nursery.cancel_scope.cancel()
        return answers

    pause, status, resume, stop = run_trio(main)
    assert pause.state == "paused" and status.state == "paused"
    assert status.live_fish == 2
    assert resume.state == "running"
    assert stop.tick >= status.tick


def test_realtime_world_keeps_pace_and_a_late_fish_keeps_its_last_command(endpoint: str) -> None:
    # One fish answered by hand: full caudal for ticks 0 and 1, then silence. In realtime
    # mode the world does not wait: it goes on at one tick per 0.1 s of wall-clock time, the
    # silent fish keeps swimming on its last command, and nobody is marked lost.
    scenario = Scenario(fish=1, duration=1.2, control_period=0.1, time_mode="realtime", seed=3)
    keys = scenario.keys

    async def main() -> tuple[World, list[Snapshot], float]:
        router = SessionSettings(mode="router", listen=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0,), admit_delay=0.05))
        snapshots: list[Snapshot] = []
        async with (
            open_session(router) as session,
            open_subscription(session, keys.perception(0)) as perceptions,
            open_subscription(session, keys.snapshot) as snapshot_inbox,
            trio.open_nursery() as nursery,
        ):
            put = publisher(session)
            async with open_token(session, keys.alive("fish", 0)):
                nursery.start_soon(world.run, session)
                for _ in range(2):
                    with trio.fail_after(5):
                        perception = decode((await perceptions.receive())[1], Perception)
                    command = Command(0, perception.tick, np.array([1.0, 0.0, 0.0, 0.0]))
                    put(keys.command(0), encode(command))
                started = trio.current_time()
                with trio.fail_after(10):
                    while world.state_name != "finished":
                        await trio.sleep(0.01)
                elapsed = trio.current_time() - started
            while (item := snapshot_inbox.receive_nowait()) is not None:
                snapshots.append(decode(item[1], Snapshot))
            nursery.cancel_scope.cancel()
        return world, snapshots, elapsed

    world, snapshots, elapsed = run_trio(main)
    assert world.tick == 12
    assert world.lost == []
    assert world.late_commands == 10  # ticks 2–11 had no answer
    # From the answer at the start of tick 1 to the end: 11 control periods of wall-clock
    # time (1.1 s), within a few per cent.
    assert elapsed == pytest.approx(1.1, rel=0.05)
    speeds = [float(np.linalg.norm(s.velocity[0, :2])) for s in snapshots]
    assert speeds[-1] > speeds[2] > 0  # still accelerating on the last command: caudal on
