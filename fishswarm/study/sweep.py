"""Running an experiment's (group, value, seed) runs, in parallel processes, with a chosen engine.

An engine turns a scenario into its recorded run: the in-process batch engine
(:func:`simulate_on_batch_engine`) or the actor system
(``fishswarm.actors.runs.simulate_on_actors``:
router, world, channel, observer and the fish over Zenoh on 127.0.0.1), which gives
the same trajectories bit for bit (tested). The command line picks the engine; this module
does not know the actors. Runs are spread over processes started with ``spawn``, one per
core by default. Ctrl-C stops a sweep between runs (the runs in progress finish, the others
do not start): the runs done come back in :class:`SweepInterrupted`, so that their report
can still be written.
"""

from __future__ import annotations

import concurrent.futures
import logging
import multiprocessing
import os
import signal
import time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from fishswarm.sim.allocator import tune_allocator
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.openmp import tune_openmp
from fishswarm.sim.scenario import Scenario
from fishswarm.study.experiment import Experiment, RunKey, RunOutcome

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


Run = tuple[FloatArray, FloatArray, NDArray[np.int64], FloatArray]
"""A recorded run: times (T,) s, positions (T, N, 3) m, neighbours seen (T, N), each fish's
effort so far (T, N, gain-weighted fin beats)."""

Engine = Callable[[Scenario], Run]
"""Runs a scenario to its end (a top-level function: runs go to spawned processes)."""


def simulate_on_batch_engine(scenario: Scenario) -> Run:
    """The batch engine: every fish in this process, one batch."""
    trajectory = simulate_batch(scenario)
    return trajectory.t, trajectory.position, trajectory.neighbors_seen, trajectory.effort


def simulate_one(experiment: Experiment, key: RunKey, engine: Engine) -> RunOutcome:
    """Run one (group, value, seed) of an experiment with ``engine``."""
    group, value, seed = key
    scenario = experiment.scenario_for(value, seed, group)
    started = time.perf_counter()
    t, position, seen, effort = engine(scenario)
    metrics = experiment.metrics_of(scenario, position, seen, effort, times=t)
    elapsed = time.perf_counter() - started
    return RunOutcome(value, seed, t, metrics, position, elapsed, group)


Progress = Callable[[int, int, RunOutcome], None]


class SweepFailed(RuntimeError):
    """A run of a sweep failed; the sweep stopped its other runs. ``outcomes`` holds the runs
    finished before, in the order of :meth:`Experiment.runs`, ``total`` the runs the sweep
    had, and the message says which run failed and why."""

    def __init__(self, outcomes: list[RunOutcome], total: int, failure: str) -> None:
        super().__init__(failure)
        self.outcomes = outcomes
        self.total = total


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a sweep; ``outcomes`` holds the runs finished before it, in the order
    of :meth:`Experiment.runs`, and ``total`` the runs the sweep had."""

    def __init__(self, outcomes: list[RunOutcome], total: int) -> None:
        super().__init__(f"interrupted after {len(outcomes)} of {total} runs")
        self.outcomes = outcomes
        self.total = total


def _start_process() -> None:
    """Set up a sweep's process: it leaves Ctrl-C to the sweep, which stops it, and keeps
    its freed arrays for the next run's."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    tune_allocator()
    tune_openmp()


