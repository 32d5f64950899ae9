"""Benchmark: the batch engine's tick at 25, 1 000 and 10 000 fish, numpy reference against
the compiled kernels (fishswarm.sim.kernels), in one run.

1 Hz control, 100 Euler substeps a period, full vision (range, blind spot, occlusion); beyond
25 fish the tank grows so that each fish has about 25 others within visual range
(``Scenario.crowded``). Each size is warmed up once (the kernels compile or load from their
cache), then timed over a run (``bench_swarm.batch_tick``); the median time of three
one-tick runs (placing the fish, the first look) is subtracted and reported as start-up.

Usage:
    python bench/bench_engine.py
    python bench/bench_engine.py --fish 1000 10000

Results and conditions are kept in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import platform

from bench_swarm import batch_tick
from options import add_sizes

from fishswarm.sim import kernels
from fishswarm.sim.allocator import tune_allocator
from fishswarm.sim.openmp import openmp_waits, tune_openmp


def tick_seconds(fish: int, compiled: bool) -> tuple[float, float]:
    """(seconds a tick, seconds of start-up and the first tick) of the batch engine, with
    or without the compiled kernels."""
    saved = kernels.COMPILED_MIN_FISH
    kernels.COMPILED_MIN_FISH = 0 if compiled else 10**9
    try:
        return batch_tick(fish)
    finally:
        kernels.COMPILED_MIN_FISH = saved


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    add_sizes(parser, fish=[25, 1000, 10_000])
    args = parser.parse_args()
    if not kernels.available():
        raise SystemExit("numba is not installed: pip install -e '.[fast]'")
    tuned = tune_allocator()  # as a fishswarm process runs
    tune_openmp()
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, allocator set: {'yes' if tuned else 'no'}, "
        f"{openmp_waits()}"
    )
    print("| fish | numpy ms/tick | compiled ms/tick | speed-up | compiled steps/s | start-up s |")
    print("|---:|---:|---:|---:|---:|---:|")
    for fish in args.fish:
        reference, _ = tick_seconds(fish, compiled=False)
        compiled, start_up = tick_seconds(fish, compiled=True)
        print(
            f"| {fish} | {reference * 1e3:.1f} | {compiled * 1e3:.1f} | "
            f"{reference / compiled:.1f}× | {fish / compiled:,.0f} | {start_up:.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
