"""The observer on the in-memory Bus: snapshots become metrics, and any number of tasks can
wait for a tick."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trio
import trio.testing
from mcap.reader import make_reader

from fishswarm.actors import observer as observer_module
from fishswarm.actors.bus import MemoryBus
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.observer import Observer
from fishswarm.actors.world import OFFLOAD_FISH
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import Snapshot, WorldPulse
from fishswarm.sim.scenario import Scenario
from fishswarm.study.metrics import _sampled_pairs, prepare_metrics, swarm_metrics
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
            bus.put(KEYS.snapshot, _snapshot(3))  # the last tick again: rejected too
            await trio.sleep(1.0)
            nursery.cancel_scope.cancel()
        return woke, observer

    woke, observer = run_mock(main)
    assert sorted(woke) == [("first", 3.0), ("second", 3.0), ("third", 4.0)]
    assert [p.tick for p in observer.history] == [0, 1, 2, 3]
    assert observer.history[-1].metrics["pairwise_distance"] == 1.0
    assert observer.statistics().rejected == 2 and observer.statistics().snapshots == 4


def test_the_end_of_a_run_waits_for_snapshots_that_come_after_the_world_has_left() -> None:
    # Zenoh carries the world's snapshots apart from its liveliness token: under load the
    # last one can arrive after the token is gone, and must still count.
    async def main() -> tuple[float, list[int]]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        ended: list[tuple[float, list[int]]] = []

        async def wait_for_the_end() -> None:
            await observer.wait_for_world_end(settle=1.0)
            ended.append((trio.current_time(), [p.tick for p in observer.history]))

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            nursery.start_soon(wait_for_the_end)
            world = bus.declare_token(KEYS.alive("world", 0))
            fish = bus.declare_token(KEYS.alive("fish", 0))
            bus.put(KEYS.snapshot, _snapshot(0))
            await trio.sleep(0.5)
            fish.undeclare()  # a fish leaving is not the world's end
            await trio.sleep(2.5)
            world.undeclare()
            await trio.sleep(0.5)
            bus.put(KEYS.snapshot, _snapshot(1))  # late, within the settle time
            await trio.sleep(0.75)
            bus.put(KEYS.snapshot, _snapshot(2))  # late again, 0.75 s after the one before
            await trio.sleep(5.0)
            nursery.cancel_scope.cancel()
        return ended[0]

    ended, ticks = run_mock(main)
    assert ticks == [0, 1, 2]
    assert ended == 5.25  # quiet for 1 s after the last snapshot, at 4.25 s


def test_an_observer_hands_each_scene_to_a_view_and_records_it(tmp_path: Path) -> None:
    from fishswarm.study.recording import open_recorder
    from fishswarm.study.scene import Scene, Stage

    shown: list[tuple[Scene, dict[str, float]]] = []
    path = tmp_path / "observed.mcap"

    async def main() -> None:
        bus = MemoryBus()
        with open_recorder(path, {}) as recorder:
            observer = Observer(
                KEYS,
                recorder=recorder,
                stage=Stage((2.0, 1.0, 1.0)),
                on_scene=lambda scene, metrics: shown.append((scene, metrics)),
            )
            async with trio.open_nursery() as nursery:
                await nursery.start(observer.run, bus)
                for tick in range(3):
                    bus.put(KEYS.snapshot, _snapshot(tick))
                    await observer.wait_for_tick(tick)
                nursery.cancel_scope.cancel()

    run_mock(main)
    assert [scene.time for scene, _ in shown] == [0.0, 1.0, 2.0]
    scene, metrics = shown[-1]
    np.testing.assert_array_equal(scene.position, [[0.5, 0.5, 0.5], [1.5, 0.5, 0.5]])
    np.testing.assert_array_equal(scene.heading, [[1.0, 0.0, 0.0]] * 2)
    assert metrics["pairwise_distance"] == 1.0
    with path.open("rb") as stream:
        scenes = [json.loads(m.data) for _, _, m in make_reader(stream).iter_messages(["scene"])]
    assert len(scenes) == 3
    fish, tank = scenes[-1]["entities"]
    assert [a["pose"]["position"]["x"] for a in fish["arrows"]] == [0.5, 1.5]
    assert max(p["x"] for p in tank["lines"][0]["points"]) == 2.0


def test_a_formation_is_measured_against_the_shape_each_snapshot_names() -> None:
    # Six fish in the slots of a column: perfect against a column, not against the pyramid
    # the scenario starts with. The snapshots after the switch name the column.
    from fishswarm.sim.scenario import Scenario
    from fishswarm.study.metrics import FormationTargets

    scenario = Scenario(fish=6, behavior="formation", formation="pyramid", spacing=0.25)
    targets = FormationTargets.of(scenario)
    assert targets is not None
    column = targets.at("column")
    assert column.slots is not None
    position = column.slots[:6] + np.array([0.9, 0.9, 0.5])

    def snapshot(tick: int, formation: str | None) -> bytes:
        zeros, counts = np.zeros((6, 3)), np.zeros(6, dtype=np.int64)
        return encode(
            Snapshot(
                tick, float(tick), np.arange(6), position, zeros, np.zeros(6), counts, counts,
                formation=formation,
            )
        )  # fmt: skip

    async def main() -> Observer:
        bus = MemoryBus()
        observer = Observer.of(scenario)
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            for tick, formation in enumerate([None, "column", "column"]):
                bus.put(KEYS.snapshot, snapshot(tick, formation))
                await observer.wait_for_tick(tick)
            nursery.cancel_scope.cancel()
        return observer

    history = run_mock(main).history
    before, *after = (progress.metrics for progress in history)
    assert before["shape_error"] > 0.05 and before["joined_fraction"] < 1.0
    for metrics in after:
        assert metrics["shape_error"] < 1e-9 and metrics["joined_fraction"] == 1.0


async def _note_the_end(observer: Observer, ended: list[float]) -> None:
    """Wait for the world's end (1 s quiet after it left) and note when it came."""
    await observer.wait_for_world_end(settle=1.0)
    ended.append(trio.current_time())