def sweep_experiment(
    experiment: Experiment,
    *,
    engine: Engine = simulate_on_batch_engine,
    jobs: int | None = None,
    on_run: Progress | None = None,
) -> list[RunOutcome]:
    """Run every (group, value, seed) of an experiment, ``jobs`` at a time in spawned
    processes.

    Args:
        experiment: what to run.
        engine: how each run goes (:data:`Engine`).
        jobs: parallel runs; default the number of cores; 1 runs in this process.
        on_run: called after each run with (runs done, runs in all, the outcome).

    Returns:
        The outcomes in the order of :meth:`Experiment.runs`.

    Raises:
        SweepInterrupted: Ctrl-C; the runs still going are stopped, those done come with it.
        SweepFailed: a run raised; the runs not started are not, those done come with it.
    """
    pairs = experiment.runs()
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(pairs)))
    outcomes: dict[RunKey, RunOutcome] = {}

    def done(outcome: RunOutcome) -> None:
        outcomes[(outcome.group, outcome.value, outcome.seed)] = outcome
        if on_run is not None:
            on_run(len(outcomes), len(pairs), outcome)

    try:
        if jobs == 1:
            for key in pairs:
                done(simulate_one(experiment, key, engine))
        else:
            _run_in_processes(experiment, pairs, engine, jobs, done)
    except KeyboardInterrupt:
        finished = [outcomes[pair] for pair in pairs if pair in outcomes]
        raise SweepInterrupted(finished, len(pairs)) from None
    except Exception as error:
        finished = [outcomes[pair] for pair in pairs if pair in outcomes]
        raise SweepFailed(finished, len(pairs), f"{type(error).__name__}: {error}") from error
    return [outcomes[pair] for pair in pairs]


def _run_in_processes(
    experiment: Experiment,
    pairs: list[RunKey],
    engine: Engine,
    jobs: int,
    done: Callable[[RunOutcome], None],
) -> None:
    """Run the pairs in ``jobs`` spawned processes, handing each outcome to ``done``.

    The processes ignore Ctrl-C; on Ctrl-C here, or when a run fails, the runs not started
    are cancelled, those in progress finish and are handed over too (a second Ctrl-C drops
    them), no process is left behind, and the interrupt or the run's error goes on up.
    """
    context = multiprocessing.get_context("spawn")
    pool = concurrent.futures.ProcessPoolExecutor(
        jobs, mp_context=context, initializer=_start_process
    )
    futures = [pool.submit(simulate_one, experiment, key, engine) for key in pairs]
    handed: set[concurrent.futures.Future[RunOutcome]] = set()
    try:
        for future in concurrent.futures.as_completed(futures):
            handed.add(future)
            done(future.result())
    except BaseException:
        _stop_runs(pool, [future for future in futures if future not in handed], done)
        raise
    pool.shutdown(wait=True)


STOP_GRACE = 2.0
"""How long a sweep's process has to exit by itself once its runs are over, s; then it is
terminated."""


def _stop_runs(
    pool: concurrent.futures.ProcessPoolExecutor,
    waiting: list[concurrent.futures.Future[RunOutcome]],
    done: Callable[[RunOutcome], None],
) -> None:
    """Stop a sweep: cancel the runs not handed to its processes, hand over those that were
    as they finish (until a Ctrl-C drops them), and end the processes. (The executor hands
    each process its run and one run more, queued.)

    The processes are ended here, not by ``pool.shutdown(wait=True)``: after a Ctrl-C that
    one waited, once in eight tries, for ever, on a process blocked writing its result to a
    pipe nobody read any more.
    """
    # The private list of processes: the executor has no public way to end them.
    processes = list((pool._processes or {}).values())
    dropped = False
    try:
        under_way = [future for future in waiting if not future.cancel()]
        unfinished = [future for future in under_way if not future.done()]
        if unfinished:
            log.warning(
                "stopping: waiting for the %d run(s) handed to its processes to finish "
                "(Ctrl-C drops them)",
                len(unfinished),
            )
        for future in concurrent.futures.as_completed(under_way):
            if future.exception() is None:
                done(future.result())
    except KeyboardInterrupt:
        dropped = True
        log.warning("stopping: dropped the run(s) handed to its processes")
    finally:
        pool.shutdown(wait=False, cancel_futures=True)
        _end_processes(processes, grace=0.0 if dropped else STOP_GRACE)


def _end_processes(
    processes: Sequence[multiprocessing.process.BaseProcess], *, grace: float
) -> None:
    """Wait ``grace`` s for the processes to exit, then terminate those that have not (they
    ignore Ctrl-C, not SIGTERM)."""
    deadline = time.monotonic() + grace
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
    for process in processes:
        if process.is_alive():
            process.terminate()
            process.join(STOP_GRACE)
        if process.is_alive():
            process.kill()
            process.join(STOP_GRACE)
