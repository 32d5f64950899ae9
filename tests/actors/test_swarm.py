"""Whole swarms over real Zenoh on 127.0.0.1: outcomes, determinism, bad traffic, faults."""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trio

from fishswarm.actors.launcher import (
    EXIT_DEGRADED,
    EXIT_WORKER_DIED,
    LaunchSettings,
    RunResult,
    WorkerFailed,
    launch_swarm,
    shared_memory_pool_bytes,
)
from fishswarm.actors.observer import Progress
from fishswarm.actors.session import SessionSettings, open_session
from fishswarm.actors.zenoh_bus import ZenohBus, query
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario
from fishswarm.study.recording import read_recording
from tests.conftest import run_trio

pytestmark = pytest.mark.integration


def _launch(scenario: Scenario, endpoint: str, path: Path, procs: int = 1) -> RunResult:
    settings = LaunchSettings(
        scenario, procs=procs, listen=endpoint, record=path, summary=path.with_suffix(".json")
    )
    return run_trio(lambda: launch_swarm(settings), timeout=120)


def test_the_shared_memory_pool_grows_with_the_swarm_within_the_free_space() -> None:
    mebibyte, plenty = 2**20, 2**40
    # Up to 2 048 fish Zenoh's default (16 MiB) holds a tick several times over.
    assert shared_memory_pool_bytes(25, free=plenty) is None
    assert shared_memory_pool_bytes(2048, free=plenty) is None
    assert shared_memory_pool_bytes(2049, free=plenty) == 2049 * 8 * 1024
    # 10 000 fish in a crowded tank put about 6.5 MB a tick: the pool holds a dozen ticks.
    assert shared_memory_pool_bytes(10_000, free=plenty) == 80_000 * 1024
    # Docker's 64 MB /dev/shm: half of it; with less room than that, Zenoh's default.
    assert shared_memory_pool_bytes(10_000, free=64 * mebibyte) == 32 * mebibyte
    assert shared_memory_pool_bytes(10_000, free=20 * mebibyte) is None


def test_small_swarms_keep_their_fish_in_the_launchers_process_unless_told_otherwise() -> None:
    def workers(fish: int, procs: int | None = None) -> int:
        return LaunchSettings(Scenario(fish=fish), procs=procs).worker_processes

    assert workers(25) == 0
    assert workers(2000) == 0
    assert workers(2001) == 2  # large schools: the world's sending in parts overlaps workers
    assert workers(25, procs=2) == 2
    assert workers(10_000, procs=0) == 0


@pytest.mark.parametrize(("behavior", "sign"), [("dispersion", 1), ("aggregation", -1)])
def test_25_fish_run_moves_the_mean_distance_the_right_way(
    behavior: str, sign: int, endpoint: str, tmp_path: Path
) -> None:
    scenario = Scenario(behavior=behavior, duration=15.0, seed=3)
    result = _launch(scenario, endpoint, tmp_path / "run.mcap")
    summary = result.summary
    assert result.exit_code == 0
    assert summary["status"] == "finished"
    assert summary["counts"]["ticks"] == 15
    assert summary["counts"]["lost_fish"] == 0
    for name in ("centroid_distance", "pairwise_distance"):
        change = summary["metrics"][name]["change_percent"]
        assert sign * change > 10, (name, change)
    assert (tmp_path / "run.json").exists()


@pytest.mark.slow
@pytest.mark.parametrize(("behavior", "sign"), [("dispersion", 1), ("aggregation", -1)])
def test_25_fish_seeing_through_their_cameras_still_disperse_and_aggregate(
    behavior: str, sign: int, endpoint: str, tmp_path: Path
) -> None:
    # The study's set-ups (15 s at 1 Hz). Measured (seed 1): dispersion 0.28 → 0.89 m mean
    # pairwise distance (geometric vision 0.87), aggregation 1.17 → 0.63 m (geometric 0.62).
    scenario = Scenario(behavior=behavior, duration=15.0, seed=1, vision_model="camera")
    result = _launch(scenario, endpoint, tmp_path / "run.mcap", procs=2)
    summary = result.summary
    assert result.exit_code == 0 and summary["counts"]["lost_fish"] == 0
    change = summary["metrics"]["pairwise_distance"]["change_percent"]
    assert sign * change > 30, change
    sight = summary["vision"]
    assert sight["detected"] > 0 and 0.5 < sight["recall"] <= 1.0
    assert sight["false_rate"] < 0.1


def test_camera_vision_runs_the_same_over_zenoh_as_in_the_batch_engine(
    endpoint: str, tmp_path: Path
) -> None:
    scenario = Scenario(fish=8, duration=4.0, seed=2, vision_model="camera")
    reference = simulate_batch(scenario)
    path = tmp_path / "camera.mcap"
    result = _launch(scenario, endpoint, path, procs=2)
    assert result.exit_code == 0
    np.testing.assert_array_equal(read_recording(path).arrays()["pos"], reference.position)
    sight = result.summary["vision"]
    # Every snapshot's neighbours-seen count is the camera's detections, ticks 0–4.
    assert sight["detected"] == int(reference.neighbors_seen.sum())
    assert 0 < sight["found"] <= sight["visible"]
    assert 0.5 < sight["recall"] <= 1.0


@pytest.mark.slow
@pytest.mark.parametrize("time_mode", ["lockstep", "jitter"])
def test_a_large_swarm_runs_over_zenoh_as_in_the_batch_engine(
    endpoint: str, tmp_path: Path, time_mode: str
) -> None:
    # 250 fish: compiled physics and vision in the world (and the batch engine) and, with
    # numba, the compiled Lennard-Jones loop in both workers — the same trajectory, bit for
    # bit; in jitter mode the fish decide a few at a time, each batch through the loop.
    scenario = Scenario.crowded(250, duration=4.0, seed=4).replace(time_mode=time_mode)
    reference = simulate_batch(scenario)
    path = tmp_path / "large.mcap"
    result = _launch(scenario, endpoint, path, procs=2)
    assert result.exit_code == 0 and result.summary["counts"]["lost_fish"] == 0
    arrays = read_recording(path).arrays()
    np.testing.assert_array_equal(arrays["pos"], reference.position)
    np.testing.assert_array_equal(arrays["yaw"], reference.yaw)
    moved = np.linalg.norm(reference.position[-1] - reference.position[0], axis=1)
    assert (moved > 0.01).mean() > 0.9  # the school swam: equal trajectories, not still ones


@pytest.mark.parametrize("time_mode", ["lockstep", "jitter"])
def test_same_seed_same_trajectory_across_processes_and_batch_engine(
    endpoint: str, tmp_path: Path, time_mode: str
) -> None:
    scenario = Scenario(fish=12, duration=8.0, seed=11, vision_noise=0.05, time_mode=time_mode)
    reference = simulate_batch(scenario)
    np.testing.assert_array_equal(simulate_batch(scenario).position, reference.position)
    for procs in (0, 1, 2):  # 0: the fish in the launcher's process
        path = tmp_path / f"procs{procs}.mcap"
        result = _launch(scenario, endpoint, path, procs=procs)
        assert result.exit_code == 0
        assert result.summary["procs"] == procs
        arrays = read_recording(path).arrays()
        np.testing.assert_array_equal(arrays["pos"], reference.position)
        np.testing.assert_array_equal(arrays["yaw"], reference.yaw)
        np.testing.assert_array_equal(arrays["ids"], reference.ids)