def of_run(tick: int, run: int) -> bytes:
    """A snapshot of two fish 1 m apart at ``tick`` of ``run``."""
    two = np.zeros(2)
    return encode(
        Snapshot(
            tick, float(tick), np.arange(2), np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5]]),
            np.zeros((2, 3)), two, np.zeros(2, dtype=np.int64), np.zeros(2, dtype=np.int64),
            run=run,
        )
    )  # fmt: skip


def test_an_observer_of_one_run_takes_only_that_runs_snapshots() -> None:
    """A world's own observer (it records the run) on a router where another world of the
    swarm is still at its end: the other's snapshots are let go (worlds take turns: no
    rejection, no warning), not recorded."""

    async def main() -> Observer:
        bus = MemoryBus()
        observer = Observer(KEYS)
        observer.world_run = 7
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            for tick, run in ((5, 3), (6, 3), (0, 7), (1, 7)):
                bus.put(KEYS.snapshot, of_run(tick, run))
            await trio.sleep(1.0)
            nursery.cancel_scope.cancel()
        return observer

    observer = run_mock(main)
    assert [p.tick for p in observer.history] == [0, 1]
    assert observer.statistics().snapshots == 2 and observer.statistics().rejected == 0


def test_an_observer_that_stays_follows_the_next_run_from_its_first_snapshot() -> None:
    """Run 3 ends at tick 5; run 7's first snapshot comes before run 3's world token is
    gone (the two travel apart). Run 7 starts afresh at tick 0 (not refused as stale), is
    announced once, and ends the wait for run 3's end; run 3's token leaving afterwards
    does not end run 7, whose end comes 1 s after its own world left."""

    async def main() -> tuple[Observer, list[tuple[float, int]], list[tuple[float, str]]]:
        bus = MemoryBus()
        announced: list[tuple[float, int]] = []
        observer = Observer(
            KEYS, on_new_run=lambda run: announced.append((trio.current_time(), run))
        )
        ended: list[tuple[float, str]] = []

        async def wait_for_the_end(name: str) -> None:
            await observer.wait_for_world_end(settle=1.0)
            ended.append((trio.current_time(), name))

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            first = bus.declare_token(KEYS.alive("world", 3))
            for tick in range(6):
                bus.put(KEYS.snapshot, of_run(tick, 3))
            await trio.sleep(1.0)
            nursery.start_soon(wait_for_the_end, "run 3")
            await trio.sleep(1.0)
            second = bus.declare_token(KEYS.alive("world", 7))
            bus.put(KEYS.snapshot, of_run(0, 7))  # at 2 s
            await trio.sleep(0.5)
            nursery.start_soon(wait_for_the_end, "run 7")
            first.undeclare()  # at 2.5 s: run 3's world, gone late
            for tick in (1, 2):
                await trio.sleep(1.0)
                bus.put(KEYS.snapshot, of_run(tick, 7))
            await trio.sleep(1.0)
            second.undeclare()  # at 5.5 s
            await trio.sleep(3.0)
            nursery.cancel_scope.cancel()
        return observer, announced, ended

    observer, announced, ended = run_mock(main)
    assert [p.tick for p in observer.history] == [0, 1, 2, 3, 4, 5, 0, 1, 2]
    assert observer.statistics().rejected == 0
    assert announced == [(2.0, 7)] and observer.current_run == 7
    assert ended == [(2.0, "run 3"), (6.5, "run 7")]


