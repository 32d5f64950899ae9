"""The C allocator of a simulation process, set for numpy's large temporaries.

Each tick allocates and frees arrays of hundreds of kilobytes to megabytes (a thousand fish's
neighbours, their forces, the vision's rows). With glibc's defaults a freed block of that
size goes back to the operating system — unmapped, or trimmed off the top of the heap — and
the next tick's allocation of the same size touches fresh pages again: hundreds of page
faults a decision. Measured on the development machine, one decision of 1 000 fish in a
fresh process (neighbours 1 000 × 29): 2.0 ms with the defaults, 0.8 ms with the allocator
set as below; the fault-free run equals what a long-warmed process shows. Nothing computed
changes, only where the memory comes from.

:func:`tune_allocator` is called once by each simulation process — the ``fishswarm``
command (except on a robot), the fish workers, the study's sweep processes, the benchmarks —
and never at import.
"""

from __future__ import annotations

import ctypes
import sys

MMAP_THRESHOLD = 32 << 20
"""Blocks from this size (32 MiB, the ceiling glibc's own sliding threshold stops at on 64
bits) get their own mapping, given back when freed; smaller ones come from a heap."""
TRIM_THRESHOLD = 128 << 20
"""Free memory at the top of a heap is given back once it exceeds this (128 MiB), so one
tick's temporaries serve the next. Each thread that allocates may have a heap of its own,
each keeping up to this much; peaks do not grow (a 10 000-fish run over two workers: the
launcher's peak 453 → 461 MB, a worker's 192 → 195 MB), but a process may hold more between
them than with glibc's defaults."""

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
"""mallopt's parameter numbers (glibc's malloc.h)."""


def tune_allocator() -> bool:
    """Set this process's C allocator to keep freed blocks for reuse (glibc only).

    Returns:
        Whether it was set: False where the C library is not glibc (macOS, musl), whose
        allocators are left as they are.
    """
    if not sys.platform.startswith("linux"):
        return False
    libc = ctypes.CDLL(None)
    if not hasattr(libc, "gnu_get_libc_version"):
        return False
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(
        mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )
