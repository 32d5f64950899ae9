"""Zenoh sessions: settings, endpoint checks, and opening and closing them from trio.

Sessions are opened and closed in worker threads and always closed, also on cancellation,
because a session left open at interpreter exit hangs the process (DESIGN §4). Every
session has explicit endpoints and multicast scouting off.
"""

from __future__ import annotations

import json
import re
import socket
import threading
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any

import trio
import zenoh

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
SHARED_MEMORY_POOL = "transport/shared_memory/transport_optimization/pool_size"
"""Where Zenoh's configuration sizes the pool it copies messages over 3 KiB into, for
sessions on the same machine (on by default in Zenoh 1.10, which fishswarm uses)."""


class ConnectError(RuntimeError):
    """A session could not be opened (nothing listening, bad endpoint, port taken)."""


@dataclass(frozen=True)
class SessionSettings:
    """How to open a Zenoh session.

    Attributes:
        mode: ``router`` (the launcher: routes for everybody), ``peer`` or ``client``.
        listen: endpoints to listen on, e.g. ``tcp/127.0.0.1:7447``.
        connect: endpoints to connect to.
        connect_timeout: how long a client waits for its router, s (< 0: forever).
        lease: link lease, s: how soon a frozen peer is noticed.
        extra: further settings, by their path in Zenoh's configuration.
        shared_memory_pool_bytes: size of the shared memory Zenoh copies large messages into
            for processes on the same machine (None: Zenoh's default, 16 MiB). A message
            that finds the pool full goes through the socket instead, several times slower.
        config_file: a Zenoh configuration file (JSON5) to start from, e.g. a robot's with
            its transport and security settings; the settings above are applied over it.
    """

    mode: str = "client"
    listen: Sequence[str] = ()
    connect: Sequence[str] = ()
    connect_timeout: float = 10.0
    lease: float = 3.0
    extra: dict[str, Any] = field(default_factory=dict)
    shared_memory_pool_bytes: int | None = None
    config_file: str | None = None

    def __post_init__(self) -> None:
        if self.mode not in ("router", "peer", "client"):
            raise ValueError(f"session mode must be router, peer or client, got {self.mode!r}")
        if self.shared_memory_pool_bytes is not None and self.shared_memory_pool_bytes <= 0:
            raise ValueError(
                f"the shared memory pool must be a positive number of bytes, "
                f"got {self.shared_memory_pool_bytes}"
            )
        for endpoint in (*self.listen, *self.connect):
            check_endpoint(endpoint)

    def to_config(self) -> zenoh.Config:
        """The Zenoh configuration: explicit endpoints, multicast scouting off.

        Raises:
            ConnectError: the configuration file is missing or not valid JSON5.
        """
        config = zenoh.Config()
        if self.config_file is not None:
            try:
                config = zenoh.Config.from_file(self.config_file)
            except zenoh.ZError as error:
                reason = str(error).split(" at /")[0].strip()
                raise ConnectError(
                    f"Zenoh configuration {self.config_file} cannot be read: {reason}"
                ) from None
        config.insert_json5("mode", json.dumps(self.mode))
        config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        timeout_ms = -1 if self.connect_timeout < 0 else int(self.connect_timeout * 1000)
        config.insert_json5("connect/timeout_ms", json.dumps(timeout_ms))
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("scouting/gossip/enabled", "false")
        # Peers and routers wait this long in open() for scouting to find others (500 ms by
        # default); with scouting off there is nothing to wait for (a run started 0.5 s later).
        config.insert_json5("scouting/delay", "0")
        config.insert_json5("transport/link/tx/lease", json.dumps(int(self.lease * 1000)))
        if self.shared_memory_pool_bytes is not None:
            config.insert_json5(SHARED_MEMORY_POOL, json.dumps(self.shared_memory_pool_bytes))
        for key, value in self.extra.items():
            config.insert_json5(key, json.dumps(value))
        return config


