"""Zenoh's shared-memory files that no process holds any more, found and removed.

Zenoh copies large messages between processes on one machine through files in
``/dev/shm`` named ``<number>.zenoh``. Zenoh 1.10 leaves one behind for each process that
sent through shared memory: the 1.3-MB segment of its buffers' metadata, which a receiver
keeps locked after the sender has gone, so that neither removes it (zenoh issue #2787;
measured here: one such file after every ``fishswarm run``). Hundreds of runs would fill
``/dev/shm``, which lives in memory (and Docker gives a container 64 MB of it).

A file is released when nothing but the calling process holds it open: a process of
Zenoh's keeps every segment it uses open for as long as it lives, so a file no process
holds is an orphan. The calling process counts as nobody, because the release runs at
its exit, when its sessions are closed.
"""

from __future__ import annotations

import atexit
import logging
import os
import signal
from pathlib import Path

log = logging.getLogger(__name__)

SHARED_MEMORY_FOLDER = Path("/dev/shm")
"""Where Zenoh keeps its shared-memory files on Linux."""

_PROCESSES = Path("/proc")
_registered = False


def files_held_open(processes: Path = _PROCESSES, *, besides: int | None = None) -> set[str]:
    """The paths of the files the processes (those we may look at) hold open, but for the
    process ``besides`` (a process id; None: every process)."""
    skipped = None if besides is None else str(besides)
    held: set[str] = set()
    for process in processes.iterdir():
        if not process.name.isdigit() or process.name == skipped:
            continue
        try:
            descriptors = list((process / "fd").iterdir())
        except OSError:  # gone meanwhile, or another user's (whose files are not ours)
            continue
        for descriptor in descriptors:
            try:
                held.add(os.readlink(descriptor))
            except OSError:
                continue
    return held


def release_shared_memory(
    folder: Path = SHARED_MEMORY_FOLDER, *, processes: Path = _PROCESSES
) -> list[str]:
    """Remove this user's Zenoh shared-memory files that no other process holds open.

    Call it only when every Zenoh session of this process is closed (at exit): a file
    that only this process holds is removed too.

    Args:
        folder: where the files are.
        processes: the ``/proc`` to learn from which files are held (elsewhere than on
            Linux there is none, and nothing is removed).

    Returns:
        The names of the files removed.
    """
    if not folder.is_dir() or not processes.is_dir():
        return []
    user = os.geteuid()
    candidates = []
    for path in folder.glob("*.zenoh"):
        try:
            if path.is_file() and path.stat().st_uid == user:
                candidates.append(path)
        except OSError:
            continue
    if not candidates:
        return []
    # The files are listed before the holders are: a file made after the listing is not
    # looked at, and one made before it is held open by its maker by the time we look.
    held = files_held_open(processes, besides=os.getpid())
    removed = []
    for path in candidates:
        if str(path) in held:
            continue
        try:
            path.unlink()
        except OSError:
            continue
        removed.append(path.name)
    if removed:
        log.debug("released %d shared-memory file(s) Zenoh left: %s", len(removed), removed)
    return removed


def release_shared_memory_at_exit() -> None:
    """Release the orphaned shared-memory files when this process exits (once, however
    often it is asked)."""
    global _registered
    if not _registered:
        atexit.register(_release_at_exit)
        _registered = True


def _release_at_exit() -> None:
    """:func:`release_shared_memory`, deaf to Ctrl-C: the process is ending already, and a
    second Ctrl-C (GNU ``timeout`` sends two, so does an impatient hand) would otherwise
    print a traceback from the middle of the release."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    release_shared_memory()
