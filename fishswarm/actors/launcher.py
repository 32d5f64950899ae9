"""The launcher behind ``fishswarm run``: one command runs a whole simulated swarm.

It opens the listening endpoint (a Zenoh router), starts the observer, the channel and the
world in this process, spawns the fish over worker processes (or, with none, runs them here
too), runs the scenario, writes the recording and the summary, and tears everything down —
on success, on Ctrl-C and when a worker dies (the run goes on without its fish, and ends
with a clear message and a non-zero exit).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import os
import signal
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trio

from fishswarm.actors.channel import Channel
from fishswarm.actors.control import run_control
from fishswarm.actors.fish import (
    PERCEPTION_TIMEOUT,
    Fish,
    FishStatistics,
    fish_span,
)
from fishswarm.actors.logs import log_prefix
from fishswarm.actors.observer import Observer, Progress
from fishswarm.actors.security import secure_run
from fishswarm.actors.session import SessionSettings, open_session
from fishswarm.actors.workers import (
    Worker,
    WorkerSpec,
    school_of,
    sole_error,
    split_fish,
    start_worker,
    stop_worker,
)
from fishswarm.actors.world import World, WorldSettings
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.behaviors.core import BehaviorError
from fishswarm.protocols.jsontext import json_text
from fishswarm.protocols.messages import ControlRequest
from fishswarm.sim.decision_kernels import prepare, with_compiled_decisions
from fishswarm.sim.scenario import COMMAND_TIMEOUT, START_TIMEOUT, Scenario
from fishswarm.study.experiment import ORBIT_SUMMARIES
from fishswarm.study.metrics import METRIC_NAMES, formation_summary
from fishswarm.study.recording import open_recorder
from fishswarm.study.scene import Scene

log = logging.getLogger(__name__)

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_WORKER_DIED = 3
EXIT_DEGRADED = 4
"""The run reached its end, but fish were stopped by their safety watchdog on the way."""
EXIT_INTERRUPTED = 130


class WorkerFailed(RuntimeError):
    """A worker process died, or the fish in the launcher's process failed, before the
    fish came up."""


@dataclass(frozen=True)
class LaunchSettings:
    """How to launch a run.

    Attributes:
        scenario: what to run.
        procs: number of fish worker processes; 0 runs the fish in this process, as trio
            tasks beside the world, talking to it over this process's own Zenoh session (a
            tick then waits for no other process; as with one worker, a failure of a fish
            loses them all). None: :func:`default_procs` of the scenario's fish.
        listen: endpoint the router listens on (loopback by default; 0.0.0.0 lets observers
            on other machines attach).
        record: MCAP recording to write (None: none).
        summary: JSON summary to write (None: none).
        start_timeout: longest wait for every fish to come up, s.
        command_timeout: a fish silent this long in a tick is marked lost, s.
        perception_timeout: each fish's safety watchdog: fins off after this long without a
            perception or a pulse of the world, s.
        log_level: logging level of the workers.
        handle_signals: stop cleanly on SIGINT (Ctrl-C) and SIGTERM, recording the run as
            interrupted (needs the main thread; the command line sets it).
        secure: a secured swarm's folder (:mod:`fishswarm.actors.security`): the router
            listens on TLS only with its access control, extended for this run's schools,
            and each worker connects with a certificate signed for the run (None: open).
    """

    scenario: Scenario
    procs: int | None = None
    listen: str = "tcp/127.0.0.1:7447"
    record: Path | None = None
    summary: Path | None = None
    start_timeout: float = START_TIMEOUT
    command_timeout: float = COMMAND_TIMEOUT
    perception_timeout: float = PERCEPTION_TIMEOUT
    log_level: str = "WARNING"
    handle_signals: bool = False
    secure: Path | None = None

    @property
    def worker_processes(self) -> int:
        """The fish worker processes of the run: ``procs`` (at most one a fish), or the
        default for its fish."""
        if self.procs is None:
            return default_procs(self.scenario.fish)
        return min(self.procs, self.scenario.fish)


IN_PROCESS_MAX_FISH = 2_000
"""Up to this many fish a run keeps them in the launcher's process unless told otherwise: a
choice between the sizes measured, 1 000 fish (faster here) and 10 000 (faster with
workers); between them it is not measured. Measured on two cores (docs/benchmarks.md,
twenty-eighth session), the fish there against one worker process: 25 fish 5-31 % shorter
ticks in eight interleaved pairs, 1 000 fish from 11 % longer to 14 % shorter (within the
spread of runs), and the first tick after 0.2-0.3 s instead of 0.7-1.4 s. At 10 000 fish,
over four runs, two workers gave 0.70-0.85 of the batch engine's speed (mean 0.76), one
0.69-0.78 (0.73), the launcher's process 0.63-0.78 (0.71): the world's sending of large
schools' perceptions in parts overlaps the workers' deciding. Since the twenty-ninth
session's changes the launcher's process has often been ahead at 10 000 fish (thirty-first
session: shorter in 7 of 9 interleaved pairs, 46.6-72.7 ms a tick against 50.4-72.3): no
longer a clear choice either way; two workers stay the default beyond 2 000 fish."""


def where_fish_run(procs: int) -> str:
    """``the fish in the launcher's process``, ``1 worker process``, ``2 worker processes``."""
    if procs == 0:
        return "the fish in the launcher's process"
    return f"{procs} worker process{'es' if procs > 1 else ''}"