def test_garbage_on_every_key_is_rejected_and_changes_nothing(
    endpoint: str, tmp_path: Path
) -> None:
    # Long enough that the vandal, connecting once the launcher listens, is heard by all.
    scenario = Scenario(fish=6, duration=40.0, seed=5)
    keys = scenario.keys
    garbage = [b"", b"\xc1\xc1", b"\x93\x01\x02\x03", b"\x83\xa1v\x01\xa1t\xa7command\xa1f\x80"]
    targets = [keys.snapshot, keys.control, keys.channel_report]
    targets += [keys.school_perceptions("worker-0"), keys.school_commands("worker-0")]
    # Keys no actor expects: a fish id that is not a number, extra path segments, an unknown
    # school, liveliness-like paths.
    targets += [
        f"{keys.prefix}/fish/abc/outbox",
        f"{keys.prefix}/fish/abc/command",
        f"{keys.prefix}/fish/1/outbox/extra",
        f"{keys.prefix}/fish/-1/outbox",
        f"{keys.prefix}/school/nobody/commands",
        f"{keys.prefix}/alive/fish/7",
        f"{keys.prefix}/world/snapshot/extra",
    ]
    for fish_id in range(scenario.fish):
        targets += [
            keys.perception(fish_id),
            keys.command(fish_id),
            keys.outbox(fish_id),
            keys.inbox(fish_id),
        ]

    async def main() -> RunResult:
        settings = LaunchSettings(scenario, listen=endpoint, record=tmp_path / "bad.mcap")
        async with trio.open_nursery() as nursery:

            async def vandal() -> None:
                client = SessionSettings(mode="client", connect=[endpoint], connect_timeout=10)
                async with open_session(client) as session:
                    put = ZenohBus(session).put
                    await query(session, keys.control, b"\xc1 not a request", timeout=1.0)
                    while True:
                        for key in targets:
                            for payload in garbage:
                                put(key, payload)
                        await trio.sleep(0.001)

            nursery.start_soon(vandal)
            result = await launch_swarm(settings)
            nursery.cancel_scope.cancel()
            return result

    result = run_trio(main, timeout=120)
    rejected = result.summary["counts"]["rejected"]
    assert result.summary["status"] == "finished"
    assert rejected["world"] > 0
    assert rejected["observer"] > 0
    assert rejected["fish"] > 0
    assert rejected["channel"] > 0
    arrays = read_recording(tmp_path / "bad.mcap").arrays()
    np.testing.assert_array_equal(arrays["pos"], simulate_batch(scenario).position)


def test_killed_worker_loses_its_fish_and_the_run_completes(endpoint: str, tmp_path: Path) -> None:
    scenario = Scenario(fish=8, duration=400.0, seed=2)
    killed: dict[str, float | int] = {}

    def kill_at_tick_5(progress: Progress) -> None:
        if progress.tick == 5 and not killed:
            worker = next(
                p for p in multiprocessing.active_children() if p.name == "fishswarm-worker-1"
            )
            assert worker.pid is not None
            os.kill(worker.pid, signal.SIGKILL)
            killed["at"] = time.monotonic()
            killed["tick"] = progress.tick

    settings = LaunchSettings(scenario, procs=2, listen=endpoint, summary=tmp_path / "summary.json")
    result = run_trio(lambda: launch_swarm(settings, on_progress=kill_at_tick_5), timeout=120)
    summary = result.summary
    assert result.exit_code == EXIT_WORKER_DIED
    assert summary["status"] == "degraded"  # a script reading it sees the loss too
    assert summary["counts"]["ticks"] == 400
    assert sorted(lost["id"] for lost in summary["lost"]) == [4, 5, 6, 7]
    assert "SIGKILL" in summary["workers_died"][0]
    assert result.history[-1].fish == 4
    assert summary["counts"]["lost_fish"] == 4


def test_a_fish_lost_while_its_process_lives_on_degrades_the_run(endpoint: str) -> None:
    # A fish of another process (a robot, a 'fishswarm fish' by hand) joins a real-time
    # run and goes at tick 10: the run reaches its end without it. Its trajectory is not
    # what its fish decided, and the summary says so (it said 'finished', exit 0).
    from fishswarm.actors.fish import Fish, FishSettings

    scenario = Scenario(fish=3, duration=3.0, control_period=0.1, time_mode="realtime", seed=1)
    gone = trio.Event()

    def progress(snapshot: Progress) -> None:
        if snapshot.tick >= 10 and snapshot.fish == 4:
            gone.set()

    async def main() -> RunResult:
        settings = LaunchSettings(scenario, listen=endpoint)
        async with trio.open_nursery() as nursery:

            async def visitor() -> None:
                client = SessionSettings(mode="client", connect=[endpoint], connect_timeout=10)
                fish = Fish(FishSettings((9,), scenario.fish_params(), scenario.keys))
                async with open_session(client) as session, trio.open_nursery() as its:
                    await its.start(fish.run, ZenohBus(session))
                    await gone.wait()
                    its.cancel_scope.cancel()

            nursery.start_soon(visitor)
            result = await launch_swarm(settings, on_progress=progress)
            nursery.cancel_scope.cancel()
            return result

    result = run_trio(main, timeout=60)
    assert result.exit_code == EXIT_DEGRADED
    assert result.summary["status"] == "degraded"
    assert [lost["id"] for lost in result.summary["lost"]] == [9]
    assert not result.summary["workers_died"]
    from fishswarm.cli.swarm import _summary_text

    first = _summary_text(result.summary).splitlines()[0]
    assert first.startswith("status: degraded — fish were lost on the way: 9 at tick "), first


