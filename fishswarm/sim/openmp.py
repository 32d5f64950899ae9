"""How long the compiled kernels' OpenMP workers wait, awake, for the next parallel loop,
set for a simulation process before numba loads its OpenMP layer.

numba runs the world's parallel loops (``fishswarm.sim.kernels``) on OpenMP, here GNU's
libgomp. Between two loops a worker spins for ``GOMP_SPINCOUNT`` rounds, then sleeps until
the next loop wakes it. libgomp's default (300 000 rounds, milliseconds here) suits a
program that does nothing but parallel loops, as the batch engine nearly does. In the
world's process the other core is wanted between the loops: by the fish in the launcher's
process, the observer's metrics, the workers. There the workers spun on through the fish's
decision and took their core (1 000 fish in the launcher's process, the machine loaded by
another program: 22 ms a tick instead of 5). Sleeping at once instead (as libgomp does
when it counts more OpenMP threads than cores) makes each loop of each tick wait for a
worker's wake-up: the world's vision of 1 000 fish took 1.6 ms a tick against the batch
engine's 1.25. :data:`SPIN_COUNT` rounds cover the short gaps between a tick's loops and not
the fish's decision (`docs/benchmarks.md`, "OpenMP workers that wait awake").

:func:`tune_openmp` is called once by each simulation process, beside
:func:`~fishswarm.sim.allocator.tune_allocator`, and never at import.
"""

from __future__ import annotations

import os

SPIN_COUNT = 30_000
"""Rounds an idle libgomp worker spins before it sleeps: of 10 000, 30 000 and 100 000
(two interleaved rounds of 1 000 fish over 0, 1 and 2 workers), the steadiest; 100 000
twice made a tick 6–12 ms instead of 5."""

SETTINGS = ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")
"""The environment variables that say how OpenMP's workers wait; one set by the user is
left as it is."""


def tune_openmp() -> bool:
    """Set how long this process's OpenMP workers spin between parallel loops
    (``GOMP_SPINCOUNT``), unless the environment says already how they wait.

    It takes effect only when called before the OpenMP library is loaded (numba loads it
    with the first parallel loop); processes this one starts inherit it.

    Returns:
        Whether it was set: False when ``GOMP_SPINCOUNT`` or ``OMP_WAIT_POLICY`` is set.
    """
    if any(name in os.environ for name in SETTINGS):
        return False
    os.environ["GOMP_SPINCOUNT"] = str(SPIN_COUNT)
    return True


def openmp_waits() -> str:
    """How this process's OpenMP workers wait, as the environment says it, for a
    benchmark's heading (``OpenMP waits: GOMP_SPINCOUNT=30000``)."""
    said = [f"{name}={os.environ[name]}" for name in SETTINGS if name in os.environ]
    return f"OpenMP waits: {', '.join(said) or 'libgomp default'}"