def check_endpoint(endpoint: str) -> str:
    """Check a Zenoh endpoint such as ``tcp/127.0.0.1:7447``.

    Raises:
        ValueError: with what is wrong and an example of a good one.
    """
    protocol, _, address = endpoint.partition("/")
    host, _, port = address.rpartition(":")
    if protocol not in ("tcp", "udp", "quic", "tls", "ws", "unixsock-stream") or (
        protocol != "unixsock-stream"
        and (not host or not port.isdigit() or not 1 <= int(port) <= 65535)
    ):
        raise ValueError(
            f"endpoint {endpoint!r} is not valid: write PROTOCOL/HOST:PORT with a port from "
            "1 to 65535, e.g. tcp/127.0.0.1:7447 or tcp/0.0.0.0:7447"
        )
    return endpoint


def free_loopback_endpoint() -> str:
    """``tcp/127.0.0.1:PORT`` with a port nothing listens on right now (for runs that must
    not collide, e.g. experiments run side by side)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


def _open_failure_hint(settings: SessionSettings, error: str) -> str:
    """What most likely stopped a session from opening, and what to do about it."""
    if "os error 99" in error or "Cannot assign requested address" in error:
        # Zenoh passes the operating system's EADDRNOTAVAIL through: the host named
        # in a listen endpoint is not one of this machine's addresses.
        return (
            "this machine has no such address: listen on one of its own addresses "
            "(see 'ip -brief address'), or on 0.0.0.0 for all of them"
        )
    if any(endpoint.startswith("tls/") for endpoint in settings.connect):
        # A TLS handshake the router refuses looks like a router that is not there.
        return (
            "is a fishswarm router listening there, and does it accept this certificate? "
            "--secure must name a folder of the router's own authority (made by the same "
            "'fishswarm secure init'), and the router's certificate must name the host in "
            "--connect (secure init --host HOST)"
        )
    if settings.connect:
        return (
            "is a fishswarm run or router listening there? (a secured swarm's router "
            "listens on tls/…: connect to tls/HOST:PORT with --secure DIR)"
        )
    return "is another program using that port?"


@asynccontextmanager
async def open_session(settings: SessionSettings) -> AsyncIterator[zenoh.Session]:
    """Open a Zenoh session and close it on exit, also when cancelled.

    Raises:
        ConnectError: the session could not be opened, with the reason.
    """
    config = settings.to_config()
    try:
        session = await _open_abandonably(config)
    except zenoh.ZError as error:
        where = ", ".join([*settings.listen, *settings.connect]) or "(no endpoint)"
        raise ConnectError(
            f"cannot open a {settings.mode} session on {where}: "
            f"{_open_failure_hint(settings, str(error))} ({_without_source(str(error))})"
        ) from None
    try:
        yield session
    finally:
        with trio.CancelScope(shield=True):
            await trio.to_thread.run_sync(session.close)


async def _open_abandonably(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open`` in a worker thread that a cancellation (Ctrl-C, SIGTERM) does not wait
    for: a client waiting for its router waits up to its connect timeout, forever for a
    robot's service. A session that opens after all is closed, by the thread or (if it
    opened in the instant of the cancellation) here."""
    lock = threading.Lock()
    abandoned = False
    opened: list[zenoh.Session] = []

    def open_unless_abandoned() -> zenoh.Session:
        session = zenoh.open(config)
        with lock:
            if abandoned:
                session.close()
            else:
                opened.append(session)
        return session

    try:
        return await trio.to_thread.run_sync(open_unless_abandoned, abandon_on_cancel=True)
    except BaseException:  # cancelled, or Ctrl-C delivered into this very task
        with lock:
            abandoned = True
        for session in opened:  # opened, but its result came too late to be taken
            session.close()  # blocks trio's thread for a moment: only ever at a shutdown
        raise


def reaches_router(session: zenoh.Session) -> bool:
    """Whether a client session is connected to a router now."""
    return bool(list(session.info.routers_zid()))


def _without_source(reason: str) -> str:
    """Zenoh's reason without the place in Zenoh's Rust source it was raised at (``… at
    /root/.cargo/…/orchestrator.rs:388.``), which says nothing to the user."""
    return re.sub(r"\s+at /\S+?\.rs:\d+\.?", "", reason).strip()
