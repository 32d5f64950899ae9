"""The trio side of every subscription: items pushed from any thread, received in trio.

Zenoh calls subscriber callbacks on its own threads, or, for an inline subscriber
(:class:`~fishswarm.actors.zenoh_bus.ZenohBus` ``inline``), inside a put from this process,
on trio's own thread. A callback only appends to a deque and wakes the receiver: from
another thread by at most one pending wake-up through the trio token (DESIGN §4: ~0.5 M
msgs/s into trio; one ``run_sync_soon`` per message is 10–70× slower), on trio's own
thread directly (no trip through trio's wake-up socket: the fish in the launcher's process
pass four or five messages a tick this way). The trio side waits on an Event.
"""

from __future__ import annotations

import contextlib
import threading
from collections import deque
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Generic, TypeVar

import trio

from fishswarm.actors.bus import Bus, open_subscriber

T = TypeVar("T")


class Inbox(Generic[T]):
    """Items pushed from Zenoh threads, received in trio, in arrival order.

    ``push`` may be called from any thread; ``receive`` only from the trio thread that made
    the inbox, by one task at a time.
    """

    def __init__(self) -> None:
        self._items: deque[T] = deque()
        self._token = trio.lowlevel.current_trio_token()
        self._trio_thread = threading.get_ident()
        self._wake_pending = False
        self._event = trio.Event()

    def push(self, item: T) -> None:
        """Append an item and wake the receiver (thread-safe, never blocks)."""
        self._items.append(item)
        if threading.get_ident() == self._trio_thread:
            # An inline put by a task of this run: wake the receiver directly, without the
            # trip through trio's wake-up socket that a push from another thread needs.
            self._event.set()
            return
        if not self._wake_pending:
            self._wake_pending = True
            # After the run has finished nobody receives: the item just stays.
            with contextlib.suppress(trio.RunFinishedError):
                self._token.run_sync_soon(self._wake)

    def _wake(self) -> None:
        self._wake_pending = False
        self._event.set()

    def pending(self) -> int:
        """How many items wait to be received."""
        return len(self._items)

    def receive_nowait(self) -> T:
        """The next item if one is waiting.

        Raises:
            trio.WouldBlock: nothing is waiting.
        """
        if not self._items:
            raise trio.WouldBlock
        return self._items.popleft()

    def drain(self) -> list[T]:
        """Every item waiting now, in order (none: an empty list)."""
        # One item at a time: a push from another thread between copying the deque and
        # clearing it would be lost; popleft and append are each atomic.
        items: list[T] = []
        try:
            while True:
                items.append(self._items.popleft())
        except IndexError:
            return items

    async def receive(self) -> T:
        """Wait for and return the next item (one that waits already is returned even when
        the receiver's time is up: the world takes every command that came before its
        deadline)."""
        while not self._items:
            self._event = trio.Event()
            await self._event.wait()
        return self._items.popleft()

    def __aiter__(self) -> Inbox[T]:
        return self

    async def __anext__(self) -> T:
        return await self.receive()


@asynccontextmanager
async def open_subscription(bus: Bus, key_expr: str) -> AsyncIterator[Inbox[tuple[str, bytes]]]:
    """Subscribe to ``key_expr`` for the duration of the block; (key, payload) pairs arrive
    in the inbox it yields."""
    inbox: Inbox[tuple[str, bytes]] = Inbox()
    async with open_subscriber(bus, key_expr, lambda key, payload: inbox.push((key, payload))):
        yield inbox
