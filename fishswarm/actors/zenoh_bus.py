"""The Bus over a Zenoh session, and the Zenoh-only parts: queryables and queries.

Keys are declared to the session on first put (``declare_keyexpr``): measured with 1000
per-fish keys, 1000 puts through a router take 22 ms with declared keys against 75 ms with
strings. Puts block under congestion rather than drop: a lost command would stall the
lockstep barrier (DESIGN §4).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

import trio
import zenoh

from fishswarm.actors.bus import Declared, OnChange, OnSample
from fishswarm.actors.inbox import Inbox


class ZenohBus:
    """A :class:`~fishswarm.actors.bus.Bus` on an open Zenoh session (which it does not own).

    Args:
        session: the session.
        droppable: puts may be dropped under congestion (best-effort data such as progress).
        inline: run :meth:`subscribe`'s callbacks on the thread that delivers the sample —
            for a put from this process, inside the put — rather than on a Python thread of
            their own (zenoh's ``direct`` callbacks, ``indirect=False``, which zenoh-python
            marks unstable; ``tests/actors/test_zenoh_bus.py`` checks them). For actors that
            share a process and talk mostly among themselves: a sample from another process
            then holds one of Zenoh's network threads while its callback waits for the
            interpreter, which is cheap when such samples are few (observers, operators)
            and not when they carry the tick. Liveliness callbacks keep their threads.
    """

    def __init__(
        self, session: zenoh.Session, *, droppable: bool = False, inline: bool = False
    ) -> None:
        self.session = session
        self._congestion = (
            zenoh.CongestionControl.DROP if droppable else zenoh.CongestionControl.BLOCK
        )
        self._inline = inline
        self._declared: dict[str, zenoh.KeyExpr] = {}

    def put(self, key: str, payload: bytes) -> None:
        key_expr = self._declared.get(key)
        if key_expr is None:
            key_expr = self._declared[key] = self.session.declare_keyexpr(key)
        self.session.put(key_expr, payload, congestion_control=self._congestion)

    def subscribe(self, key_expr: str, on_sample: OnSample) -> Declared:
        if "*" in key_expr:

            def callback(sample: zenoh.Sample) -> None:
                on_sample(str(sample.key_expr), sample.payload.to_bytes())

        else:
            # An exact key need not be read back from every sample (hot per-fish keys).
            def callback(sample: zenoh.Sample) -> None:
                on_sample(key_expr, sample.payload.to_bytes())

        # Run inline, inside a put from trio, a callback may be where Ctrl-C lands; zenoh
        # would swallow the KeyboardInterrupt (and the sample): trio is to deliver it
        # instead. (On Zenoh's own threads, where Ctrl-C never lands, this changes nothing.)
        callback = trio.lowlevel.enable_ki_protection(callback)
        handler = zenoh.handlers.Callback(callback, indirect=not self._inline)
        subscriber: Declared = self.session.declare_subscriber(key_expr, handler)
        return subscriber

    def declare_token(self, key: str) -> Declared:
        token: Declared = self.session.liveliness().declare_token(key)
        return token

    def watch_alive(self, key_expr: str, on_change: OnChange) -> Declared:
        def callback(sample: zenoh.Sample) -> None:
            on_change(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)

        subscriber: Declared = self.session.liveliness().declare_subscriber(
            key_expr, callback, history=True
        )
        return subscriber


@asynccontextmanager
async def open_queryable(
    session: zenoh.Session, key_expr: str, note: Callable[[], bool]
) -> AsyncIterator[Inbox[tuple[zenoh.Query, bool]]]:
    """Serve queries on ``key_expr``; answer each with :func:`reply` from trio.

    Each query comes with ``note()`` as it was when the query arrived (called in Zenoh's
    thread: a flag to read, not a computation), for what may have changed before trio
    takes the query in.
    """
    inbox: Inbox[tuple[zenoh.Query, bool]] = Inbox()
    queryable = session.declare_queryable(key_expr, lambda query: inbox.push((query, note())))
    try:
        yield inbox
    finally:
        queryable.undeclare()


def reply(query: zenoh.Query, payload: bytes) -> None:
    """Answer a query and finalise it."""
    try:
        query.reply(str(query.key_expr), payload)
    finally:
        query.drop()


async def query(
    session: zenoh.Session, key_expr: str, payload: bytes, *, timeout: float = 5.0
) -> list[bytes]:
    """Send a query and collect the payloads of the replies (waits at most ``timeout``)."""

    def run() -> list[bytes]:
        replies = session.get(key_expr, payload=payload, timeout=timeout)
        return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

    return await trio.to_thread.run_sync(run, abandon_on_cancel=True)
