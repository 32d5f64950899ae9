"""Fish worker processes: many fish actors per process, as trio tasks on one session.

Workers are started with the ``spawn`` context (never fork after Zenoh is in use). A worker
ignores Ctrl-C — its launcher decides when it stops — and stops when its launcher says so or
disappears (the pipe closes), then reports its fish's counters through the pipe.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import signal
import sys
from dataclasses import dataclass, field
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection
from typing import Any

import trio

from fishswarm.actors.fish import (
    PERCEPTION_TIMEOUT,
    Fish,
    FishSettings,
    FishStatistics,
    fish_span,
)
from fishswarm.actors.logs import DEFAULT_PREFIX, configure_logging
from fishswarm.actors.session import SessionSettings, open_session
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.behaviors.core import BehaviorError, FishParams
from fishswarm.protocols.keys import KeySpace
from fishswarm.sim.allocator import tune_allocator
from fishswarm.sim.decision_kernels import prepare


@dataclass(frozen=True)
class WorkerSpec:
    """What one worker process runs.

    Attributes:
        index: the worker's number.
        fish_ids: the fish it hosts.
        params: what its fish do.
        swarm: swarm name.
        connect: the router's endpoint.
        perception_timeout: the fish's safety watchdog, s.
        log_level: logging level name.
        log_prefix: what its log lines start with: the launching command's own prefix.
        schooled: serve the fish as one school (batched keys) rather than each on its own
            keys as a robot would.
        session_extra: further Zenoh settings of its session (a secured run's TLS).
    """

    index: int
    fish_ids: tuple[int, ...]
    params: FishParams
    swarm: str
    connect: str
    perception_timeout: float = PERCEPTION_TIMEOUT
    log_level: str = "WARNING"
    log_prefix: str = DEFAULT_PREFIX
    schooled: bool = True
    session_extra: dict[str, Any] = field(default_factory=dict)

    @property
    def school(self) -> str | None:
        """The school its fish are served under (one message per tick each way), or None
        when each fish has its own keys."""
        return school_of(self.index) if self.schooled else None

    def fish(self) -> Fish:
        """The fish actor that serves this spec's fish (load the compiled decisions its
        parameters name with :func:`~fishswarm.sim.decision_kernels.prepare` first)."""
        return Fish(
            FishSettings(
                self.fish_ids,
                self.params,
                KeySpace(self.swarm),
                perception_timeout=self.perception_timeout,
                school=self.school,
            )
        )

    def describe(self) -> str:
        """``worker 1 (fish 13–24)``."""
        return f"worker {self.index} (fish {fish_span(self.fish_ids)})"


def school_of(index: int) -> str:
    """The school name of the fish of worker ``index`` (``worker-0`` also for fish in the
    launcher's own process)."""
    return f"worker-{index}"


def split_fish(ids: list[int], procs: int) -> list[tuple[int, ...]]:
    """Split fish ids into ``procs`` contiguous, nearly equal groups (no empty group)."""
    procs = max(1, min(procs, len(ids)))
    size, extra = divmod(len(ids), procs)
    groups, start = [], 0
    for n in range(procs):
        end = start + size + (1 if n < extra else 0)
        groups.append(tuple(ids[start:end]))
        start = end
    return groups


log = logging.getLogger(__name__)

STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}
"""What stops a run: the launcher's to handle, never a worker's."""


