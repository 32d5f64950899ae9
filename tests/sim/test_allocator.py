"""The simulation processes' allocator: freed temporaries are reused, not faulted in again."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import textwrap

import pytest

from fishswarm.sim.allocator import tune_allocator

glibc = pytest.mark.skipif(
    platform.libc_ver()[0] != "glibc", reason="the allocator is set on glibc only"
)
# The defaults measured below are glibc's own: tunables, a preloaded allocator or malloc
# settings from the environment change them.
own_defaults = pytest.mark.skipif(
    any(name.startswith(("MALLOC_", "GLIBC_TUNABLES", "LD_PRELOAD")) for name in os.environ),
    reason="the environment sets the allocator",
)

# A decision's worth of temporaries (a thousand fish's neighbours, 700 kB an array), a
# hundred times over, in a fresh process: its minor page faults.
_FAULTS = textwrap.dedent(
    """
    import resource, sys
    import numpy as np
    from fishswarm.sim.allocator import tune_allocator
    if sys.argv[1] == "tuned":
        assert tune_allocator()
    def decide():
        neighbours = np.ones((1000, 29, 3))
        force = neighbours * 2.0
        return float((force + neighbours).sum())
    decide()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(100):
        decide()
    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
    """
)


def _faults(mode: str) -> int:
    done = subprocess.run(
        [sys.executable, "-c", _FAULTS, mode], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    return int(done.stdout)


@glibc
@own_defaults
def test_a_tuned_process_reuses_its_freed_arrays() -> None:
    # glibc's defaults give each round's arrays back and fault them in again: ~480 faults
    # a round here (2 MB of pages); set, the heap keeps them.
    defaults, tuned = _faults("defaults"), _faults("tuned")
    assert defaults > 100 * 100
    assert tuned < 50


@glibc
def test_setting_the_allocator_twice_is_setting_it_once() -> None:
    assert tune_allocator()
    assert tune_allocator()
