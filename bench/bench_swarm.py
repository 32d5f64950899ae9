"""Benchmark: fish-control steps per second, real-time factor and round-trip latency.

Runs whole swarms through the actor system over Zenoh on 127.0.0.1 (1 Hz control, full
physics and vision) for 25, 100 and 1000 fish with 1 and 2 worker processes; beyond 25 fish
the tank grows so that each fish has about 25 others within visual range. Then measures the
perception → command round trip of one fish actor in a worker process.

Usage:
    python bench/bench_swarm.py                 # everything, prints Markdown tables
    python bench/bench_swarm.py --fish 25 100   # some sizes only
    python bench/bench_swarm.py --round-trips 0 # skip the latency part

Results and conditions are kept in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import socket
import statistics
import time

import numpy as np
import trio

from fishswarm.actors.bridge import SessionSettings, open_session, open_subscription, publisher
from fishswarm.actors.launcher import LaunchSettings, run_swarm
from fishswarm.actors.workers import WorkerSpec, start_worker, stop_worker
from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Perception
from fishswarm.scenario import Scenario
from fishswarm.simulation import policy_of

DURATION = {25: 120.0, 100: 60.0, 1000: 15.0}


def _endpoint() -> str:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


def swarm_row(fish: int, procs: int) -> dict[str, float]:
    """Run one swarm; return fish, procs, steps/s, real-time factor."""
    scenario = Scenario.crowded(fish, duration=DURATION.get(fish, 15.0), seed=1)
    settings = LaunchSettings(scenario, procs=procs, listen=_endpoint(), start_timeout=120)
    result = trio.run(lambda: run_swarm(settings))
    summary = result.summary
    loop_time = summary["loop_time"]
    steps = summary["counts"]["ticks"] * fish
    return {
        "fish": fish,
        "procs": procs,
        "ticks": summary["counts"]["ticks"],
        "steps_per_second": steps / loop_time,
        "real_time_factor": summary["real_time_factor"],
        "seen": summary["metrics"]["neighbors_seen"]["final"],
    }


async def _round_trips(count: int) -> list[float]:
    endpoint = _endpoint()
    scenario = Scenario()
    keys = scenario.keys
    spec = WorkerSpec(0, (0,), policy_of(scenario), scenario.swarm, endpoint)
    router = SessionSettings(mode="router", listen=[endpoint])
    neighbors = np.array([[0.5, 0.1, 0.0], [-0.3, 0.4, 0.1], [1.0, -1.0, 0.0]])
    samples: list[float] = []
    async with open_session(router) as session:
        worker = start_worker(spec)
        try:
            async with open_subscription(session, keys.command(0)) as commands:
                await trio.sleep(2.0)  # let the worker start and subscribe
                put = publisher(session)
                for tick in range(count + 50):
                    perception = Perception(0, tick, float(tick), 0.5, neighbors, np.zeros((0, 3)))
                    started = time.perf_counter()
                    put(keys.perception(0), encode(perception))
                    with trio.fail_after(5):
                        await commands.receive()
                    if tick >= 50:  # warm-up
                        samples.append(time.perf_counter() - started)
        finally:
            await trio.to_thread.run_sync(stop_worker, worker)
    return samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fish", type=int, nargs="+", default=[25, 100, 1000])
    parser.add_argument("--procs", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--round-trips", type=int, default=2000)
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}\n"
    )
    print(
        "| fish | worker processes | ticks | fish-control steps/s | real-time factor "
        "| neighbours seen |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for fish in args.fish:
        for procs in args.procs:
            row = swarm_row(fish, procs)
            print(
                f"| {fish} | {procs} | {row['ticks']} | {row['steps_per_second']:,.0f} | "
                f"{row['real_time_factor']:.0f}× | {row['seen']:.1f} |",
                flush=True,
            )
    if args.round_trips:
        samples = np.array(trio.run(_round_trips, args.round_trips)) * 1e3
        print(
            f"\nround trip perception → command, {len(samples)} samples: "
            f"p50 {np.percentile(samples, 50):.3f} ms, p90 {np.percentile(samples, 90):.3f} ms, "
            f"p99 {np.percentile(samples, 99):.3f} ms, mean {statistics.fmean(samples):.3f} ms"
        )


if __name__ == "__main__":
    main()
