"""Running an experiment's (value, seed) runs, in parallel processes.

Every run goes through the actor system (router, world, channel, observer and a worker
process, over Zenoh on 127.0.0.1) or, with the ``batch`` engine, through the in-process
batch engine that calls the same pure functions and gives the same trajectories bit for bit
(tested). Runs are spread over processes started with ``spawn``, one per core by default.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trio
from numpy.typing import NDArray

from fishswarm.actors.bridge import free_loopback_endpoint
from fishswarm.actors.launcher import LaunchSettings, run_swarm
from fishswarm.experiment import ENGINES, Experiment, RunOutcome
from fishswarm.recording import read_recording
from fishswarm.scenario import ConfigError, Scenario
from fishswarm.simulation import run_batch

FloatArray = NDArray[np.float64]


def run_one(experiment: Experiment, value: float, seed: int, engine: str) -> RunOutcome:
    """Run one (value, seed) of an experiment with the ``actors`` or ``batch`` engine."""
    scenario = experiment.scenario_for(value, seed)
    started = time.perf_counter()
    if engine == "batch":
        trajectory = run_batch(scenario)
        t, position, seen = trajectory.t, trajectory.position, trajectory.neighbors_seen
    elif engine == "actors":
        t, position, seen = _run_actors(scenario)
    else:
        raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    metrics = experiment.metrics_of(scenario, position, seen)
    return RunOutcome(value, seed, t, metrics, position, time.perf_counter() - started)


def _run_actors(scenario: Scenario) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
    """Run through the actor system, recording to a temporary MCAP file read back after."""
    endpoint = free_loopback_endpoint()
    with tempfile.TemporaryDirectory(prefix="fishswarm-experiment-") as folder:
        record = Path(folder) / "run.mcap"
        settings = LaunchSettings(scenario, listen=endpoint, record=record)
        result = trio.run(run_swarm, settings)
        if result.summary["status"] != "finished":
            raise RuntimeError(
                f"run with seed {scenario.seed} ended {result.summary['status']} "
                f"(exit code {result.exit_code})"
            )
        snapshots = read_recording(record).snapshots
    t = np.array([s.time for s in snapshots])
    position = np.array([s.position for s in snapshots])
    seen = np.array([s.neighbors_seen for s in snapshots])
    return t, position, seen


Progress = Callable[[int, int, RunOutcome], None]


def run_experiment(
    experiment: Experiment,
    *,
    engine: str = "actors",
    jobs: int | None = None,
    on_run: Progress | None = None,
) -> list[RunOutcome]:
    """Run every (value, seed) of an experiment, ``jobs`` at a time in spawned processes.

    Args:
        experiment: what to run.
        engine: ``actors`` (the actor system over Zenoh) or ``batch``.
        jobs: parallel runs; default the number of cores; 1 runs in this process.
        on_run: called after each run with (runs done, runs in all, the outcome).

    Returns:
        The outcomes in the order of :meth:`Experiment.runs`.
    """
    if engine not in ENGINES:
        raise ConfigError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    pairs = experiment.runs()
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(pairs)))
    outcomes: dict[tuple[float, int], RunOutcome] = {}

    def done(outcome: RunOutcome) -> None:
        outcomes[(outcome.value, outcome.seed)] = outcome
        if on_run is not None:
            on_run(len(outcomes), len(pairs), outcome)

    if jobs == 1:
        for value, seed in pairs:
            done(run_one(experiment, value, seed, engine))
    else:
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=context) as pool:
            futures = [pool.submit(run_one, experiment, v, s, engine) for v, s in pairs]
            for future in concurrent.futures.as_completed(futures):
                done(future.result())
    return [outcomes[pair] for pair in pairs]
