"""The channel on the in-memory Bus under trio's MockClock: it delivers exactly what each
snapshot announces, whatever else arrives and in whatever order."""

from __future__ import annotations

import numpy as np
import trio

from fishswarm.actors.bus import MemoryBus
from fishswarm.actors.channel import Channel
from fishswarm.protocols.codec import decode, encode
from fishswarm.protocols.messages import Broadcast, ChannelReport, Delivery, Snapshot
from fishswarm.sim.scenario import Scenario
from tests.conftest import run_mock, subscription

SCENARIO = Scenario(fish=3)
KEYS = SCENARIO.keys
IDS = np.array([0, 1, 2])
# Three fish in a row 0.1 m apart, all in range of one another.
POSITION = np.array([[0.5, 0.5, 0.5], [0.6, 0.5, 0.5], [0.7, 0.5, 0.5]])


def snapshot(tick: int, broadcasts: list[int]) -> bytes:
    zeros = np.zeros(3, dtype=np.int64)
    return encode(
        Snapshot(
            tick, float(tick), IDS, POSITION, np.zeros((3, 3)), np.zeros(3), zeros,
            np.array(broadcasts, dtype=np.int64),
        )
    )  # fmt: skip


def broadcast(sender: int, tick: int, value: int) -> bytes:
    return encode(Broadcast(sender, tick, "signal", np.array([value])))


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
    assert statistics.missing_broadcasts == 0 and statistics.rejected == 1  # fish 1's
    assert statistics.delivered == 4


def test_broadcasts_a_snapshot_announces_none_of_are_counted_and_let_go() -> None:
    # Every broadcaster of a tick was late (realtime mode): the snapshot announces nothing,
    # and what came is counted, not kept for ever.
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

    channel = run_mock(main)
    assert channel.statistics().rejected == 49
    assert channel.statistics().delivered == 0
