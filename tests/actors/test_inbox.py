"""The trio side of a subscription: items pushed from another thread all arrive, in order."""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable, Iterator
from types import SimpleNamespace

import pytest
import trio
import trio.testing

from fishswarm.actors.inbox import Inbox


@pytest.fixture
def frequent_switches() -> Iterator[None]:
    """Threads handed the interpreter every microsecond: a push then lands between any two
    lines of the receiving side."""
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    yield
    sys.setswitchinterval(interval)


def test_everything_pushed_from_another_thread_is_received_in_order(
    frequent_switches: None,
) -> None:
    count = 200_000
    received: list[int] = []

    async def main() -> None:
        inbox: Inbox[int | None] = Inbox()

        def produce() -> None:
            for item in range(count):
                inbox.push(item)
            inbox.push(None)

        producer = threading.Thread(target=produce)
        producer.start()
        try:
            with trio.fail_after(60):
                while True:
                    batch = [await inbox.receive(), *inbox.drain()]
                    received.extend(item for item in batch if item is not None)
                    if batch[-1] is None:
                        break
        finally:
            producer.join()

    trio.run(main)
    assert len(received) == count and received == list(range(count))


def test_a_push_from_the_trio_thread_wakes_the_receiver_without_the_wake_up_socket(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # An inline put (the fish in the launcher's process) pushes on trio's own thread: the
    # receiver is woken directly. A push from any other thread goes through the token.
    async def main() -> tuple[list[str], list[int]]:
        inbox: Inbox[str] = Inbox()
        scheduled: list[int] = []
        token = trio.lowlevel.current_trio_token()
        run_sync_soon = token.run_sync_soon

        def counted(function: Callable[[], object]) -> None:
            scheduled.append(threading.get_ident())
            run_sync_soon(function)

        monkeypatch.setattr(inbox, "_token", SimpleNamespace(run_sync_soon=counted))
        got: list[str] = []
        async with trio.open_nursery() as nursery:

            async def receive(count: int) -> None:
                for _ in range(count):
                    got.append(await inbox.receive())

            nursery.start_soon(receive, 3)
            await trio.testing.wait_all_tasks_blocked()
            inbox.push("inline")
            await trio.testing.wait_all_tasks_blocked()
            assert got == ["inline"] and scheduled == []
            await trio.to_thread.run_sync(inbox.push, "from a thread")
            await trio.testing.wait_all_tasks_blocked()
            inbox.push("inline again")
        return got, scheduled

    got, scheduled = trio.run(main)
    assert got == ["inline", "from a thread", "inline again"]
    assert len(scheduled) == 1 and scheduled[0] != threading.get_ident()


def test_an_item_that_waits_is_received_even_when_the_receivers_time_is_up() -> None:
    # The world collects commands under a deadline: those that came before it are taken,
    # not left in the inbox while their fish are marked lost.
    async def main() -> tuple[list[int], bool]:
        inbox: Inbox[int] = Inbox()
        for item in range(3):
            inbox.push(item)
        got: list[int] = []
        with trio.CancelScope() as scope:
            scope.cancel()
            for _ in range(3):
                got.append(await inbox.receive())
            await inbox.receive()  # nothing waits: the cancellation is seen here
        return got, scope.cancelled_caught

    assert trio.run(main) == ([0, 1, 2], True)
