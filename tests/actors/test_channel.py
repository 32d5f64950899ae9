"""The channel on the in-memory Bus under trio's MockClock: it delivers exactly what each
snapshot announces, whatever else arrives and in whatever order."""

from __future__ import annotations

import contextlib
import logging
import re

import numpy as np
import pytest
import trio

from fishswarm.actors import channel as channel_module
from fishswarm.actors.bus import MemoryBus, open_token
from fishswarm.actors.channel import Channel
from fishswarm.actors.inbox import Inbox
from fishswarm.behaviors.formation import NO_HOPS, flag_by_light
from fishswarm.protocols.codec import decode, encode
from fishswarm.protocols.messages import (
    DARK,
    FLASHING,
    FORMATION_SHAPES,
    STEADY,
    Broadcast,
    ChannelReport,
    Delivery,
    FormationFlag,
    Snapshot,
)
from fishswarm.sim.scenario import ConfigError, Scenario
from tests.conftest import run_mock, subscription

SCENARIO = Scenario(fish=3)
KEYS = SCENARIO.keys
IDS = np.array([0, 1, 2])
# Three fish in a row 0.1 m apart, all in range of one another.
POSITION = np.array([[0.5, 0.5, 0.5], [0.6, 0.5, 0.5], [0.7, 0.5, 0.5]])


def snapshot(tick: int, broadcasts: list[int], run: int = 0) -> bytes:
    zeros = np.zeros(3, dtype=np.int64)
    return encode(
        Snapshot(
            tick, float(tick), IDS, POSITION, np.zeros((3, 3)), np.zeros(3), zeros,
            np.array(broadcasts, dtype=np.int64), run=run,
        )
    )  # fmt: skip


def broadcast(sender: int, tick: int, value: int, run: int = 0) -> bytes:
    return encode(Broadcast(sender, tick, "signal", np.array([value]), run))