def test_a_world_that_leaves_before_any_snapshot_ends_the_wait_for_its_run() -> None:
    """A world that never started its run (its fish did not come up) leaves before the
    observer has seen a snapshot: the wait for the world's end ends 1 s later all the same."""

    async def main() -> list[float]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        ended: list[float] = []

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            nursery.start_soon(_note_the_end, observer, ended)
            world = bus.declare_token(KEYS.alive("world", 3))
            await trio.sleep(2.0)
            world.undeclare()
            await trio.sleep(3.0)
            nursery.cancel_scope.cancel()
        return ended

    assert run_mock(main) == [3.0]


def test_a_world_whose_token_comes_back_has_not_left_and_its_end_is_waited_for_again() -> None:
    """The router lost and back: the world's token goes and comes back while run 3 goes
    on. Its return is told to whoever waits for it, and the wait for the run's end waits for
    the world's next leaving, not the one before."""

    async def main() -> tuple[list[float], list[float]]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        ended: list[float] = []
        back: list[float] = []

        async def note_the_return() -> None:
            await observer.wait_for_world_back()
            back.append(trio.current_time())

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            world = bus.declare_token(KEYS.alive("world", 3))
            bus.put(KEYS.snapshot, of_run(0, 3))
            nursery.start_soon(_note_the_end, observer, ended)
            await trio.sleep(1.0)
            world.undeclare()  # at 1 s: the router lost
            await trio.sleep(0)
            nursery.start_soon(note_the_return)
            await trio.sleep(2.0)
            world = bus.declare_token(KEYS.alive("world", 3))  # at 3 s: back
            await trio.sleep(0.5)
            bus.put(KEYS.snapshot, of_run(1, 3))
            nursery.start_soon(_note_the_end, observer, ended)
            await trio.sleep(2.0)
            world.undeclare()  # at 5.5 s: gone again
            await trio.sleep(3.0)
            nursery.cancel_scope.cancel()
        assert observer.last_tick == 1
        return ended, back

    ended, back = run_mock(main)
    assert back == [3.0]
    assert ended == [2.0, 6.5]  # quiet 1 s after each leaving


def test_a_world_back_before_its_return_is_waited_for_is_known_at_once() -> None:
    """The token back within the second the end of the run is still settled in (a view
    then asks whether it is back): the return was told to no one, and missed for good."""

    async def main() -> float:
        bus = MemoryBus()
        observer = Observer(KEYS)
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            world = bus.declare_token(KEYS.alive("world", 3))
            bus.put(KEYS.snapshot, of_run(0, 3))
            await trio.sleep(1.0)
            world.undeclare()
            await trio.sleep(0.5)
            world = bus.declare_token(KEYS.alive("world", 3))  # back, before anyone asks
            await trio.sleep(2.0)
            with trio.fail_after(1.0):
                await observer.wait_for_world_back()
            nursery.cancel_scope.cancel()
        return trio.current_time()

    assert run_mock(main) == 3.5


