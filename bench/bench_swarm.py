"""Benchmark: fish-control steps per second, real-time factor and round-trip latency.

Runs whole swarms through the actor system over Zenoh on 127.0.0.1 (1 Hz control, full
physics and vision) for 25, 100 and 1000 fish with 1 and 2 worker processes; beyond 25 fish
the tank grows so that each fish has about 25 others within visual range. A worker's fish
form a school: one perception batch and one command batch per tick. Then measures the
perception → command round trip of one fish actor on its own keys (as on a robot) in a
worker process, timed from a plain Zenoh session and from a trio task.

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
import statistics
import threading
import time

import numpy as np
import trio
import zenoh

from fishswarm.actors.bus import open_subscriber
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.launcher import LaunchSettings, run_swarm
from fishswarm.actors.session import SessionSettings, free_loopback_endpoint, open_session
from fishswarm.actors.workers import WorkerSpec, start_worker, stop_worker
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Perception
from fishswarm.sim.scenario import Scenario

DURATION = {25: 120.0, 100: 60.0, 1000: 15.0}


def swarm_row(fish: int, procs: int) -> dict[str, float]:
    """Run one swarm; return fish, procs, steps/s, real-time factor."""
    scenario = Scenario.crowded(fish, duration=DURATION.get(fish, 15.0), seed=1)
    settings = LaunchSettings(
        scenario, procs=procs, listen=free_loopback_endpoint(), start_timeout=120
    )
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


def _perceptions(count: int) -> list[bytes]:
    neighbors = np.array([[0.5, 0.1, 0.0], [-0.3, 0.4, 0.1], [1.0, -1.0, 0.0]])
    return [
        encode(Perception(0, tick, float(tick), 0.5, neighbors, np.zeros((0, 3))))
        for tick in range(count)
    ]


def round_trips_from_zenoh(count: int) -> list[float]:
    """Round trips timed from a plain Zenoh session: the perception is put from this thread
    and the command time-stamped in Zenoh's callback thread, so the harness adds no event
    loop of its own; what is timed is Zenoh both ways plus the fish actor."""
    endpoint = free_loopback_endpoint()
    scenario = Scenario()
    keys = scenario.keys
    spec = WorkerSpec(0, (0,), scenario.fish_params(), scenario.swarm, endpoint, schooled=False)
    session = zenoh.open(SessionSettings(mode="router", listen=[endpoint]).to_config())
    arrived = threading.Event()
    stamp = [0.0]

    def on_command(sample: zenoh.Sample) -> None:
        stamp[0] = time.perf_counter()
        arrived.set()

    subscriber = session.declare_subscriber(keys.command(0), on_command)
    worker = start_worker(spec)
    samples: list[float] = []
    try:
        time.sleep(2.0)  # let the worker start and subscribe
        key = session.declare_keyexpr(keys.perception(0))
        for tick, payload in enumerate(_perceptions(count + 50)):
            arrived.clear()
            started = time.perf_counter()
            session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)
            if not arrived.wait(5.0):
                raise RuntimeError(f"no command for tick {tick} within 5 s")
            if tick >= 50:  # warm-up
                samples.append(stamp[0] - started)
    finally:
        stop_worker(worker)
        subscriber.undeclare()
        session.close()
    return samples


async def round_trips_from_trio(count: int) -> list[float]:
    """The same round trips timed from a trio task (as a trio world or driver would see
    them): adds the harness's own wake-up from Zenoh's thread into trio."""
    endpoint = free_loopback_endpoint()
    scenario = Scenario()
    keys = scenario.keys
    spec = WorkerSpec(0, (0,), scenario.fish_params(), scenario.swarm, endpoint, schooled=False)
    router = SessionSettings(mode="router", listen=[endpoint])
    samples: list[float] = []
    async with open_session(router) as session:
        worker = start_worker(spec)
        try:
            bus = ZenohBus(session)
            commands: Inbox[bytes] = Inbox()
            async with open_subscriber(bus, keys.command(0), lambda _, p: commands.push(p)):
                await trio.sleep(2.0)  # let the worker start and subscribe
                for tick, payload in enumerate(_perceptions(count + 50)):
                    started = time.perf_counter()
                    bus.put(keys.perception(0), payload)
                    with trio.fail_after(5):
                        await commands.receive()
                    if tick >= 50:  # warm-up
                        samples.append(time.perf_counter() - started)
        finally:
            await trio.to_thread.run_sync(stop_worker, worker)
    return samples


def _describe(name: str, samples: list[float]) -> str:
    milliseconds = np.array(samples) * 1e3
    return (
        f"round trip perception → command, {name}, {len(samples)} samples: "
        f"p50 {np.percentile(milliseconds, 50):.3f} ms, "
        f"p90 {np.percentile(milliseconds, 90):.3f} ms, "
        f"p99 {np.percentile(milliseconds, 99):.3f} ms, "
        f"mean {statistics.fmean(milliseconds):.3f} ms"
    )


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
        print()
        print(_describe("timed from Zenoh", round_trips_from_zenoh(args.round_trips)))
        print(_describe("timed from trio", trio.run(round_trips_from_trio, args.round_trips)))


if __name__ == "__main__":
    main()
