"""The observer on the in-memory Bus: snapshots become metrics, and any number of tasks can
wait for a tick."""

from __future__ import annotations

import numpy as np
import trio

from fishswarm.actors.bus import MemoryBus
from fishswarm.actors.observer import Observer
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import Snapshot
from tests.conftest import run_mock

KEYS = KeySpace()


def _snapshot(tick: int) -> bytes:
    # Two fish 1 m apart along x: pairwise and nearest-neighbour distances are 1 m.
    position = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5]])
    zeros = np.zeros((2, 3))
    counts = np.ones(2, dtype=np.int64)
    message = Snapshot(
        tick, float(tick), np.arange(2), position, zeros, np.zeros(2), counts, counts * 0
    )
    return encode(message)


def test_every_task_waiting_for_a_tick_wakes() -> None:
    async def main() -> tuple[list[tuple[str, float]], Observer]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        woke: list[tuple[str, float]] = []

        async def wait(name: str, tick: int) -> None:
            await observer.wait_for_tick(tick)
            woke.append((name, trio.current_time()))

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            nursery.start_soon(wait, "first", 2)
            nursery.start_soon(wait, "second", 2)
            nursery.start_soon(wait, "third", 3)
            for tick in range(4):
                await trio.sleep(1.0)
                bus.put(KEYS.snapshot, _snapshot(tick))
            await trio.sleep(1.0)
            bus.put(KEYS.snapshot, _snapshot(1))  # stale: rejected
            await trio.sleep(1.0)
            nursery.cancel_scope.cancel()
        return woke, observer

    woke, observer = run_mock(main)
    assert sorted(woke) == [("first", 3.0), ("second", 3.0), ("third", 4.0)]
    assert [p.tick for p in observer.history] == [0, 1, 2, 3]
    assert observer.history[-1].metrics["pairwise_distance"] == 1.0
    assert observer.statistics().rejected == 1 and observer.statistics().snapshots == 4
