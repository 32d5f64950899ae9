"""Shared test helpers: free loopback ports, running trio code with a bound, reading a
process's messages as they come."""

from __future__ import annotations

import queue
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import TypeVar

import pytest
import trio
import trio.testing

from fishswarm.actors.bus import Bus
from fishswarm.actors.inbox import Inbox, open_subscription
from fishswarm.actors.session import SessionSettings, open_session
from fishswarm.actors.shared_memory import release_shared_memory_at_exit
from fishswarm.actors.zenoh_bus import ZenohBus

T = TypeVar("T")

subscription = open_subscription
"""Subscribe for the block; (key, payload) pairs arrive in the inbox it yields."""


_HANDED_OUT: set[int] = set()
"""Ports :func:`free_port` gave this test session already."""


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now, and that this session was
    not given before: the system may hand the same free port to two probes in a row (a test
    once got one port for a page and its data stream), so a test asking for several gets
    different ones."""
    for _ in range(100):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.bind(("127.0.0.1", 0))
            port: int = probe.getsockname()[1]
        if port not in _HANDED_OUT:
            _HANDED_OUT.add(port)
            return port
    raise RuntimeError("no free port on 127.0.0.1 that this test session has not used")


def pip(*args: str, cwd: Path) -> None:
    """Run this interpreter's pip quietly in ``cwd`` (offline work: building and installing
    wheels from folders here), failing the test with pip's output if it fails."""
    done = subprocess.run(
        [sys.executable, "-m", "pip", "-q", *args],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=cwd,
    )
    assert done.returncode == 0, done.stderr


def install_wheel_of(source: Path, folder: Path, wheel_glob: str) -> Path:
    """Build the wheel of the package in ``source`` (offline, without its dependencies)
    into ``folder``/dist, check its name against ``wheel_glob`` and install it into
    ``folder``/site, as pip would on a machine that has the rest: that site."""
    dist, site = folder / "dist", folder / "site"
    pip("wheel", "--no-deps", "--no-build-isolation", "-w", str(dist), str(source), cwd=folder)
    (wheel,) = dist.glob(wheel_glob)
    pip("install", "--no-deps", "--target", str(site), str(wheel), cwd=folder)
    return site


def wait_for_port(port: int, *, timeout: float = 20.0) -> None:
    """Wait until something accepts TCP connections on 127.0.0.1:``port`` (e.g. a router
    started in another process)."""
    deadline = time.monotonic() + timeout
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            probe.settimeout(0.2)
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return
        if time.monotonic() > deadline:
            raise TimeoutError(f"nothing listens on 127.0.0.1:{port} after {timeout:g} s")
        time.sleep(0.05)


@pytest.fixture
def endpoint() -> str:
    """A fresh loopback endpoint for one test."""
    return f"tcp/127.0.0.1:{free_port()}"


def run_trio(main: Callable[[], Awaitable[T]], *, timeout: float = 60.0) -> T:
    """Run ``main`` under trio, failing the test if it takes longer than ``timeout``."""

    async def bounded() -> T:
        with trio.fail_after(timeout):
            return await main()

    return trio.run(bounded)


async def wait_until_routed(bus: Bus, inbox: Inbox[tuple[str, bytes]], key: str) -> None:
    """Put probes on ``key`` until one comes back through ``inbox``: the subscription has
    reached the router. Then the inbox is emptied of probes."""
    with trio.fail_after(10):
        while True:
            bus.put(key, b"probe")
            with trio.move_on_after(0.05):
                await inbox.receive()
                break
    inbox.drain()


def run_mock(main: Callable[[], Awaitable[T]], *, timeout: float = 3600.0) -> T:
    """Run ``main`` under trio with a MockClock that jumps ahead whenever every task waits:
    simulated seconds cost nothing. ``timeout`` bounds the mock time."""

    async def bounded() -> T:
        with trio.fail_after(timeout):
            return await main()

    return trio.run(bounded, clock=trio.testing.MockClock(autojump_threshold=0))


@asynccontextmanager
async def open_client_bus(endpoint: str, connect_timeout: float = 10.0) -> AsyncIterator[Bus]:
    """A Zenoh client session to the router at ``endpoint``, as a Bus."""
    settings = SessionSettings(mode="client", connect=(endpoint,), connect_timeout=connect_timeout)
    async with open_session(settings) as session:
        yield ZenohBus(session)


class Lines:
    """The stderr lines of a process, read as they come."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.seen: list[str] = []
        self._queue: queue.Queue[str] = queue.Queue()
        assert process.stderr is not None
        self._stream = process.stderr
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self._stream:
            self._queue.put(line.rstrip("\n"))

    def close(self) -> None:
        """Stop reading (the process has ended)."""
        self._reader.join(timeout=10)
        self._stream.close()

    def wait_for(self, pattern: str, *, timeout: float = 60.0) -> re.Match[str]:
        """The first line (from now on) that matches ``pattern``."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise TimeoutError(f"no line matching {pattern!r} in {self.seen}") from None
            self.seen.append(line)
            found = re.search(pattern, line)
            if found:
                return found


def end_processes(processes: list[subprocess.Popen[str]], *, timeout: float = 10.0) -> None:
    """End the processes a test started: terminated, then killed if one lingers past
    ``timeout``; their output collected (pipes a test already read and closed are not)."""
    for process in processes:
        if process.poll() is None:
            process.terminate()
    for process in processes:
        try:
            process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.communicate(timeout=timeout)
        except ValueError:  # its pipes were read and closed by the test
            process.wait(timeout=timeout)


def pytest_configure(config: pytest.Config) -> None:
    """The suite's own runs leave Zenoh's shared-memory files behind as any process does;
    released when the suite's process exits, as every fishswarm command's are."""
    release_shared_memory_at_exit()
