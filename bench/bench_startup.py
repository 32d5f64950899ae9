"""Benchmark: launch to the first tick, each run in a fresh interpreter.

``bench_swarm.py`` times start-up inside one long process, after the runs before it; there
the previous run's worker processes and Zenoh threads may still be winding down. Here every
measurement starts its own interpreter (the ``spawn`` context), which imports fishswarm,
warms the batch engine (and the compiled kernels from 200 fish on) as ``fishswarm run``
would on its first tick, and then times ``launch_swarm`` from launch to the first tick's
snapshot: what issue 14's start-up target counts.

Usage:
    python bench/bench_startup.py                          # 25 and 10 000 fish, 0-2 workers
    python bench/bench_startup.py --fish 25 --repeat 5

Results and conditions are kept in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

from options import add_sizes


def first_tick(fish: int, procs: int) -> float:
    """Seconds from launch to the first tick's snapshot of a 2-s crowded run."""
    import trio

    from fishswarm.actors.launcher import LaunchSettings, launch_swarm
    from fishswarm.actors.session import free_loopback_endpoint
    from fishswarm.sim.engine import simulate_batch
    from fishswarm.sim.scenario import Scenario

    simulate_batch(Scenario.crowded(fish, duration=1.0, seed=1))  # imports and kernels warm
    scenario = Scenario.crowded(fish, duration=2.0, seed=1)
    settings = LaunchSettings(
        scenario, procs=procs, listen=free_loopback_endpoint(), start_timeout=120
    )
    reached: list[float] = []

    def progress(_: object) -> None:
        if not reached:
            reached.append(time.perf_counter())

    launched = time.perf_counter()
    trio.run(lambda: launch_swarm(settings, on_progress=progress))
    return reached[0] - launched


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_sizes(parser, fish=[25, 10_000], procs=[0, 1, 2])
    parser.add_argument("--repeat", type=int, default=3, help="fresh runs per row")
    args = parser.parse_args()
    context = multiprocessing.get_context("spawn")
    print("| fish | workers | to first tick s, each run | median |")
    print("|---:|---:|---|---:|")
    for fish in args.fish:
        for procs in args.procs:
            times = []
            for _ in range(args.repeat):
                # A pool of one fresh process per run (not multiprocessing.Pool, whose
                # daemonic processes may not start the swarm's workers).
                with ProcessPoolExecutor(1, mp_context=context) as pool:
                    times.append(pool.submit(first_tick, fish, procs).result(timeout=600))
            shown = ", ".join(f"{t:.2f}" for t in times)
            print(f"| {fish} | {procs} | {shown} | {statistics.median(times):.2f} |", flush=True)


if __name__ == "__main__":
    main()
