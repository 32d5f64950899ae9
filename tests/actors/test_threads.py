"""Work handed from an event loop to a thread (fishswarm.actors.threads)."""

from __future__ import annotations

import threading
from typing import Any

import pytest
import trio
import trio.testing

from fishswarm.actors.threads import in_thread_at_once


@pytest.fixture
def order(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """What happened, in order: "thread" whenever a thread is started, of trio's cache or
    of its own (tests add their own entries)."""
    happened: list[str] = []
    start_thread_soon = trio.lowlevel.start_thread_soon
    start = threading.Thread.start

    inside: list[bool] = []  # trio's cache may start a threading.Thread itself: one thread

    def recorded_soon(*arguments: Any, **options: Any) -> None:
        happened.append("thread")
        inside.append(True)
        try:
            start_thread_soon(*arguments, **options)
        finally:
            inside.pop()

    def recorded_start(thread: threading.Thread) -> None:
        if not inside:
            happened.append("thread")
        start(thread)

    monkeypatch.setattr(trio.lowlevel, "start_thread_soon", recorded_soon)
    monkeypatch.setattr(threading.Thread, "start", recorded_start)
    return happened


@pytest.mark.parametrize("passing", [False, True])
def test_a_thread_started_at_once_starts_before_a_task_scheduled_with_it_runs(
    order: list[str], passing: bool
) -> None:
    # In the launcher's process a task scheduled with the observer is the fish, about to
    # decide: trio.to_thread.run_sync passes a schedule point first, and the fish went first.
    async def other() -> None:
        order.append("other")

    async def main() -> int:
        async with trio.open_nursery() as nursery:
            nursery.start_soon(other)
            return await in_thread_at_once(lambda: 7, name="test", passing=passing)

    assert trio.run(main) == 7
    assert order == ["thread", "other"]


@pytest.mark.parametrize("passing", [False, True])
def test_a_thread_started_at_once_is_waited_for_when_cancelled_and_passes_on_errors(
    passing: bool,
) -> None:
    release = threading.Event()
    started: list[str] = []

    def measure() -> float:
        started.append("measure")
        release.wait(10.0)  # bounded: the test releases it once the caller is cancelled
        return 1.5

    def fail() -> float:
        raise ValueError("no distances for these positions")

    async def main() -> tuple[bool, float | None, bool]:
        # Cancelled before it starts: no thread, trio.Cancelled.
        with trio.CancelScope() as before:
            before.cancel()
            await in_thread_at_once(measure, name="test", passing=passing)
        value = None
        async with trio.open_nursery() as nursery:
            with trio.CancelScope() as during:

                async def cancel_then_release() -> None:
                    await trio.testing.wait_all_tasks_blocked()
                    during.cancel()
                    await trio.testing.wait_all_tasks_blocked()
                    release.set()

                nursery.start_soon(cancel_then_release)
                # cancelled while it waits
                value = await in_thread_at_once(measure, name="test", passing=passing)
        with pytest.raises(ValueError, match="no distances"):
            await in_thread_at_once(fail, name="test", passing=passing)
        return before.cancelled_caught, value, during.cancelled_caught

    assert trio.run(main) == (True, 1.5, False)
    assert started == ["measure"]


def test_a_passing_thread_ends_with_its_work_and_a_cached_one_is_kept() -> None:
    """A passing thread is gone once its work is done (and the OpenMP team it may lead
    with it); trio keeps its own threads for the next work."""

    def where() -> threading.Thread:
        return threading.current_thread()

    async def main() -> list[threading.Thread]:
        return [
            await in_thread_at_once(where, name="fishswarm test passing", passing=True),
            await in_thread_at_once(where, name="fishswarm test cached"),
            await in_thread_at_once(where, name="fishswarm test cached again"),
        ]

    passing, cached, again = trio.run(main)
    passing.join(timeout=10.0)
    assert not passing.is_alive() and passing.name == "fishswarm test passing"
    assert passing is not threading.main_thread() and passing is not cached
    assert cached.is_alive() and again is cached  # trio's cache gives it back
