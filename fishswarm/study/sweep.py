"""Running an experiment's (value, seed) runs, in parallel processes, with a chosen engine.

An engine turns a scenario into its recorded run: the in-process batch engine
(:func:`run_on_batch_engine`) or the actor system (``fishswarm.actors.runs.run_on_actors``:
router, world, channel, observer and a worker process over Zenoh on 127.0.0.1), which gives
the same trajectories bit for bit (tested). The command line picks the engine; this module
does not know the actors. Runs are spread over processes started with ``spawn``, one per
core by default.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from fishswarm.sim.engine import run_batch
from fishswarm.sim.scenario import Scenario
from fishswarm.study.experiment import Experiment, RunOutcome

FloatArray = NDArray[np.float64]


Run = tuple[FloatArray, FloatArray, NDArray[np.int64]]
"""A recorded run: times (T,) s, positions (T, N, 3) m, neighbours seen (T, N)."""

Engine = Callable[[Scenario], Run]
"""Runs a scenario to its end (a top-level function: runs go to spawned processes)."""


def run_on_batch_engine(scenario: Scenario) -> Run:
    """The batch engine: every fish in this process, one batch."""
    trajectory = run_batch(scenario)
    return trajectory.t, trajectory.position, trajectory.neighbors_seen


def run_one(experiment: Experiment, value: float, seed: int, engine: Engine) -> RunOutcome:
    """Run one (value, seed) of an experiment with ``engine``."""
    scenario = experiment.scenario_for(value, seed)
    started = time.perf_counter()
    t, position, seen = engine(scenario)
    metrics = experiment.metrics_of(scenario, position, seen)
    return RunOutcome(value, seed, t, metrics, position, time.perf_counter() - started)


Progress = Callable[[int, int, RunOutcome], None]


def run_experiment(
    experiment: Experiment,
    *,
    engine: Engine = run_on_batch_engine,
    jobs: int | None = None,
    on_run: Progress | None = None,
) -> list[RunOutcome]:
    """Run every (value, seed) of an experiment, ``jobs`` at a time in spawned processes.

    Args:
        experiment: what to run.
        engine: how each run goes (:data:`Engine`).
        jobs: parallel runs; default the number of cores; 1 runs in this process.
        on_run: called after each run with (runs done, runs in all, the outcome).

    Returns:
        The outcomes in the order of :meth:`Experiment.runs`.
    """
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