def test_a_world_token_that_names_no_run_neither_ends_the_run_nor_stops_the_observer() -> None:
    """Liveliness is not access-controlled: a token ``alive/world/intruder`` may come and go
    while run 3 is watched. The observer notes it and goes on; run 3's end is its own."""

    async def main() -> tuple[Observer, list[float]]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        ended: list[float] = []

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            world = bus.declare_token(KEYS.alive("world", 3))
            bus.put(KEYS.snapshot, of_run(0, 3))
            await trio.sleep(0.5)
            nursery.start_soon(_note_the_end, observer, ended)
            bus.declare_token(KEYS.alive("world", "intruder")).undeclare()  # at 0.5 s
            await trio.sleep(0.5)
            bus.put(KEYS.snapshot, of_run(1, 3))
            await trio.sleep(1.0)
            world.undeclare()  # at 2 s
            await trio.sleep(3.0)
            nursery.cancel_scope.cancel()
        return observer, ended

    observer, ended = run_mock(main)
    assert ended == [3.0]
    assert [p.tick for p in observer.history] == [0, 1]
    assert [(e["event"], e["id"]) for e in observer.events if e["role"] == "world"] == [
        ("joined", "3"), ("joined", "intruder"), ("left", "intruder"), ("left", "3"),
    ]  # fmt: skip


def test_a_later_run_counts_its_revolutions_from_its_own_first_snapshot() -> None:
    """Two fish circling a post at (1, 0.5) m: run 3 turns them a quarter of a revolution;
    run 7 begins where run 3 ended, and its revolutions start from 0 there."""
    from fishswarm.study.metrics import OrbitTarget

    start = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5]])
    quarter = np.array([[1.0, 1.0, 0.5], [1.0, 0.0, 0.5]])  # clockwise, seen with y up

    def at(tick: int, run: int, position: np.ndarray) -> bytes:
        zeros = np.zeros(2, dtype=np.int64)
        return encode(
            Snapshot(
                tick, float(tick), np.arange(2), position, np.zeros((2, 3)), np.zeros(2),
                zeros, zeros, run=run,
            )
        )  # fmt: skip

    async def main() -> Observer:
        bus = MemoryBus()
        observer = Observer(
            KEYS, orbit=OrbitTarget(np.array([1.0, 0.5, 0.5]), 0.5), on_new_run=lambda run: None
        )
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            bus.put(KEYS.snapshot, at(0, 3, start))
            bus.put(KEYS.snapshot, at(1, 3, quarter))
            bus.put(KEYS.snapshot, at(0, 7, quarter))
            bus.put(KEYS.snapshot, at(1, 7, quarter))
            await trio.sleep(0.5)
            nursery.cancel_scope.cancel()
        return observer

    observer = run_mock(main)
    assert [p.tick for p in observer.history] == [0, 1, 0, 1]
    assert [p.metrics["revolutions"] for p in observer.history] == [0.0, 0.25, 0.0, 0.0]
    assert [p.metrics["radius"] for p in observer.history] == [0.5] * 4


def _following_runs(snapshots: list[tuple[int, int]]) -> tuple[Observer, list[int]]:
    """An observer that follows runs, given snapshots (tick, run) in this order: the
    observer, and the runs it announced as beginning."""

    async def main() -> tuple[Observer, list[int]]:
        bus = MemoryBus()
        announced: list[int] = []
        observer = Observer(KEYS, on_new_run=announced.append)
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            for tick, run in snapshots:
                bus.put(KEYS.snapshot, of_run(tick, run))
            await trio.sleep(0.5)
            nursery.cancel_scope.cancel()
        return observer, announced

    return run_mock(main)


def test_a_late_snapshot_of_a_run_that_gave_way_is_refused_as_stale() -> None:
    """Run 3's tick 5 comes after run 7 has begun (the two travel apart): it is refused, and
    run 7 goes on; the view was told of one new run only."""

    observer, announced = _following_runs([(0, 3), (1, 3), (0, 7), (2, 3), (1, 7)])
    assert announced == [7] and observer.current_run == 7
    assert [p.tick for p in observer.history] == [0, 1, 0, 1]
    assert observer.statistics().rejected == 1


def test_an_observer_remembers_the_last_16_runs_that_gave_way_and_no_more() -> None:
    """Runs 1 to 18 one after the other, then late snapshots of runs 2 and 1: run 2 is among
    the last 16 that gave way (2 to 17), so its snapshot is refused as stale; run 1 is
    forgotten, so its snapshot is taken as a run that begins."""
    from fishswarm.actors.observer import ENDED_RUNS_KEPT

    observer, announced = _following_runs([*((0, run) for run in range(1, 19)), (1, 2), (1, 1)])
    assert ENDED_RUNS_KEPT == 16
    assert announced == [*range(2, 19), 1] and observer.current_run == 1
    assert observer.statistics().rejected == 1


