"""Shared test helpers: free loopback ports and running trio code with a bound."""

from __future__ import annotations

import socket
from collections.abc import Awaitable, Callable
from typing import TypeVar

import pytest
import trio

T = TypeVar("T")


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


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
