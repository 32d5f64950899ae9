"""The trio side of a subscription: items pushed from another thread all arrive, in order."""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator

import pytest
import trio

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