def test_fish_that_all_fail_in_the_launchers_process_stop_the_run_there(
    endpoint: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Every fish of the run failed (one behaviour's error), and no other is in the world:
    # the run ticked on empty to its end (a real-time run waiting out its whole duration).
    from fishswarm.behaviors.registry import BEHAVIORS
    from tests.behaviors.signal_behavior import FAILING

    monkeypatch.setitem(BEHAVIORS, FAILING.name, FAILING)
    scenario = Scenario(fish=4, duration=8.0, seed=2, behavior=FAILING.name)
    settings = LaunchSettings(scenario, procs=0, listen=endpoint)
    result = run_trio(lambda: launch_swarm(settings), timeout=120)
    summary = result.summary
    assert result.exit_code == EXIT_WORKER_DIED
    assert summary["status"] == "failed"  # a script reading it sees the failure too
    assert summary["counts"]["ticks"] == 3
    (died,) = summary["workers_died"]
    assert died == (
        "the fish in the launcher's process (fish 0–3) failed: BehaviorError: the behaviour "
        "'test-fails-at-third' deciding for 4 fish (3 neighbour rows each): its steer raised "
        "RuntimeError: no third decision; they are lost"
    )
    assert summary["fish"]["batches"] == 3  # their counters up to the failure are kept


@pytest.mark.slow
def test_a_worker_whose_behaviour_fails_says_why_and_the_run_stops_when_none_is_left(
    endpoint: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # It printed its whole traceback among the run's lines, and the run said only "worker 0
    # exited with code 1", then ticked on empty (in real time, to the end of its duration).
    from fishswarm.behaviors.registry import BEHAVIORS
    from tests.behaviors.signal_behavior import FAILING

    monkeypatch.setitem(BEHAVIORS, FAILING.name, FAILING)
    scenario = Scenario(fish=4, duration=30.0, seed=2, behavior=FAILING.name, time_mode="realtime")
    settings = LaunchSettings(scenario, procs=2, listen=endpoint)
    result = run_trio(lambda: launch_swarm(settings), timeout=120)
    summary = result.summary
    assert result.exit_code == EXIT_WORKER_DIED
    assert summary["status"] == "failed" and summary["counts"]["ticks"] < 10
    # Each fish lost says it failed, and how, not only that its token went.
    assert {lost["reason"] for lost in summary["lost"]} == {"failed: BehaviorError"}
    for died, fish in zip(sorted(summary["workers_died"]), ("0–1", "2–3"), strict=True):
        assert died.startswith("worker ") and f"(fish {fish}) failed: BehaviorError: the " in died
        assert died.endswith(
            "'test-fails-at-third' deciding for 2 fish (3 neighbour rows each): its steer raised "
            "RuntimeError: no third decision; its fish are lost"
        ), died


@pytest.mark.parametrize("up", [False, True])
def test_fish_that_fail_in_the_launchers_process_before_the_world_has_them_fail_the_run(
    endpoint: str, monkeypatch: pytest.MonkeyPatch, up: bool
) -> None:
    # Before the fish are up, or up but before the world admitted them: the run fails at
    # once (as when a worker dies then), not after the start timeout.
    from fishswarm.actors.fish import Fish

    async def fail(self: Fish, bus: Any, *, task_status: Any = trio.TASK_STATUS_IGNORED) -> None:
        if up:
            task_status.started()
        raise OSError("no fins today")

    monkeypatch.setattr(Fish, "run", fail)
    settings = LaunchSettings(
        Scenario(fish=3, duration=2.0, seed=1), procs=0, listen=endpoint, start_timeout=60
    )
    started = time.monotonic()
    with pytest.raises(ExceptionGroup) as raised:
        run_trio(lambda: launch_swarm(settings), timeout=60)
    if up:
        assert raised.group_contains(WorkerFailed, match="OSError: no fins today, before the")
    else:
        assert raised.group_contains(OSError, match="no fins today")
    assert time.monotonic() - started < 10


def test_a_killed_worker_is_noticed_by_liveliness_not_by_the_command_timeout(
    endpoint: str,
) -> None:
    from fishswarm.actors.world import World, WorldSettings

    scenario = Scenario(fish=4, duration=100_000.0, seed=1)

    async def main() -> None:
        from fishswarm.actors.workers import WorkerSpec, start_worker, stop_worker

        router = SessionSettings(mode="router", listen=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2, 3)))
        spec = WorkerSpec(0, (0, 1, 2, 3), scenario.fish_params(), scenario.swarm, endpoint)
        worker = start_worker(spec)
        try:
            async with open_session(router) as session, trio.open_nursery() as nursery:
                nursery.start_soon(world.run, ZenohBus(session))
                with trio.fail_after(60):
                    while world.tick < 3:
                        await trio.sleep(0.01)
                assert worker.process.pid is not None
                os.kill(worker.process.pid, signal.SIGKILL)
                with trio.fail_after(5):  # half the command timeout: liveliness told
                    while len(world.lost) < 4:
                        await trio.sleep(0.01)
                nursery.cancel_scope.cancel()
        finally:
            await trio.to_thread.run_sync(stop_worker, worker)
        assert sorted(f.fish_id for f in world.lost) == [0, 1, 2, 3]
        assert {f.reason for f in world.lost} == {"left (liveliness token gone)"}

    run_trio(main)


def test_a_stop_signal_while_a_worker_starts_neither_kills_it_nor_loses_its_counters(
    endpoint: str,
) -> None:
    # Ctrl-C and SIGTERM reach every process of the group, also a worker still importing
    # fishswarm; they are the launcher's to act on. Sent right after the start, they land
    # long before the new interpreter could set its own handlers.
    from fishswarm.actors.workers import WorkerSpec, start_worker, stop_worker

    scenario = Scenario(fish=2, seed=1)

    async def main() -> None:
        async with open_session(SessionSettings(mode="router", listen=[endpoint])):
            spec = WorkerSpec(0, (0, 1), scenario.fish_params(), scenario.swarm, endpoint)
            worker = start_worker(spec)
            try:
                assert worker.process.pid is not None
                for number in (signal.SIGTERM, signal.SIGINT):
                    os.kill(worker.process.pid, number)
                ready = await trio.to_thread.run_sync(worker.connection.poll, 60.0)
                assert ready and worker.connection.recv() == ("ready", 0)
                assert worker.process.is_alive()
            finally:
                await trio.to_thread.run_sync(stop_worker, worker)
            assert worker.process.exitcode == 0
            assert worker.statistics is not None

    run_trio(main, timeout=90)


def test_late_fish_is_included_from_a_later_tick(endpoint: str) -> None:
    from fishswarm.actors.fish import Fish, FishSettings
    from fishswarm.actors.observer import Observer
    from fishswarm.actors.world import World, WorldSettings

    scenario = Scenario(fish=3, duration=100_000.0, seed=4)
    policy = scenario.fish_params()

    async def main() -> tuple[list[tuple[int, int]], list[int]]:
        router = SessionSettings(mode="router", listen=[endpoint])
        client = SessionSettings(mode="client", connect=[endpoint])
        world = World(WorldSettings(scenario, expected_fish=(0, 1, 2)))
        observer = Observer(scenario.keys)
        async with (
            open_session(router) as hub,
            open_session(client) as fish_session,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(observer.run, ZenohBus(hub))
            # A school of three, then a fish on its own keys (as a robot would be).
            school = FishSettings((0, 1, 2), policy, scenario.keys, school="tank")
            await nursery.start(Fish(school).run, ZenohBus(fish_session))
            nursery.start_soon(world.run, ZenohBus(hub))
            await observer.wait_for_tick(3)
            await nursery.start(
                Fish(FishSettings((9,), policy, scenario.keys)).run, ZenohBus(fish_session)
            )
            with trio.fail_after(10):
                while not world.joined:
                    await trio.sleep(0.01)
            joined_tick = world.joined[0][1]
            await observer.wait_for_tick(joined_tick + 3)
            nursery.cancel_scope.cancel()
        return world.joined, [p.fish for p in observer.history]

    joined, counts = run_trio(main)
    assert joined[0][0] == 9
    assert counts[0] == 3
    assert counts[-1] == 4


def test_broadcasts_cross_processes_and_are_counted_in_the_summary(
    endpoint: str, tmp_path: Path
) -> None:
    # A behaviour of the tests' own, registered here: worker processes get it with the
    # fish's parameters. Every fish broadcasts at every decision and swims towards whoever
    # it heard, so the trajectory shows whether the deliveries arrived.
    from tests.behaviors.signal_behavior import registered

    scenario = Scenario(fish=6, duration=5.0, seed=7, behavior=registered().name)
    result = _launch(scenario, endpoint, tmp_path / "signal.mcap", procs=2)
    assert result.exit_code == 0
    counts = result.summary["counts"]
    assert counts["broadcasts"] == 6 * 5
    assert counts["unannounced_broadcasts"] == 0 and counts["rejected"]["channel"] == 0
    assert counts["mismatched_fish"] == 0  # the workers' fish decide as the world's scenario
    # Each broadcast of ticks 0–3 reaches the 5 others at the next tick (all within 3 m);
    # tick 4's are delivered at the last snapshot, if the channel gets to it first.
    assert counts["deliveries"] in (4 * 6 * 5, 5 * 6 * 5)
    assert result.summary["fish"]["deliveries"] == 4 * 6 * 5
    arrays = read_recording(tmp_path / "signal.mcap").arrays()
    np.testing.assert_array_equal(arrays["pos"], simulate_batch(scenario).position)


@pytest.mark.parametrize("shape", ["tetrahedral-pyramid", "triangle", "trigonal-planar"])
def test_a_formation_with_flags_flowing_is_the_same_across_processes_and_engines(
    endpoint: str, tmp_path: Path, shape: str
) -> None:
    scenario = Scenario(
        fish=8, behavior="formation", formation=shape, duration=4.0, seed=6,
        control_period=0.5, controller="pid", spawn_radius=0.4, spacing=0.25, channel_loss=0.2,
    )  # fmt: skip
    reference = simulate_batch(scenario)
    for procs in (0, 1, 2):
        path = tmp_path / f"formation{procs}.mcap"
        result = _launch(scenario, endpoint, path, procs=procs)
        assert result.exit_code == 0
        assert result.summary["counts"]["broadcasts"] == 8 * 8
        assert result.summary["formation"]["shape_error"] > 0.0
        np.testing.assert_array_equal(read_recording(path).arrays()["pos"], reference.position)


def test_a_scheduled_formation_switch_reaches_fish_in_worker_processes(
    endpoint: str, tmp_path: Path
) -> None:
    # The fish of `fishswarm run` decide in spawned worker processes, where their
    # parameters arrive as copies: the switch must reach them there as in the batch engine.
    scenario = Scenario(
        fish=6, behavior="formation", formation="pyramid", switch_formation="diamond",
        switch_at=1.0, duration=4.0, seed=2, control_period=0.5, controller="pid",
        spawn_radius=0.4, spacing=0.25,
    )  # fmt: skip
    reference = simulate_batch(scenario)
    unswitched = simulate_batch(dataclasses.replace(scenario, switch_formation=None))
    assert not np.array_equal(reference.position[-1], unswitched.position[-1])
    path = tmp_path / "switch.mcap"
    result = _launch(scenario, endpoint, path)
    assert result.exit_code == 0
    np.testing.assert_array_equal(read_recording(path).arrays()["pos"], reference.position)
    # The summary names the shape its final formation metrics measure, and the switch.
    formation = result.summary["formation"]
    assert formation["shape"] == "diamond"
    assert formation["shapes"] == [
        {"time": 0.0, "shape": "pyramid"},
        {"time": 1.0, "shape": "diamond"},
    ]
    from fishswarm.cli.swarm import _summary_text

    assert "  formation pyramid → diamond (from 1 s): shape error " in _summary_text(result.summary)


def test_effort_sharing_in_a_flow_is_the_same_across_processes_and_engines(
    endpoint: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import fishswarm.behaviors.formation as formation

    # A column holding station behind a post against the flow, wakes on, swaps asked for
    # from 1 gain-weighted fin beat over the most rested neighbour, a tenth of the flags lost.
    scenario = Scenario(
        fish=4, behavior="formation", formation="column", duration=30.0, seed=2,
        control_period=0.5, controller="pid", spawn_radius=0.2, spacing=0.25, tolerance=0.2,
        flow=(-0.06, 0.0, 0.0), landmark=(1.3, 0.89, 0.6), station_distance=0.2,
        wake_saving=0.9, rotate_effort=True, effort_margin=1.0, channel_loss=0.1,
    )  # fmt: skip
    asking: list[int] = []
    share = formation.share_effort

    def counting(*arguments: Any, **settings: Any) -> Any:
        swaps = share(*arguments, **settings)
        asking.append(int((swaps.asking >= 0).sum()))
        return swaps

    with monkeypatch.context() as patch:
        patch.setattr(formation, "share_effort", counting)
        reference = simulate_batch(scenario)
    assert sum(asking) > 20  # swaps were asked for, agreed and made: the flags carried them
    for procs in (1, 2):
        path = tmp_path / f"energy{procs}.mcap"
        result = _launch(scenario, endpoint, path, procs=procs)
        assert result.exit_code == 0
        np.testing.assert_array_equal(read_recording(path).arrays()["pos"], reference.position)
        assert result.summary["effort"]["spread"] == pytest.approx(
            reference.effort[-1].max() / reference.effort[-1].mean(), rel=1e-12
        )


def test_a_worker_that_failed_before_the_watch_saw_it_is_counted_as_died() -> None:
    # A short run can end before the launcher's watch (every 50 ms) sees a worker fail:
    # the worker's own exit code still says it did.
    import sys

    from fishswarm.actors.launcher import _death_of, _failed_unseen, _loss_of
    from fishswarm.actors.workers import Worker, WorkerSpec

    context = multiprocessing.get_context("spawn")
    scenario = Scenario(fish=2)
    spec = WorkerSpec(0, (0, 1), scenario.fish_params(), scenario.swarm, "tcp/127.0.0.1:1")
    workers = []
    for code in (1, 0, 1, -signal.SIGKILL, -signal.SIGSEGV):
        if code >= 0:
            process = context.Process(target=sys.exit, args=(code,))
            process.start()
        else:  # ended by a signal: one stop_worker sent, or one of its own (a crash)
            process = context.Process(target=time.sleep, args=(60,))
            process.start()
            assert process.pid is not None
            os.kill(process.pid, -code)
        process.join(30)
        ours, theirs = context.Pipe()
        theirs.close()
        workers.append(Worker(spec, process, ours))
    workers[2].lost = True  # seen by the watch already: reported there
    workers[3].killed = True  # killed by stop_worker: the launcher's doing, not a failure
    failed = _failed_unseen(workers)
    assert [_death_of(worker) for worker in failed] == [
        "worker 0 (fish 0–1) exited with code 1; its fish are lost",
        "worker 0 (fish 0–1) was killed by SIGSEGV; its fish are lost",
    ]
    assert [_loss_of(worker) for worker in failed] == [
        "its worker exited with code 1",
        "its worker was killed by SIGSEGV",
    ]
    for worker in workers:
        worker.connection.close()
        worker.process.close()