def default_procs(fish: int) -> int:
    """Worker processes for a run of ``fish`` when none are asked for: none (the fish in
    the launcher's process) up to :data:`IN_PROCESS_MAX_FISH`, two beyond (one a core)."""
    return 0 if fish <= IN_PROCESS_MAX_FISH else 2


@dataclass
class RunResult:
    """The outcome of a run."""

    exit_code: int
    summary: dict[str, Any]
    history: list[Progress] = field(default_factory=list)


async def launch_swarm(
    settings: LaunchSettings,
    *,
    on_progress: Callable[[Progress], None] | None = None,
    on_scene: Callable[[Scene, dict[str, float]], None] | None = None,
) -> RunResult:
    """Run a whole swarm to the end of its scenario and return the summary; the observer
    calls ``on_progress`` and ``on_scene`` (e.g. a live view) after every snapshot."""
    scenario = settings.scenario
    procs = settings.worker_processes
    if procs < 0:
        raise ValueError(f"procs must be 0 (the fish in this process) or more, got {procs}")
    started = time.perf_counter()
    everyone = tuple(range(scenario.fish))
    schools = split_fish(list(everyone), procs) if procs > 0 else []
    here = procs == 0
    workers: list[Worker] = []
    fish_here: Fish | None = None
    died: list[str] = []
    status = "failed"
    none_left = False
    world = World(
        WorldSettings(
            scenario,
            expected_fish=everyone,
            start_timeout=settings.start_timeout,
            command_timeout=settings.command_timeout,
            vouched_only=settings.secure is not None,
        )
    )
    channel = Channel(scenario)
    interrupted = trio.Event()
    with contextlib.ExitStack() as files:
        router_extra: dict[str, Any] = {}
        worker_extra: dict[str, dict[str, Any]] = {}
        if settings.secure is not None:
            signed = Path(files.enter_context(tempfile.TemporaryDirectory(prefix="fishswarm-")))
            names = {school_of(index): ids for index, ids in enumerate(schools)}
            router_extra, worker_extra = secure_run(settings.secure, scenario.keys, names, signed)
        router = SessionSettings(
            mode="router",
            listen=[settings.listen],
            extra=router_extra,
            # Shared memory carries large messages to other processes: without workers, only
            # to observers on this machine, for whom Zenoh's default pool does.
            shared_memory_pool_bytes=None if here else shared_memory_pool_bytes(scenario.fish),
        )
        # The router first: a run that cannot open it (the port is taken) fails before
        # it replaces the last run's recording and summary.
        async with open_session(router) as session:
            recorder = (
                files.enter_context(open_recorder(settings.record, scenario.to_dict()))
                if settings.record is not None
                else None
            )
            observer = Observer.of(
                scenario, recorder=recorder, on_progress=on_progress, on_scene=on_scene
            )
            observer.world_run = world.run_id
            try:
                async with trio.open_nursery() as nursery:
                    # With the fish here, every message of a tick goes between actors of
                    # this process: delivered inside the put, nothing waits for a thread.
                    bus = ZenohBus(session, inline=here)
                    await nursery.start(observer.run, bus)
                    await nursery.start(channel.run, bus)
                    await nursery.start(run_control, session, world)
                    params = with_compiled_decisions(scenario.fish_params(), scenario.fish)
                    specs = [
                        WorkerSpec(
                            index,
                            ids,
                            params,
                            scenario.swarm,
                            _connect_to(settings.listen),
                            perception_timeout=settings.perception_timeout,
                            log_level=settings.log_level,
                            log_prefix=log_prefix(),
                            session_extra=worker_extra.get(school_of(index), {}),
                        )
                        for index, ids in enumerate(schools or [everyone])
                    ]
                    failed_here = False

                    def stop_if_none_left() -> None:
                        """Every fish this run started has failed, and no other fish (a
                        robot's) is in the world: nothing is left to decide, so the run
                        stops now instead of ticking empty to its end."""
                        nonlocal none_left
                        if (here and not failed_here) or not all(w.lost for w in workers):
                            return
                        # Fish beyond this run's own (robots) may come back after a lost
                        # link: a run that ever had one goes on.
                        others = world.unexpected or world.roster.alive - set(everyone)
                        if others or world.state_name in ("stopping", "stopped", "finished"):
                            return
                        none_left = True
                        log.error(
                            "every fish of the run failed and no other is in the world: the "
                            "run stops at tick %d",
                            world.tick,
                        )
                        world.control(ControlRequest("stop"))

                    def lost_here() -> None:
                        nonlocal failed_here
                        failed_here = True
                        stop_if_none_left()

                    if here:
                        prepare(params)
                        fish_here = specs[0].fish()
                        await nursery.start(
                            _run_fish_here,
                            fish_here,
                            bus,
                            died,
                            world,
                            lost_here,
                        )
                    else:
                        workers += [start_worker(spec) for spec in specs]
                    if workers:
                        nursery.start_soon(_watch_workers, workers, died, world, stop_if_none_left)
                    if settings.handle_signals:
                        nursery.start_soon(_watch_signals, interrupted, nursery.cancel_scope)
                    await world.run(bus)
                    with trio.move_on_after(5.0):
                        await observer.wait_for_tick(world.tick)
                    status = "stopped" if world.state_name == "stopped" else "finished"
                    if none_left:
                        status = "failed"
                    nursery.cancel_scope.cancel()
                if interrupted.is_set():
                    status = "interrupted"
            except BaseException as error:
                if _contains(error, KeyboardInterrupt):
                    status = "interrupted"
                raise
            finally:
                with trio.CancelScope(shield=True):
                    await _stop_all(workers)
                for worker in _failed_unseen(workers):
                    _report_death(worker, died, world)
                summary = _summary(
                    settings,
                    status,
                    world,
                    channel,
                    observer,
                    [w.statistics for w in workers if w.statistics is not None]
                    + ([fish_here.statistics()] if fish_here is not None else []),
                    died,
                    time.perf_counter() - started,
                )
                if settings.summary is not None:
                    settings.summary.parent.mkdir(parents=True, exist_ok=True)
                    settings.summary.write_text(
                        json_text(summary, indent=2) + "\n", encoding="utf-8"
                    )
    exit_code = (
        EXIT_INTERRUPTED
        if status == "interrupted"
        else EXIT_WORKER_DIED
        if died
        else EXIT_DEGRADED
        if summary["status"] == "degraded"
        else EXIT_OK
    )
    return RunResult(exit_code, summary, observer.history)


