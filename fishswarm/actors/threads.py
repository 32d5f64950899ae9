"""Work an actor hands from its event loop to a thread: started at once, and waited for
once started, even when the actor is cancelled."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import TypeVar

import outcome
import trio

T = TypeVar("T")


async def in_thread_at_once(function: Callable[[], T], *, name: str, passing: bool = False) -> T:
    """What ``function()`` returns, run in a thread started at once; once started, waited
    for even when cancelled (as :func:`trio.to_thread.run_sync` waits for its thread).

    ``trio.to_thread.run_sync`` passes a schedule point before it starts its thread. In the
    launcher's process the fish, woken in the same step of the world, would then decide
    first, and a large school's metrics would run beside the world's next physics, whose
    compiled kernels wait for the core the metrics hold (1 000 fish: the whole tick
    1.0–1.7 ms longer than with the metrics left out, `docs/benchmarks.md`).

    Args:
        function: the work.
        name: the thread's name (``ps -L``, py-spy).
        passing: run it in a thread of its own that ends with it, not in one of trio's
            cache. For the world's compiled parallel loops: the thread that runs one leads
            an OpenMP team of its own, which lives as long as the thread. Kept in trio's
            cache (and reused for the observer's metrics), that team would stay beside the
            event loop's, and with more OpenMP threads than cores libgomp's workers sleep
            at once after each loop instead of waiting for the next: every loop of every
            tick would then wait for a worker to wake (at 1 000 fish the world's vision
            took 1.5–1.6 ms a tick against 1.2–1.3, `docs/benchmarks.md`).

    Raises:
        trio.Cancelled: the caller was cancelled before the thread started.
    """
    await trio.lowlevel.checkpoint_if_cancelled()  # a cancelled actor starts no more work
    token = trio.lowlevel.current_trio_token()
    done = trio.Event()
    result: list[outcome.Outcome[T]] = []

    def deliver(value: outcome.Outcome[T]) -> None:
        result.append(value)
        # A Ctrl-C between the start and the wait can end the run first; then nobody waits.
        with contextlib.suppress(trio.RunFinishedError):
            token.run_sync_soon(done.set)

    if passing:
        threading.Thread(
            target=lambda: deliver(outcome.capture(function)), name=name, daemon=True
        ).start()
    else:
        trio.lowlevel.start_thread_soon(function, deliver, name=name)
    with trio.CancelScope(shield=True):
        await done.wait()
    return result[0].unwrap()
