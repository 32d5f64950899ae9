"""The Bus: what an actor needs of the network — put, subscribe, liveliness — and an
in-memory Bus for actors that share a process.

Actors talk through a :class:`Bus`, not a Zenoh session: :class:`~fishswarm.actors.zenoh_bus.
ZenohBus` between processes and machines, :class:`MemoryBus` inside one process — on a robot
the driver and the fish actor share a process, so the fins' safety never depends on Wi-Fi —
and in tests, where trio's MockClock then drives time without sleeping.

Callbacks (``on_sample``, ``on_change``) may run on any thread and must only hand over,
e.g. :meth:`~fishswarm.actors.inbox.Inbox.push`; they must not call the Bus.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import dataclass, field
from typing import Protocol

OnSample = Callable[[str, bytes], None]
"""Called with (key, payload) for each sample."""

OnChange = Callable[[str, bool], None]
"""Called with (token key, alive) when a liveliness token appears or goes."""


class Declared(Protocol):
    """Something declared on a Bus (a subscriber, a token) until undeclared."""

    def undeclare(self) -> None:
        """Withdraw it."""
        ...


class Bus(Protocol):
    """Publish/subscribe with liveliness, as a fishswarm actor uses it."""

    def put(self, key: str, payload: bytes) -> None:
        """Publish ``payload`` on ``key`` (reliably: simulation traffic is never dropped)."""
        ...

    def subscribe(self, key_expr: str, on_sample: OnSample) -> Declared:
        """Call ``on_sample`` for every sample on keys matching ``key_expr``."""
        ...

    def declare_token(self, key: str) -> Declared:
        """Hold a liveliness token: ``I am alive``."""
        ...

    def watch_alive(self, key_expr: str, on_change: OnChange) -> Declared:
        """Call ``on_change`` for the tokens matching ``key_expr``: the current ones first,
        then every change."""
        ...


def key_matches(key_expr: str, key: str) -> bool:
    """Whether ``key`` matches ``key_expr`` as Zenoh matches them: ``*`` stands for one
    chunk, ``**`` for any number of chunks (also none)."""
    if "*" not in key_expr:
        return key_expr == key
    return _match(key_expr.split("/"), key.split("/"))


def _match(pattern: list[str], chunks: list[str]) -> bool:
    if not pattern:
        return not chunks
    head, rest = pattern[0], pattern[1:]
    if head == "**":
        return any(_match(rest, chunks[skip:]) for skip in range(len(chunks) + 1))
    if not chunks:
        return False
    return (head == "*" or head == chunks[0]) and _match(rest, chunks[1:])


@dataclass(eq=False)
class _Declared:
    undeclare_action: Callable[[], None]
    done: bool = False

    def undeclare(self) -> None:
        if not self.done:
            self.done = True
            self.undeclare_action()


@dataclass(eq=False)
class MemoryBus:
    """A Bus inside one process: a put reaches every matching subscriber at once, in order.

    Attributes:
        puts: how many samples were put.
    """

    puts: int = 0
    _subscribers: list[tuple[str, OnSample]] = field(default_factory=list)
    _tokens: dict[str, int] = field(default_factory=dict)
    _watchers: list[tuple[str, OnChange]] = field(default_factory=list)

    def put(self, key: str, payload: bytes) -> None:
        self.puts += 1
        for key_expr, on_sample in list(self._subscribers):
            if key_matches(key_expr, key):
                on_sample(key, payload)

    def subscribe(self, key_expr: str, on_sample: OnSample) -> Declared:
        entry = (key_expr, on_sample)
        self._subscribers.append(entry)
        return _Declared(lambda: self._subscribers.remove(entry))

    def declare_token(self, key: str) -> Declared:
        self._tokens[key] = self._tokens.get(key, 0) + 1
        if self._tokens[key] == 1:
            self._announce(key, True)

        def withdraw() -> None:
            self._tokens[key] -= 1
            if not self._tokens[key]:
                del self._tokens[key]
                self._announce(key, False)

        return _Declared(withdraw)

    def watch_alive(self, key_expr: str, on_change: OnChange) -> Declared:
        entry = (key_expr, on_change)
        self._watchers.append(entry)
        for key in sorted(self._tokens):
            if key_matches(key_expr, key):
                on_change(key, True)
        return _Declared(lambda: self._watchers.remove(entry))

    def _announce(self, key: str, alive: bool) -> None:
        for key_expr, on_change in list(self._watchers):
            if key_matches(key_expr, key):
                on_change(key, alive)


@asynccontextmanager
async def held(declared: Declared) -> AsyncIterator[None]:
    """Keep something declared on a Bus for the duration of the block."""
    try:
        yield
    finally:
        declared.undeclare()


def open_subscriber(
    bus: Bus, key_expr: str, on_sample: OnSample
) -> AbstractAsyncContextManager[None]:
    """Subscribe for the duration of the block."""
    return held(bus.subscribe(key_expr, on_sample))


def open_token(bus: Bus, key: str) -> AbstractAsyncContextManager[None]:
    """Hold a liveliness token for the duration of the block."""
    return held(bus.declare_token(key))


def open_alive_events(
    bus: Bus, key_expr: str, on_change: OnChange
) -> AbstractAsyncContextManager[None]:
    """Watch liveliness tokens for the duration of the block (current ones first)."""
    return held(bus.watch_alive(key_expr, on_change))