def test_only_announced_broadcasts_are_delivered_however_they_arrive() -> None:
    async def main() -> tuple[list[ChannelReport], list[Delivery], Channel]:
        bus = MemoryBus()
        channel = Channel(SCENARIO)
        async with (
            subscription(bus, KEYS.channel_report) as reports,
            subscription(bus, KEYS.fish_inboxes()) as inboxes,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(channel.run, bus)
            bus.put(KEYS.snapshot, snapshot(0, [0, 0, 0]))
            await trio.sleep(0.01)
            # Fish 1's broadcast of tick 0 reaches the channel although the world did not
            # count it (its command came late), before fish 0's, which the world counted.
            bus.put(KEYS.outbox(1), broadcast(1, 0, 7))
            bus.put(KEYS.snapshot, snapshot(1, [1, 0, 0]))
            await trio.sleep(0.01)
            # The next snapshot comes while the channel still waits for fish 0's.
            bus.put(KEYS.outbox(2), broadcast(2, 1, 5))
            bus.put(KEYS.snapshot, snapshot(2, [0, 0, 1]))
            await trio.sleep(0.01)
            bus.put(KEYS.outbox(0), broadcast(0, 0, 9))
            with trio.fail_after(10):
                got = [decode((await reports.receive())[1], ChannelReport) for _ in range(2)]
            nursery.cancel_scope.cancel()
        deliveries = [decode(payload, Delivery) for _, payload in inboxes.drain()]
        return got, deliveries, channel

    reports, deliveries, channel = run_mock(main)
    # Tick 1: fish 0's broadcast, to fish 1 and 2; tick 2: fish 2's, to fish 0 and 1.
    assert [report.tick for report in reports] == [1, 2]
    assert reports[0].inbox_counts.tolist() == [0, 1, 1]
    assert reports[1].inbox_counts.tolist() == [1, 1, 0]
    assert sorted((d.tick, d.receiver_id, int(d.values[0])) for d in deliveries) == [
        (1, 1, 9), (1, 2, 9), (2, 0, 5), (2, 1, 5),
    ]  # fmt: skip
    statistics = channel.statistics()
    assert statistics.missing_broadcasts == 0 and statistics.rejected == 0
    assert statistics.unannounced == 1  # fish 1's
    assert statistics.delivered == 4


def test_broadcasts_a_snapshot_announces_none_of_are_counted_and_let_go(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # Every broadcaster of a tick was late (realtime mode): the snapshot announces nothing,
    # and what came is counted, not kept for ever; said once, and not as a bad message.
    async def main() -> Channel:
        bus = MemoryBus()
        channel = Channel(SCENARIO)
        async with trio.open_nursery() as nursery:
            await nursery.start(channel.run, bus)
            bus.put(KEYS.snapshot, snapshot(0, [0, 0, 0]))
            for tick in range(1, 50):
                await trio.sleep(0.01)
                bus.put(KEYS.outbox(1), broadcast(1, tick - 1, tick))
                bus.put(KEYS.snapshot, snapshot(tick, [0, 0, 0]))
            await trio.sleep(0.01)
            nursery.cancel_scope.cancel()
        return channel

    with caplog.at_level(logging.INFO, "fishswarm"):
        channel = run_mock(main)
    assert channel.statistics().unannounced == 49
    assert channel.statistics().rejected == 0
    said = [(r.levelname, r.getMessage()) for r in caplog.records if "fish 1" in r.getMessage()]
    assert said == [
        (
            "INFO",
            "channel: a broadcast of fish 1 of tick 0, which the snapshot of tick 1 does not "
            "announce (its command came late or not at all), not delivered; further ones of "
            "this fish are counted as unannounced broadcasts",
        )
    ]
    assert channel.statistics().delivered == 0


def test_a_new_runs_first_broadcasts_that_come_before_its_first_snapshot_are_delivered() -> None:
    # Run 7 went to tick 15; a new world's run 8 starts, and its fish's broadcasts of tick
    # 0 reach the channel before the run's first snapshot does (another path through the
    # router). They name their run: kept for it, and delivered when announced (they were
    # refused as stale against run 7's ticks, and the run went otherwise than its seed
    # says). Run 9's, whose snapshots never come, are let go when run 8's first comes.
    deliveries, channel = _run_8_after(
        [
            (0, broadcast(0, 0, 4, run=8)),
            (1, broadcast(1, 0, 5, run=9)),
            (2, broadcast(2, 3, 6, run=8)),  # no first tick: let go
        ],
        run_7_ticks=16,
    )
    assert sorted((d.receiver_id, d.tick, d.run, int(d.values[0])) for d in deliveries) == [
        (1, 1, 8, 4), (2, 1, 8, 4),
    ]  # fmt: skip
    statistics = channel.statistics()
    assert statistics.missing_broadcasts == 0
    assert statistics.unannounced == 2 and statistics.rejected == 0


def _run_8_after(
    early: list[tuple[int, bytes]], *, run_7_ticks: int
) -> tuple[list[Delivery], Channel]:
    """Run 7's first ``run_7_ticks`` snapshots, then the broadcasts ``early`` (sender,
    payload) before run 8's first snapshot, then run 8's ticks 0 and 1 (which announces
    fish 0's broadcast of tick 0): what the channel delivered, and the channel."""

    async def main() -> tuple[list[Delivery], Channel]:
        bus = MemoryBus()
        channel = Channel(SCENARIO)
        async with (
            subscription(bus, KEYS.channel_report) as reports,
            subscription(bus, KEYS.fish_inboxes()) as inboxes,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(channel.run, bus)
            for tick in range(run_7_ticks):
                bus.put(KEYS.snapshot, snapshot(tick, [0, 0, 0], run=7))
                await trio.sleep(0.01)
            for sender, payload in early:
                bus.put(KEYS.outbox(sender), payload)
            await trio.sleep(0.01)
            bus.put(KEYS.snapshot, snapshot(0, [0, 0, 0], run=8))
            await trio.sleep(0.01)
            bus.put(KEYS.snapshot, snapshot(1, [1, 0, 0], run=8))
            with trio.fail_after(10):
                report = decode((await reports.receive())[1], ChannelReport)
            nursery.cancel_scope.cancel()
        assert report.tick == 1 and report.inbox_counts.tolist() == [0, 1, 1]
        return [decode(payload, Delivery) for _, payload in inboxes.drain()], channel

    return run_mock(main)


def test_a_flood_of_one_unseen_runs_broadcasts_does_not_crowd_out_the_next_runs(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Run 9's fish 1 floods the channel with tick-0 broadcasts before any snapshot of its
    # run: past the per-run cap they are refused, while run 8's first broadcast is still
    # kept and delivered once run 8 starts. A fourth unseen run lets go the earliest's.
    monkeypatch.setattr(channel_module, "HELD_BROADCASTS_MAX", 3)
    monkeypatch.setattr(channel_module, "HELD_RUNS_MAX", 3)

    flood = [(1, broadcast(1, 0, value, run=9)) for value in range(5)]
    deliveries, channel = _run_8_after(
        [
            *flood,
            (0, broadcast(0, 0, 4, run=8)),
            (2, broadcast(2, 0, 6, run=10)),
            (2, broadcast(2, 0, 6, run=11)),  # a fourth run: run 9's let go
        ],
        run_7_ticks=1,
    )
    assert sorted((d.receiver_id, d.tick, d.run, int(d.values[0])) for d in deliveries) == [
        (1, 1, 8, 4), (2, 1, 8, 4),
    ]  # fmt: skip
    statistics = channel.statistics()
    # Two of run 9's five refused; its other three let go for run 11, and runs 10's and
    # 11's when run 8 came.
    assert statistics.rejected == 2 and statistics.unannounced == 5


Step = tuple[str, int, int, int | list[int]]
Served = tuple[list[tuple[float, ChannelReport]], list[Delivery], Channel]


def serve(steps: list[Step]) -> Served:
    """:func:`_serve` under a MockClock."""
    return run_mock(lambda: _serve(steps))


async def _serve(steps: list[Step]) -> Served:
    """Run a channel on the in-memory Bus through ``steps`` ("snapshot", tick, 0,
    announced) or ("broadcast", sender, tick, value), 10 ms apart, then 10 s more; the
    reports with the (mock) time each came at, the deliveries, and the channel."""
    bus = MemoryBus()
    channel = Channel(SCENARIO)
    reports: list[tuple[float, ChannelReport]] = []

    async def collect(inbox: Inbox[tuple[str, bytes]]) -> None:
        async for _, payload in inbox:
            reports.append((trio.current_time(), decode(payload, ChannelReport)))

    async with (
        subscription(bus, KEYS.channel_report) as report_inbox,
        subscription(bus, KEYS.fish_inboxes()) as inboxes,
        trio.open_nursery() as nursery,
    ):
        await nursery.start(channel.run, bus)
        nursery.start_soon(collect, report_inbox)
        for kind, first, second, third in steps:
            if kind == "snapshot":
                assert isinstance(third, list)
                bus.put(KEYS.snapshot, snapshot(first, third))
            else:
                assert isinstance(third, int)
                bus.put(KEYS.outbox(first), broadcast(first, second, third))
            await trio.sleep(0.01)
        await trio.sleep(10)
        nursery.cancel_scope.cancel()
    deliveries = [decode(payload, Delivery) for _, payload in inboxes.drain()]
    return reports, deliveries, channel


def test_a_tick_is_reported_as_soon_as_its_announced_broadcasts_are_in() -> None:
    # Not after the 5-s wait for missing ones: the last announced broadcast completes it.
    reports, deliveries, channel = serve(
        [("snapshot", 0, 0, [0, 0, 0]), ("snapshot", 1, 0, [2, 0, 0]),
         ("broadcast", 0, 0, 3), ("broadcast", 0, 0, 4)],
    )  # fmt: skip
    assert [report.tick for _, report in reports] == [1]
    assert reports[0][0] < 0.1  # mock seconds: the steps took 0.04
    assert sorted((d.receiver_id, int(d.values[0])) for d in deliveries) == [
        (1, 3), (1, 4), (2, 3), (2, 4),
    ]  # fmt: skip
    assert channel.statistics().missing_broadcasts == 0


def test_a_channel_that_comes_up_mid_run_does_not_wait_for_what_it_could_not_hear() -> None:
    # Its first snapshot is of tick 7: the broadcasts of tick 6 it announces were sent
    # before the channel listened. It reports after a moment (0.5 s) with what it has,
    # nothing, instead of holding the world for the 5-s wait; from the next tick on it
    # waits as ever.
    reports, deliveries, channel = serve(
        [("snapshot", 7, 0, [1, 1, 0]), ("snapshot", 8, 0, [1, 0, 0]),
         ("broadcast", 0, 7, 3)],
    )  # fmt: skip
    assert [report.tick for _, report in reports] == [7, 8]
    assert reports[0][0] == pytest.approx(0.5, abs=0.02)  # mock seconds
    assert reports[1][0] < 0.6  # its broadcast was in
    assert [(d.receiver_id, int(d.values[0])) for d in deliveries] == [(1, 3), (2, 3)]
    assert channel.statistics().missing_broadcasts == 2


def test_broadcasts_beyond_those_announced_are_not_delivered_but_counted() -> None:
    reports, deliveries, channel = serve(
        [("snapshot", 0, 0, [0, 0, 0]), ("broadcast", 2, 0, 1), ("broadcast", 2, 0, 2),
         ("snapshot", 1, 0, [0, 0, 1])],
    )  # fmt: skip
    assert reports[0][1].inbox_counts.tolist() == [1, 1, 0]
    assert sorted((d.receiver_id, int(d.values[0])) for d in deliveries) == [(0, 1), (1, 1)]
    # One more than fish 2 announced: a bad sender's, rejected (not an ordinary late one).
    assert channel.statistics().rejected == 1
    assert channel.statistics().unannounced == 0


def test_stale_and_far_future_broadcasts_are_rejected_near_ones_kept(
    caplog: pytest.LogCaptureFixture,
) -> None:
    # After the snapshot of tick 3, broadcasts of ticks 2 to 5 may still be delivered; one
    # of tick 1 is stale and one of tick 6 cannot be a real fish's.
    steps: list[Step] = [("snapshot", tick, 0, [0, 0, 0]) for tick in range(4)]
    steps += [("broadcast", 0, 1, 1), ("broadcast", 1, 2, 2), ("broadcast", 1, 5, 5)]
    steps += [("broadcast", 2, 6, 6)]
    steps += [("snapshot", 4, 0, [0, 0, 0]), ("snapshot", 5, 0, [0, 0, 0])]
    steps += [("snapshot", 6, 0, [0, 1, 0])]
    with caplog.at_level(logging.WARNING, "fishswarm"):
        _, deliveries, channel = serve(steps)
    # Delivered: the broadcast of tick 5 (announced by the snapshot of tick 6). Rejected:
    # ticks 1 and 6 as stale when they came. Let go: tick 2, unannounced at the snapshot of 4.
    assert sorted((d.tick, d.receiver_id, int(d.values[0])) for d in deliveries) == [
        (6, 0, 5), (6, 2, 5),
    ]  # fmt: skip
    assert channel.statistics().rejected == 2
    assert channel.statistics().unannounced == 1
    pattern = re.compile(r"rejected an? (\w+) message on \S+: [^0-9]*tick (\d+)")
    said = [record.getMessage() for record in caplog.records]
    rejections = sorted(pattern.findall(message)[0] for message in said if pattern.search(message))
    assert rejections == [("stale", "1"), ("stale", "6")]


def test_broadcasts_of_a_tick_whose_snapshot_was_missed_are_counted_when_a_later_one_comes() -> (
    None
):
    # The snapshot of tick 2 never reaches the channel: fish 0's broadcast of tick 1 stays
    # unannounced, and is let go and counted at the snapshot of tick 3.
    reports, deliveries, channel = serve(
        [("snapshot", 0, 0, [0, 0, 0]), ("snapshot", 1, 0, [0, 0, 0]),
         ("broadcast", 0, 1, 8), ("snapshot", 3, 0, [0, 0, 0])],
    )  # fmt: skip
    assert deliveries == [] and reports == []  # a tick that announces nothing is not reported
    assert channel.statistics().unannounced == 1
    assert channel.statistics().rejected == 0


LOSSY = Scenario(fish=3, channel_loss=0.5, seed=4)


async def _one_run(
    bus: MemoryBus, reports: Inbox[tuple[str, bytes]], *, run: int = 0, first_lost: bool = False
) -> list[list[int]]:
    """A run of 8 ticks in which fish 0 broadcasts at every tick: each tick's inbox counts
    (``first_lost``: the run's snapshot of tick 0 never reaches the channel)."""
    counts = []
    if not first_lost:
        bus.put(KEYS.snapshot, snapshot(0, [0, 0, 0], run=run))
    for tick in range(1, 9):
        bus.put(KEYS.outbox(0), broadcast(0, tick - 1, tick, run=run))
        bus.put(KEYS.snapshot, snapshot(tick, [1, 0, 0], run=run))
        report = decode((await reports.receive())[1], ChannelReport)
        counts.append(report.inbox_counts.tolist())
    return counts


async def _one_run_with_a_stale_snapshot(
    bus: MemoryBus, reports: Inbox[tuple[str, bytes]], *, run: int, stale: int
) -> list[list[int]]:
    """As :func:`_one_run`, with a late snapshot of the ended run ``stale`` among its own."""
    counts = []
    bus.put(KEYS.snapshot, snapshot(0, [0, 0, 0], run=run))
    for tick in range(1, 9):
        if tick == 4:
            bus.put(KEYS.snapshot, snapshot(15, [0, 0, 0], run=stale))
        bus.put(KEYS.outbox(0), broadcast(0, tick - 1, tick, run=run))
        bus.put(KEYS.snapshot, snapshot(tick, [1, 0, 0], run=run))
        report = decode((await reports.receive())[1], ChannelReport)
        counts.append(report.inbox_counts.tolist())
    return counts


async def _runs(channel: Channel, runs: int | list[tuple[int, bool]]) -> list[list[list[int]]]:
    """Runs served one after the other: ``runs`` unnumbered ones, or those listed as (run,
    whether its tick-0 snapshot is lost)."""
    listed = [(0, False)] * runs if isinstance(runs, int) else runs
    bus = MemoryBus()
    async with (
        subscription(bus, KEYS.channel_report) as reports,
        trio.open_nursery() as nursery,
    ):
        await nursery.start(channel.run, bus)
        counts = [await _one_run(bus, reports, run=run, first_lost=lost) for run, lost in listed]
        nursery.cancel_scope.cancel()
    return counts


def test_a_run_whose_first_snapshot_was_lost_still_loses_what_its_seed_says() -> None:
    """A channel that served run 7 misses run 8's snapshot of tick 0: run 8 starts for it
    at its first snapshot of tick 1, and loses what a channel serving run 8 alone loses
    (the loss streams restart; they went on from run 7's draws)."""

    reference = run_mock(lambda: _runs(Channel(LOSSY), [(8, False)]))[0]
    served = run_mock(lambda: _runs(Channel(LOSSY), [(7, False), (8, True)]))
    assert sum(c[1] + c[2] for c in reference) < 16  # the seed loses some of 16
    assert served[0] == reference  # run 7 from its start, as run 8 alone
    assert served[1] == reference


def test_a_late_snapshot_of_an_ended_run_does_not_start_it_again() -> None:
    """Run 8 follows run 7; a snapshot of run 7 that comes late, in the middle of run 8, is
    let go: run 8 loses what it loses alone (its loss streams restarted twice before)."""

    async def after_run_7(channel: Channel) -> list[list[int]]:
        bus = MemoryBus()
        async with (
            subscription(bus, KEYS.channel_report) as reports,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(channel.run, bus)
            await _one_run(bus, reports, run=7)
            counts = await _one_run_with_a_stale_snapshot(bus, reports, run=8, stale=7)
            nursery.cancel_scope.cancel()
        return counts

    reference = run_mock(lambda: _runs(Channel(LOSSY), [(8, False)]))[0]
    channel = Channel(LOSSY)
    assert run_mock(lambda: after_run_7(channel)) == reference
    assert channel.statistics().rejected == 0  # let go, not refused: it is a real snapshot


def test_a_channel_apart_from_its_world_takes_each_runs_medium_from_the_world(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Started with no loss, a channel whose world runs with loss 0.5 and seed 4 loses what
    a channel started with the world's settings loses; when the next world does not answer
    (or answers nonsense) it says so and takes its own settings (no loss: every reception
    heard); the next world's no-loss medium hears every reception too."""
    answers: list[Scenario | ConfigError | None] = [
        LOSSY,
        None,
        ConfigError("the world's answer is no run settings"),
        Scenario(fish=3, seed=4),
    ]

    async def ask_world() -> Scenario | None:
        answer = answers.pop(0)
        if isinstance(answer, ConfigError):
            raise answer
        return answer

    reference = run_mock(lambda: _runs(Channel(LOSSY), 1))[0]
    with caplog.at_level(logging.INFO, "fishswarm.actors.channel"):
        apart = run_mock(lambda: _runs(Channel(Scenario(fish=3), ask_world=ask_world), 4))
    assert sum(c[1] + c[2] for c in reference) < 16  # the seed loses some of 16
    assert apart[0] == reference
    assert apart[1] == apart[2] == apart[3] == [[0, 1, 1]] * 8
    assert answers == []
    said = [r.getMessage() for r in caplog.records]
    own = (
        "channel: the run's world did not tell its settings: the medium takes the channel's "
        "own (range 3 m, loss 0, seed 0, flags by channel)"
    )
    assert said == [
        "channel: a run starts: range 3 m, loss 0.5, seed 4, flags by channel",
        own,
        "channel: a run starts: range 3 m, loss 0, seed 0, flags by channel",
        "channel: the world's answer is no run settings",
        own,
        "channel: a run starts: range 3 m, loss 0, seed 0, flags by channel",
        "channel: a run starts: range 3 m, loss 0, seed 4, flags by channel",
    ]


def test_a_channel_apart_from_its_world_takes_the_worlds_range_alone(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Started on a range of 3 m, a channel whose world differs only in its range, 0.15 m,
    takes it: fish 0's broadcasts reach fish 1 (0.1 m away), not fish 2 (0.2 m away)."""

    async def ask_world() -> Scenario | None:
        return Scenario(fish=3, channel_range=0.15)

    with caplog.at_level(logging.INFO, "fishswarm.actors.channel"):
        counts = run_mock(lambda: _runs(Channel(Scenario(fish=3), ask_world=ask_world), 1))
    assert counts == [[[0, 1, 0]] * 8]
    assert "channel: a run starts: range 0.15 m, loss 0, seed 0, flags by channel" in caplog.text


def test_a_channel_serving_run_after_run_gives_each_the_losses_of_a_run_alone() -> None:
    """Two runs of the same seed through one channel (as with `fishswarm channel` left up
    while `fishswarm world` runs again): fish 0 broadcasts at every tick, half of all
    receptions are lost, and the second run loses the same ones as the first. A broadcast
    of the first run for a tick it never reached is counted and let go when the second
    starts."""
    lossy = LOSSY

    async def main() -> tuple[list[list[int]], list[list[int]], Channel]:
        bus = MemoryBus()
        channel = Channel(lossy)
        async with (
            subscription(bus, KEYS.channel_report) as reports,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(channel.run, bus)
            first = await _one_run(bus, reports)
            bus.put(KEYS.outbox(0), broadcast(0, 9, 99))  # for a tick the run never reached
            await trio.sleep(0.01)
            second = await _one_run(bus, reports)
            nursery.cancel_scope.cancel()
        return first, second, channel

    first, second, channel = run_mock(main)
    assert first == second
    heard = sum(c[1] + c[2] for c in first)
    assert 4 <= heard <= 12  # of 16 receptions, about half lost (the seed's draw)
    assert channel.statistics().unannounced == 1  # of the first run, let go at the second's
    assert channel.statistics().rejected == 0


def test_a_channel_apart_from_its_world_takes_how_its_flags_travel_and_who_sees_whom() -> None:
    """A world whose flags go by light, with its own vision: the channel takes both, and
    the run's signals (which light does not carry) reach no one."""

    async def ask_world() -> Scenario | None:
        return Scenario(
            fish=3, flag_medium="light", visual_range=0.5, blind_width=0.1, sphere_radius=0.02
        )

    channel = Channel(Scenario(fish=3), ask_world=ask_world)
    counts = run_mock(lambda: _runs(channel, 1))
    taken = channel.scenario
    assert (taken.flag_medium, taken.visual_range, taken.blind_width, taken.sphere_radius) == (
        "light", 0.5, 0.1, 0.02,
    )  # fmt: skip
    assert counts == [[[0, 0, 0]] * 8]


# Three fish in a row along +x, 1 m apart, all facing +x: each sees the one ahead of it
# (the one beyond is hidden behind it); the ones behind are in its blind spot.
ROW = np.array([[0.5, 1.0, 0.5], [1.5, 1.0, 0.5], [2.5, 1.0, 0.5]])
JOINED = (True, False, True)
"""Whose formation flags say they hold their places."""


def formation_flag(sender: int, tick: int, joined: bool) -> Broadcast:
    values = FormationFlag(FORMATION_SHAPES.index("pyramid"), 3 - sender, joined, 2, 90_000, 7)
    return Broadcast(sender, tick, "formation", values.values())


async def _light_run(channel: Channel) -> tuple[list[list[int]], list[Delivery]]:
    """Tick 0: fish 0 and 2 flag that they hold their places, fish 1 that it seeks its
    place; tick 1: fish 2 sends a signal. Each tick's inbox counts, and the deliveries."""
    bus = MemoryBus()
    zeros = np.zeros(3, dtype=np.int64)

    def row_snapshot(tick: int, broadcasts: list[int]) -> bytes:
        announced = np.array(broadcasts, dtype=np.int64)
        return encode(Snapshot(tick, float(tick), IDS, ROW, np.zeros((3, 3)), np.zeros(3),
                               zeros, announced))  # fmt: skip

    counts = []
    async with (
        subscription(bus, KEYS.channel_report) as reports,
        subscription(bus, KEYS.fish_inboxes()) as inboxes,
        trio.open_nursery() as nursery,
    ):
        await nursery.start(channel.run, bus)
        bus.put(KEYS.snapshot, row_snapshot(0, [0, 0, 0]))
        for sender, joined in enumerate(JOINED):
            bus.put(KEYS.outbox(sender), encode(formation_flag(sender, 0, joined)))
        bus.put(KEYS.snapshot, row_snapshot(1, [1, 1, 1]))
        counts.append(decode((await reports.receive())[1], ChannelReport).inbox_counts.tolist())
        bus.put(KEYS.outbox(2), broadcast(2, 1, 5))
        bus.put(KEYS.snapshot, row_snapshot(2, [0, 0, 1]))
        counts.append(decode((await reports.receive())[1], ChannelReport).inbox_counts.tolist())
        nursery.cancel_scope.cancel()
    return counts, [decode(payload, Delivery) for _, payload in inboxes.drain()]


def test_by_light_only_a_joined_flag_travels_to_the_fish_that_see_its_sender() -> None:
    """With flags by light the channel plays the robots' medium: only fish 2's flag (it
    holds its place) travels, to fish 1 alone, which sees it 1 m ahead (fish 0's reaches no
    one: the others have it behind them; fish 1's says it seeks its place), reduced to what
    light says; the signal travels not at all. By the channel, every broadcast reaches
    both other fish (3 m range), as it is."""
    counts, deliveries = run_mock(
        lambda: _light_run(Channel(Scenario(fish=3, flag_medium="light")))
    )
    assert counts == [[0, 1, 0], [0, 0, 0]]
    [delivery] = deliveries
    assert (delivery.receiver_id, delivery.tick, delivery.kind) == (1, 1, "formation")
    own = FormationFlag.from_values(formation_flag(2, 0, True).values)
    assert FormationFlag.from_values(delivery.values) == flag_by_light(own)
    np.testing.assert_allclose(delivery.sender_position, [1.0, 0.0, 0.0], atol=1e-12)
    counts, deliveries = run_mock(lambda: _light_run(Channel(Scenario(fish=3))))
    assert counts == [[2, 2, 2], [1, 1, 0]]
    sent = [formation_flag(n, 0, joined).values.tolist() for n, joined in enumerate(JOINED)]
    flags = [d.values.tolist() for d in deliveries if d.kind == "formation"]
    assert sorted(flags) == sorted(sent * 2)


@pytest.mark.parametrize(("visual_range", "counts"), [(3.0, [0, 1, 0]), (0.5, [0, 0, 0])])
def test_a_channel_apart_from_its_world_takes_its_flag_medium_and_its_sight(
    visual_range: float, counts: list[int]
) -> None:
    """A channel started with the simulated channel's flags takes flags by light from the
    world of the run, and the world's vision decides who sees whom: with a visual range of
    0.5 m, fish 1 does not see fish 2, 1 m ahead, and no flag travels."""

    async def ask_world() -> Scenario | None:
        return Scenario(fish=3, flag_medium="light", visual_range=visual_range)

    channel = Channel(Scenario(fish=3), ask_world=ask_world)
    got, _ = run_mock(lambda: _light_run(channel))
    assert got == [counts, [0, 0, 0]]


async def _robot_lights(
    channel: Channel,
    lights: list[int] | None,
    told: str | None = None,
    *,
    robots: tuple[int, ...] = (2,),
    signals: int = 0,
    ticks: int = 1,
    run: int = 0,
) -> tuple[list[int], list[Delivery]]:
    """Fish 0, 1 and 2 in a row facing +x, ``robots`` among them (their drivers' tokens
    shown); the snapshots of ticks 1 to ``ticks`` say each fish's LEDs as ``lights`` (a
    robot's flash when its fish holds its place) and announce ``signals`` broadcasts of
    fish 0 at the tick before. The inbox counts of every tick, added up, and the
    deliveries."""
    bus = MemoryBus()
    zeros = np.zeros(3, dtype=np.int64)
    counts = np.zeros(3, dtype=np.int64)
    async with contextlib.AsyncExitStack() as stack:
        reports = await stack.enter_async_context(subscription(bus, KEYS.channel_report))
        inboxes = await stack.enter_async_context(subscription(bus, KEYS.fish_inboxes()))
        for robot in robots:
            await stack.enter_async_context(open_token(bus, KEYS.alive("robot", robot)))
        nursery = await stack.enter_async_context(trio.open_nursery())
        await nursery.start(channel.run, bus)
        for tick in range(ticks + 1):
            bus.put(KEYS.snapshot, encode(Snapshot(
                tick, float(tick), IDS, ROW, np.zeros((3, 3)), np.zeros(3), zeros,
                np.array([signals, 0, 0]) if tick else zeros, formation=told,
                lights=None if lights is None or not tick else np.array(lights), run=run,
            )))  # fmt: skip
            if tick:
                counts += decode((await reports.receive())[1], ChannelReport).inbox_counts
            for value in range(signals if tick < ticks else 0):
                bus.put(KEYS.outbox(0), broadcast(0, tick, value))
        nursery.cancel_scope.cancel()
    return counts.tolist(), [decode(payload, Delivery) for _, payload in inboxes.drain()]


@pytest.mark.parametrize("told", [None, "triangle"])
def test_a_flashing_robot_shows_the_simulated_fish_that_see_it_that_it_holds_its_place(
    told: str | None,
) -> None:
    """Robot 2 flashes (its fish holds its place): fish 1, which sees it 1 m ahead, gets a
    formation flag that says so in its own shape (the one it is told, if any) and
    orientation, nothing else; fish 0 has it behind fish 1, out of its sight. Flags travel
    by the simulated channel here: a robot's go by light whatever the medium."""
    scenario = Scenario(fish=3, behavior="formation", formation="pyramid",
                        formation_heading_deg=90.0)  # fmt: skip
    counts, deliveries = run_mock(
        lambda: _robot_lights(Channel(scenario), [STEADY, DARK, FLASHING], told)
    )
    assert counts == [0, 1, 0]
    [delivery] = deliveries
    assert (delivery.receiver_id, delivery.tick, delivery.kind) == (1, 1, "formation")
    flag = FormationFlag.from_values(delivery.values)
    shape = told or "pyramid"
    assert flag == FormationFlag(FORMATION_SHAPES.index(shape), -1, True, NO_HOPS, 90_000, 0)
    np.testing.assert_allclose(delivery.sender_position, [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize(
    "scenario", [Scenario(fish=3), Scenario(fish=3, behavior="formation", flags=False)]
)
def test_flashing_robots_mean_nothing_to_fish_that_heed_no_flags(scenario: Scenario) -> None:
    """Dispersing fish, or formation fish with flags off, get nothing from a flashing
    robot; the tick is still reported, so that the world, which announced it, goes on."""
    counts, deliveries = run_mock(
        lambda: _robot_lights(Channel(scenario), [DARK, STEADY, FLASHING])
    )
    assert counts == [0, 0, 0]
    assert deliveries == []


def test_robots_are_shown_no_robots_flags_and_take_the_simulated_fishs_as_before() -> None:
    """Fish 1 is a robot too: it sees robot 2 flash with its own cameras, so the channel
    shows it nothing; a simulated fish's broadcasts still reach it (loss 0.5 here, and over
    three ticks their receptions and losses are the same whether robot 2 flashes or not:
    the robots' lights are lost by draws of their own)."""
    scenario = Scenario(fish=3, behavior="formation", channel_loss=0.5, seed=4)
    flashing = run_mock(
        lambda: _robot_lights(Channel(scenario), [STEADY, STEADY, FLASHING], robots=(1, 2),
                              signals=4, ticks=3, run=7)
    )  # fmt: skip
    steady = run_mock(
        lambda: _robot_lights(Channel(scenario), None, robots=(1, 2), signals=4, ticks=3, run=7)
    )
    assert not any(d.kind == "formation" for d in flashing[1])
    assert flashing == steady
    # A robot's driver numbers its fish's mail by its own run: the world's stays off the
    # wire (a driver not yet upgraded reads what it always read).
    assert steady[1] and {d.run for d in steady[1]} == {None}
    assert 0 < steady[0][1] < 12  # fish 1 heard some of fish 0's signals, lost others