def test_an_observer_that_does_not_follow_runs_lets_a_later_runs_snapshots_go() -> None:
    """Without ``on_new_run`` (``fishswarm observe``, which ends with its run) the snapshots
    of the next run on the swarm are neither taken nor counted as bad, and its world's end
    is that of the first run: its own world leaving, 1 s quiet after."""

    async def main() -> tuple[Observer, float]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        ended: list[float] = []

        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            nursery.start_soon(_note_the_end, observer, ended)
            first = bus.declare_token(KEYS.alive("world", 3))
            for tick in range(3):
                bus.put(KEYS.snapshot, of_run(tick, 3))
            await trio.sleep(1.0)
            first.undeclare()
            for tick in range(3):  # the next world's, while the first's end settles
                await trio.sleep(0.25)
                bus.put(KEYS.snapshot, of_run(tick, 7))
            await trio.sleep(3.0)
            nursery.cancel_scope.cancel()
        return observer, ended[0]

    observer, ended = run_mock(main)
    assert [p.tick for p in observer.history] == [0, 1, 2] and observer.current_run == 3
    assert observer.statistics().rejected == 0 and observer.statistics().snapshots == 3
    assert ended == 2.0


def test_an_observer_tells_a_run_its_world_ended_from_one_whose_world_vanished() -> None:
    """The world's last pulse says its run is over; a world that dies, or is cut off with
    the router, never sends it. Pulses of another run say nothing of this one, and none
    is counted as a snapshot."""

    async def main(pulses: list[WorldPulse]) -> tuple[bool | None, int]:
        bus = MemoryBus()
        observer = Observer(KEYS)
        async with trio.open_nursery() as nursery:
            await nursery.start(observer.run, bus)
            bus.put(KEYS.snapshot, _snapshot(0))  # run 0: the snapshots' own
            for pulse in pulses:
                await trio.sleep(1.0)
                bus.put(KEYS.world_pulse, encode(pulse))
            bus.put(KEYS.world_pulse, b"not a pulse")
            await trio.sleep(1.0)
            nursery.cancel_scope.cancel()
        return observer.world_said_ended(), observer.statistics().snapshots

    ended = [WorldPulse(0, 3, "running"), WorldPulse(0, 7, "ended")]
    assert run_mock(lambda: main(ended)) == (True, 1)
    vanished = [WorldPulse(0, 3, "running"), WorldPulse(9, 7, "ended")]
    assert run_mock(lambda: main(vanished)) == (False, 1)
    assert run_mock(lambda: main([])) == (None, 1)  # no pulse came through: cannot tell


def test_a_large_schools_metrics_are_measured_in_a_thread_as_swarm_metrics_measures_them() -> None:
    rng = np.random.default_rng(8)
    count = OFFLOAD_FISH + 100
    position = rng.uniform(0.0, 2.0, (count, 3))
    seen = rng.integers(0, 5, count)
    ones = np.ones(count)
    message = Snapshot(0, 0.0, np.arange(count), position, np.zeros((count, 3)), ones, seen, seen)

    async def main() -> Observer:
        bus = MemoryBus()
        observer = Observer(KEYS)
        with trio.fail_after(30):  # real time: the distances are compiled on first use
            async with trio.open_nursery() as nursery:
                await nursery.start(observer.run, bus)
                bus.put(KEYS.snapshot, encode(message))
                await observer.wait_for_tick(0)
                nursery.cancel_scope.cancel()
        return observer

    observer = trio.run(main)
    assert observer.history[0].metrics == swarm_metrics(position, seen, message.effort)


@pytest.mark.parametrize(("fish", "prepared"), [(300, [300]), (25, [])])
def test_an_observer_of_a_large_swarm_loads_its_metrics_before_the_first_snapshot(
    monkeypatch: pytest.MonkeyPatch, fish: int, prepared: list[int]
) -> None:
    # At 10 000 fish loading the distances took the first snapshot 0.27 s, while the world
    # ran five ticks ahead. 25 fish are measured without compiled distances: no thread.
    pytest.importorskip("numba")
    loaded: list[int] = []
    monkeypatch.setattr(observer_module, "prepare_metrics", loaded.append)

    async def main() -> None:
        observer = Observer.of(Scenario.crowded(fish, duration=2.0, seed=1))
        assert observer.fish == fish
        with trio.fail_after(5):
            async with trio.open_nursery() as nursery:
                await nursery.start(observer.run, MemoryBus())
                while len(loaded) < len(prepared):
                    await trio.sleep(0.01)
                await trio.sleep(0.05)
                nursery.cancel_scope.cancel()

    trio.run(main)
    assert loaded == prepared
    assert Observer(KEYS).fish is None  # a remote observer does not know beforehand


