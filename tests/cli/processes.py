"""fishswarm commands started as processes for a test, and ended at its end."""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Callable, Iterator

from tests.conftest import end_processes, free_port, wait_for_port

FISHSWARM = [sys.executable, "-m", "fishswarm"]


@contextlib.contextmanager
def started_commands(*, piped: bool = True) -> Iterator[Callable[..., subprocess.Popen[str]]]:
    """A function that starts ``fishswarm ARGS…`` (output piped, or dropped when not
    ``piped``: a process nobody reads must not fill its pipe); every process it started is
    ended at the block's exit (terminated, killed if it lingers)."""
    processes: list[subprocess.Popen[str]] = []
    output = subprocess.PIPE if piped else subprocess.DEVNULL

    def start(*args: str) -> subprocess.Popen[str]:
        process = subprocess.Popen([*FISHSWARM, *args], stdout=output, stderr=output, text=True)
        processes.append(process)
        return process

    try:
        yield start
    finally:
        end_processes(processes)


@contextlib.contextmanager
def routed_commands(
    *, piped: bool = True
) -> Iterator[tuple[str, Callable[..., subprocess.Popen[str]]]]:
    """A router on a free port of 127.0.0.1, up: its endpoint, and :func:`started_commands`'s
    function to start more beside it."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    with started_commands(piped=piped) as start:
        start("router", "--listen", endpoint)
        wait_for_port(port)
        yield endpoint, start