def shapes_told(history: list[Progress]) -> dict[str, Any]:
    """The shape a formation run's final metrics measure (``shape``), and every shape its
    fish were told to take, from when (``shapes``: time s, shape; one entry when the run was
    never switched)."""
    shapes: list[dict[str, Any]] = []
    for progress in history:
        if not shapes or progress.shape != shapes[-1]["shape"]:
            shapes.append({"time": progress.time, "shape": progress.shape})
    return {"shape": history[-1].shape, "shapes": shapes}


def shared_memory_pool_bytes(fish: int, *, free: int | None = None) -> int | None:
    """Bytes of shared memory for the world's Zenoh session (the launcher's, or that of
    ``fishswarm world``) to copy its large messages into for the fish on this machine:
    8 KiB a fish beyond Zenoh's default of 16 MiB (None: the default, up to 2 048 fish), at
    most half of what ``/dev/shm`` has free.

    A crowded tank's tick puts about 0.7 KiB a fish (perceptions and snapshot), and the
    pool must hold several ticks' worth while the workers let go of them; a message that
    finds it full goes through the socket instead (10 000 fish: 2.4 MB parts, 0.3 ms to put
    into shared memory against 1.8 ms through the socket). A pool larger than the free
    space would not fit: Zenoh then sends everything through the socket and leaves the
    failed pool's file behind, filling ``/dev/shm`` for every session after it (Docker
    gives a container 64 MB unless told otherwise with ``--shm-size``).

    Args:
        fish: how many fish the run has.
        free: bytes free for shared memory (None: ask ``/dev/shm``; unknown: the default).
    """
    wanted = fish * 8 * 2**10
    default = 16 * 2**20
    if wanted <= default:
        return None
    if free is None:
        try:
            stats = os.statvfs("/dev/shm")
        except OSError:
            return None
        free = stats.f_bavail * stats.f_frsize
    pool = min(wanted, free // 2)
    return pool if pool > default else None


def _contains(error: BaseException, kind: type[BaseException]) -> bool:
    """Whether ``error`` is ``kind`` or an exception group holding one."""
    if isinstance(error, BaseExceptionGroup):
        return error.subgroup(kind) is not None
    return isinstance(error, kind)


def _connect_to(listen: str) -> str:
    """Where local workers connect for a listening endpoint (0.0.0.0 → loopback)."""
    return listen.replace("0.0.0.0", "127.0.0.1").replace("[::]", "[::1]")


async def _watch_signals(interrupted: trio.Event, scope: trio.CancelScope) -> None:
    with trio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async for number in signals:
            log.warning("%s received: stopping", signal.Signals(number).name)
            interrupted.set()
            scope.cancel()
            return


async def _run_fish_here(
    fish: Fish,
    bus: ZenohBus,
    died: list[str],
    world: World,
    on_lost: Callable[[], None],
    *,
    task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
) -> None:
    """Serve the fish in the launcher's process. A failure of theirs once the run is under
    way loses them, as a dead worker loses its fish, and the world goes on without them
    (``on_lost`` is called); one before the world has them all fails the run, as a worker
    that dies then does."""
    up = False
    try:
        async with trio.open_nursery() as nursery:
            await nursery.start(fish.run, bus)
            up = True
            task_status.started()
    except Exception as error:
        if not up:
            raise
        error = sole_error(error)
        failure = (
            f"the fish in the launcher's process (fish {fish_span(fish.settings.fish_ids)}) "
            f"failed: {type(error).__name__}: {error}"
        )
        if world.state_name == "waiting":
            raise WorkerFailed(f"{failure}, before the world had them all") from error
        message = f"{failure}; they are lost"
        # A behaviour's own error says all there is to say; anything else, where it came from.
        log.error(message, exc_info=None if isinstance(error, BehaviorError) else error)
        died.append(message)
        world.explain_loss(fish.settings.fish_ids, f"failed: {type(error).__name__}")
        on_lost()


async def _watch_workers(
    workers: list[Worker], died: list[str], world: World, on_lost: Callable[[], None]
) -> None:
    while True:
        for worker in workers:
            if worker.stopping or worker.lost:
                continue
            if worker.process.exitcode is not None:
                worker.lost = True
                if world.state_name == "waiting":
                    died.append(_death_of(worker))
                    raise WorkerFailed(
                        f"{worker.spec.describe()} {worker.exit_description()} before its fish "
                        "came up; run with --log-level INFO to see why"
                    )
                _report_death(worker, died, world)
                on_lost()
        await trio.sleep(0.05)


def _failed_unseen(workers: list[Worker]) -> list[Worker]:
    """The workers that failed on their own without the watch seeing it (it looks every
    50 ms; a short run can end first): ended with an error or a signal we did not send, and
    no counters to give."""
    return [
        worker
        for worker in workers
        if not (worker.lost or worker.killed)
        and worker.statistics is None
        and worker.process.exitcode not in (0, None)
    ]


def _death_of(worker: Worker) -> str:
    return f"{worker.spec.describe()} {worker.exit_description()}; its fish are lost"


def _loss_of(worker: Worker) -> str:
    """Why a dead worker's fish are lost, short enough to follow each of them: the kind of
    error it said it failed with, or how it ended."""
    ended = worker.exit_description()  # reads what it said, if anything
    if worker.failure is not None:
        return f"failed: {worker.failure.partition(':')[0]}"
    return f"its worker {ended}"


def _report_death(worker: Worker, died: list[str], world: World) -> None:
    """Say that a worker died, once, when seen: in the log, in the run's list of deaths, and
    to the world, as why its fish are lost."""
    message = _death_of(worker)
    log.error(message)
    died.append(message)
    world.explain_loss(worker.spec.fish_ids, _loss_of(worker))


async def _stop_all(workers: list[Worker]) -> None:
    async with trio.open_nursery() as nursery:
        for worker in workers:
            nursery.start_soon(_stop_in_thread, worker)


async def _stop_in_thread(worker: Worker) -> None:
    await trio.to_thread.run_sync(stop_worker, worker)


def _summary(
    settings: LaunchSettings,
    status: str,
    world: World,
    channel: Channel,
    observer: Observer,
    fish_statistics: list[FishStatistics],
    died: list[str],
    wall_time: float,
) -> dict[str, Any]:
    history = observer.history
    metrics: dict[str, Any] = {}
    if history:
        first, last = history[0].metrics, history[-1].metrics
        for name in (*METRIC_NAMES, "neighbors_seen"):
            # None where it is not defined: from zero, or to or from a world without fish.
            defined = first[name] and math.isfinite(first[name]) and math.isfinite(last[name])
            change = 100.0 * (last[name] - first[name]) / first[name] if defined else None
            metrics[name] = {"initial": first[name], "final": last[name], "change_percent": change}
    formation = None
    if history and observer.formation is not None:
        told = shapes_told(history)
        times, series = [p.time for p in history], [p.metrics for p in history]
        since = told["shapes"][-1]["time"]
        formation = {**formation_summary(times, series, since=since), **told}
    orbit = None
    if history and observer.orbit is not None:
        centre = observer.orbit.centre
        orbit = {
            "post": None if centre is None else [float(v) for v in centre],
            "orbit_radius": observer.orbit.radius,
            **{
                column.key: column.reduce(np.array([p.metrics[column.metric] for p in history]))
                for column in ORBIT_SUMMARIES
            },
        }
    fish_totals: dict[str, int] = {}
    for statistics in fish_statistics:
        for name, value in dataclasses.asdict(statistics).items():
            fish_totals[name] = fish_totals.get(name, 0) + int(value)
    if status == "finished" and (fish_totals.get("watchdog_stops", 0) or world.lost or died):
        # Fins were off for part of the run, or fish went missing (their process died, hung,
        # or a robot went): its trajectory is not what the fish decided. (Fish whose process
        # died make the run's exit code say so too: 3, not 4; workers_died names them.)
        status = "degraded"
    world_stats = world.statistics()
    channel_stats = channel.statistics()
    simulated = world.tick * settings.scenario.control_period
    return {
        "status": status,
        "scenario": settings.scenario.to_dict(),
        "procs": settings.worker_processes,
        "listen": settings.listen,
        "metrics": metrics,
        "formation": formation,
        "orbit": orbit,
        "effort": (
            {
                "school": history[-1].metrics["effort"],
                "spread": history[-1].metrics["effort_spread"],
            }
            if history and "effort" in history[-1].metrics
            else None
        ),
        "counts": {
            "ticks": world.tick,
            "messages": world_stats.messages_in + world_stats.messages_out,
            "rejected": {
                "world": world_stats.rejected_total,
                "channel": channel_stats.rejected,
                "observer": observer.statistics().rejected,
                "fish": fish_totals.get("rejected", 0),
            },
            "lost_fish": len(world.lost),
            "joined_fish": len(world.joined),
            "late_commands": world.late_commands,
            "deliveries": channel_stats.delivered,
            "broadcasts": world_stats.broadcasts,
            "unannounced_broadcasts": channel_stats.unannounced,
            "mismatched_fish": world_stats.mismatched_fish,
            "unexpected_fish": world_stats.unexpected_fish,
        },
        "vision": world.sim.sight.summary() if world.params.cameras is not None else None,
        "lost": [{"id": f.fish_id, "tick": f.tick, "reason": f.reason} for f in world.lost],
        "joined": [{"id": fish_id, "tick": tick} for fish_id, tick in world.joined],
        "workers_died": died,
        "fish": fish_totals,
        "simulated_time": simulated,
        "wall_time": wall_time,
        "loop_time": world.wall_time,
        "paused_time": world.paused_time,
        "compiled_kernels": world.params.compiled,
        "world_time": {
            "physics": world_stats.physics_time_median,
            "vision": world_stats.vision_time_median,
            "perceptions": world_stats.perceptions_time_median,
        },
        "answer_time": {
            "median": world_stats.answer_time_median,
            "p90": world_stats.answer_time_p90,
        },
        # Of the time the ticks ran: an operator's pause is no time the world took.
        "real_time_factor": (
            simulated / (world.wall_time - world.paused_time)
            if world.wall_time > world.paused_time
            else None
        ),
        # None too when nothing was recorded (stopped before the first snapshot): the file
        # is then as it was.
        "recording": (
            str(settings.record)
            if settings.record and observer.recorder is not None and observer.recorder.begun
            else None
        ),
        "summary": str(settings.summary) if settings.summary else None,
    }