def test_an_observer_whose_head_start_fails_measures_on(monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("numba")

    def fail(fish: int) -> None:
        raise MemoryError("no room to load the distances")

    monkeypatch.setattr(observer_module, "prepare_metrics", fail)

    async def main() -> Observer:
        observer = Observer.of(Scenario.crowded(300, duration=2.0, seed=1))
        bus = MemoryBus()
        with trio.fail_after(5):
            async with trio.open_nursery() as nursery:
                await nursery.start(observer.run, bus)
                await trio.sleep(0.05)  # the head start has failed by now
                bus.put(KEYS.snapshot, _snapshot(0))
                await observer.wait_for_tick(0)
                nursery.cancel_scope.cancel()
        return observer

    assert [p.tick for p in trio.run(main).history] == [0]


def test_preparing_the_metrics_loads_the_loops_a_snapshot_is_measured_with() -> None:
    # A snapshot's positions are read-only (decoded from the wire): numba compiles its loops
    # anew for those, so the head start must load that signature too.
    pytest.importorskip("numba")
    from fishswarm.study import distance_loops

    prepare_metrics(300)
    loaded = len(distance_loops.pairs_and_nearest.signatures)
    position = np.random.default_rng(1).uniform(0.0, 5.0, (300, 3))
    position.setflags(write=False)
    swarm_metrics(position, np.zeros(300, dtype=np.int64), np.zeros(300))
    assert len(distance_loops.pairs_and_nearest.signatures) == loaded


def test_preparing_the_metrics_of_a_swarm_loads_its_sampled_pairs() -> None:
    pytest.importorskip("numba")
    _sampled_pairs.cache_clear()
    prepare_metrics(3000)  # 4.5 million pairs: sampled
    assert _sampled_pairs.cache_info().currsize == 1
    _sampled_pairs(3000)
    assert _sampled_pairs.cache_info().hits == 1
    prepare_metrics(25)  # measured without the kernels: nothing to load
    assert _sampled_pairs.cache_info().currsize == 1


@pytest.fixture
def order(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """What happened, in order: "thread" whenever trio.lowlevel.start_thread_soon starts
    one (tests add their own entries)."""
    happened: list[str] = []
    start_thread_soon = trio.lowlevel.start_thread_soon

    def recorded(*arguments: Any, **options: Any) -> None:
        happened.append("thread")
        start_thread_soon(*arguments, **options)

    monkeypatch.setattr(trio.lowlevel, "start_thread_soon", recorded)
    return happened


def test_an_observer_starts_measuring_a_large_school_before_a_task_woken_with_it_runs(
    order: list[str],
) -> None:
    # The fish in the launcher's process, woken by the world's put with the observer, let it
    # go first (one checkpoint); the observer must then start its thread before yielding.
    count = OFFLOAD_FISH
    position = np.random.default_rng(3).uniform(0.0, 2.0, (count, 3))
    zeros, counts = np.zeros((count, 3)), np.zeros(count, dtype=np.int64)

    async def main() -> Observer:
        bus = MemoryBus()
        observer = Observer(KEYS)
        fish = Inbox[int]()

        async def decide() -> None:
            async for _ in fish:
                await trio.lowlevel.checkpoint()
                order.append("decision")

        with trio.fail_after(30):  # real time: the distances are compiled on first use
            async with trio.open_nursery() as nursery:
                await nursery.start(observer.run, bus)
                nursery.start_soon(decide)
                for tick in range(10):
                    snapshot = Snapshot(
                        tick, float(tick), np.arange(count), position, zeros, np.zeros(count),
                        counts, counts,
                    )  # fmt: skip
                    await trio.testing.wait_all_tasks_blocked()
                    bus.put(KEYS.snapshot, encode(snapshot))
                    fish.push(tick)
                    await observer.wait_for_tick(tick)
                nursery.cancel_scope.cancel()
        return observer

    observer = trio.run(main)
    assert order == ["thread", "decision"] * 10
    assert len(observer.history) == 10