def worker_main(spec: WorkerSpec, connection: Connection) -> None:
    """Entry point of a worker process: Ctrl-C and SIGTERM are the launcher's to act on
    (sent to the whole process group, they reach the worker too), which stops the worker
    through its pipe and collects its counters."""
    for number in STOP_SIGNALS:
        signal.signal(number, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    tune_allocator()
    configure_logging(prefix=spec.log_prefix, level=spec.log_level)
    prepare(spec.params)
    try:
        statistics = trio.run(_serve, spec, connection)
    except Exception as error:
        # Said to the launcher, which names it with the fish it loses; a traceback only for
        # what is not a behaviour's own error (that one says all there is to say).
        error = sole_error(error)
        with contextlib.suppress(BrokenPipeError, OSError):
            connection.send(("failed", f"{type(error).__name__}: {error}"))
        if not isinstance(error, BehaviorError):
            log.error("%s failed", spec.describe(), exc_info=error)
        sys.exit(1)
    with contextlib.suppress(BrokenPipeError, OSError):
        connection.send(("statistics", statistics))


def sole_error(error: Exception) -> Exception:
    """The one error inside nested groups of one (trio's nurseries wrap what fails in
    them), to say it as it was raised; a group of several as it is."""
    while isinstance(error, ExceptionGroup) and len(error.exceptions) == 1:
        error = error.exceptions[0]
    return error


async def _serve(spec: WorkerSpec, connection: Connection) -> FishStatistics:
    fish = spec.fish()
    settings = SessionSettings(mode="client", connect=[spec.connect], extra=spec.session_extra)
    async with open_session(settings) as session, trio.open_nursery() as nursery:
        await nursery.start(fish.run, ZenohBus(session))
        connection.send(("ready", spec.index))
        await trio.to_thread.run_sync(_wait_for_stop, connection, abandon_on_cancel=True)
        nursery.cancel_scope.cancel()
    return fish.statistics()


def _wait_for_stop(connection: Connection) -> None:
    # Readable means "stop" was sent or the launcher is gone (end of file): both end the worker.
    connection.poll(None)


@dataclass
class Worker:
    """A running worker process, as its launcher sees it."""

    spec: WorkerSpec
    process: multiprocessing.process.BaseProcess
    connection: Connection
    statistics: FishStatistics | None = None
    stopping: bool = False
    lost: bool = False
    """Seen to have ended on its own while the run went on."""
    killed: bool = False
    """Killed by :func:`stop_worker`, as it did not stop when asked."""
    failure: str | None = None
    """What made it fail, as it said before it exited (None: it said nothing)."""

    def exit_description(self) -> str:
        """How the process ended, in words: what made it fail, when it said so."""
        code = self.process.exitcode
        if code is None:
            return "is still running"
        if self.failure is None and not self.connection.closed:
            self.failure = _last_words(self.connection)
        if self.failure is not None:
            return f"failed: {self.failure}"
        if code < 0:
            try:
                return f"was killed by {signal.Signals(-code).name}"
            except ValueError:
                return f"was killed by signal {-code}"
        return f"exited with code {code}"


def _last_words(connection: Connection) -> str | None:
    """What a worker that ended said of its failure, if it did, from what is left in its
    pipe."""
    try:
        while connection.poll(0):
            kind, payload = connection.recv()
            if kind == "failed":
                return str(payload)
    except (EOFError, OSError):
        pass
    return None


def start_worker(spec: WorkerSpec) -> Worker:
    """Start a worker process (spawn context)."""
    context = multiprocessing.get_context("spawn")
    ours, theirs = context.Pipe(duplex=True)
    process = context.Process(
        target=worker_main, args=(spec, theirs), name=f"fishswarm-worker-{spec.index}", daemon=True
    )
    # Started with Ctrl-C and SIGTERM held back (the mask is inherited), so that one sent to
    # the process group while the new interpreter imports fishswarm does not end it with a
    # traceback; worker_main ignores them and lets them through.
    # The resource tracker, started with the first worker otherwise, unblocks both signals
    # as it starts: started now, before they are held back.
    resource_tracker.ensure_running()
    held = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        process.start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    theirs.close()
    return Worker(spec, process, ours)


def stop_worker(worker: Worker, *, timeout: float = 1.5) -> None:
    """Ask a worker to stop, collect its counters, and make sure the process is gone.

    Blocking; call it from a thread. Waits at most about ``timeout`` before killing.
    """
    worker.stopping = True
    # A worker that failed is gone, its pipe closed at its end: its last words may be there.
    with contextlib.suppress(BrokenPipeError, OSError):
        worker.connection.send(("stop", None))
    try:
        if worker.connection.poll(timeout):
            kind, payload = worker.connection.recv()
            while kind not in ("statistics", "failed") and worker.connection.poll(timeout):
                kind, payload = worker.connection.recv()
            if kind == "statistics":
                worker.statistics = payload
            elif kind == "failed" and worker.failure is None:
                worker.failure = str(payload)
    except (BrokenPipeError, EOFError, OSError):
        pass
    worker.process.join(timeout)
    if worker.process.is_alive():
        worker.killed = True
        worker.process.kill()
        worker.process.join(1.0)
    worker.connection.close()
