"""Zenoh's shared-memory files that nobody holds are released: those another process holds,
another user's, and other files stay."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
from multiprocessing.connection import Connection
from pathlib import Path

import pytest

from fishswarm.actors.session import free_loopback_endpoint
from fishswarm.actors.shared_memory import (
    SHARED_MEMORY_FOLDER,
    files_held_open,
    release_shared_memory,
)


def _hold(path: str, connection: Connection) -> None:
    with open(path, "rb"):
        connection.send("holding")
        connection.recv()  # until told to let go


def test_only_files_that_no_other_process_holds_are_released(tmp_path: Path) -> None:
    for name in ("orphan.zenoh", "held-elsewhere.zenoh", "held-here.zenoh", "notes.txt"):
        (tmp_path / name).write_bytes(b"\0" * 64)
    (tmp_path / "folder.zenoh").mkdir()
    ours, theirs = multiprocessing.get_context("spawn").Pipe()
    holder = multiprocessing.get_context("spawn").Process(
        target=_hold, args=(str(tmp_path / "held-elsewhere.zenoh"), theirs)
    )
    holder.start()
    try:
        assert ours.poll(30), "the holding process did not start"
        assert ours.recv() == "holding"
        with open(tmp_path / "held-here.zenoh", "rb"):
            removed = release_shared_memory(tmp_path)
        left = sorted(path.name for path in tmp_path.iterdir())
    finally:
        ours.send("let go")
        holder.join(10)
    assert sorted(removed) == ["held-here.zenoh", "orphan.zenoh"]
    assert left == ["folder.zenoh", "held-elsewhere.zenoh", "notes.txt"]
    # Once its holder has gone, a file is an orphan too.
    assert release_shared_memory(tmp_path) == ["held-elsewhere.zenoh"]


@pytest.mark.skipif(os.geteuid() != 0, reason="giving a file to another user needs root")
def test_another_users_file_is_left_alone(tmp_path: Path) -> None:
    theirs = tmp_path / "theirs.zenoh"
    theirs.write_bytes(b"\0")
    os.chown(theirs, 65534, 65534)
    assert release_shared_memory(tmp_path) == []
    assert theirs.exists()


def test_without_a_proc_folder_nothing_is_released(tmp_path: Path) -> None:
    (tmp_path / "orphan.zenoh").write_bytes(b"\0")
    assert release_shared_memory(tmp_path, processes=tmp_path / "no-proc") == []
    assert (tmp_path / "orphan.zenoh").exists()


def _orphans() -> set[str]:
    """Zenoh's files in /dev/shm that no process holds open."""
    held = files_held_open()
    return {p.name for p in SHARED_MEMORY_FOLDER.glob("*.zenoh") if str(p) not in held}


@pytest.mark.integration
@pytest.mark.skipif(not SHARED_MEMORY_FOLDER.is_dir(), reason="no /dev/shm on this machine")
def test_a_run_leaves_no_shared_memory_behind(tmp_path: Path) -> None:
    """Zenoh alone leaves its metadata segment (1.3 MB) behind after every run."""
    before = _orphans()
    result = subprocess.run(
        [sys.executable, "-m", "fishswarm", "run", "--fish", "25", "--duration", "3",
         "--quiet", "--listen", free_loopback_endpoint(), "--summary", str(tmp_path / "s.json")],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert _orphans() - before == set()


CHILD_THAT_EXITS_SLOWLY = """
import sys, time
from pathlib import Path
from fishswarm.actors import shared_memory

def slow(*args, **kwargs):
    print("releasing", flush=True)
    time.sleep(2.0)
    return set()

shared_memory.files_held_open = slow
Path(sys.argv[1]).write_bytes(b"")  # a file of ours for the release to look at
shared_memory.release_shared_memory_at_exit()
"""


@pytest.mark.skipif(not SHARED_MEMORY_FOLDER.is_dir(), reason="no /dev/shm here")
def test_a_ctrl_c_while_the_release_runs_at_exit_prints_no_traceback() -> None:
    # The release runs as the process exits; a second Ctrl-C then (GNU timeout sends two)
    # printed a KeyboardInterrupt traceback from the atexit handler.
    import signal

    orphan = SHARED_MEMORY_FOLDER / f"fishswarm-test-{os.getpid()}.zenoh"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD_THAT_EXITS_SLOWLY, str(orphan)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline() == "releasing\n"
        child.send_signal(signal.SIGINT)
        _, said = child.communicate(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
        orphan.unlink(missing_ok=True)
    assert child.returncode == 0, said
    assert "Traceback" not in said and "KeyboardInterrupt" not in said, said
