"""Benchmark: the actor system against its floors, in one run.

First the floors: the Zenoh echo round trip (``bench_bridge.py``) and, for each size, the
in-process batch engine's tick (compiled kernels from 200 fish on when numba is installed,
as the world uses them). Then whole swarms through the actor system over Zenoh on 127.0.0.1
(1 Hz control, full physics and vision) for 25, 1 000 and 10 000 fish with the fish in the
launcher's own process beside the world (``workers`` 0, still over Zenoh) and with 1 and 2
worker processes; beyond 25 fish the tank grows so that each fish has about 25 others within
visual range. The fish of a process form a school: one perception batch (in parts when
large) and one command batch per tick. Each row gives the tick (from the snapshot of tick 4
to the last, as the batch engine's leaves out its start-up and first tick; beside it the
whole tick loop's average, first ticks included), the time from launch to the first tick's
snapshot (what issue 14's start-up target counts), start-up (launch to the end of the run,
less the tick loop: processes, sessions, tokens, and teardown too), and the ratios issue 14
sets targets for: the actor tick over (batch tick + one echo) at 25 fish, over the batch
tick alone at 1 000, and the batch engine's speed as a share at 10 000. A second table says
where each actor tick goes: the world's physics and vision beside the batch engine's own
(the same steps, so a gap between them is the other work on the two cores), the
perceptions sent, and the fish's answer (perceptions out to the last command in). Then the
perception → command round trip of one fish actor on its own keys (as on a robot) in a
worker process, timed from a plain Zenoh session and from a trio task.

Usage:
    python bench/bench_swarm.py                    # everything, prints Markdown tables
    python bench/bench_swarm.py --fish 25 1000     # some sizes only
    python bench/bench_swarm.py --round-trips 0    # skip the latency part
    python bench/bench_swarm.py --rounds 3         # each size three times: median and range

Results and conditions are kept in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import threading
import time
from collections.abc import Callable
from typing import Any
from unittest.mock import patch

import numpy as np
import trio
import zenoh
from bench_bridge import echo_round_trips
from options import add_sizes

from fishswarm.actors.bus import open_subscriber
from fishswarm.actors.inbox import Inbox
from fishswarm.actors.launcher import LaunchSettings, launch_swarm, where_fish_run
from fishswarm.actors.observer import Progress
from fishswarm.actors.session import SessionSettings, free_loopback_endpoint, open_session
from fishswarm.actors.workers import WorkerSpec, start_worker, stop_worker
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Perception
from fishswarm.sim import kernels
from fishswarm.sim.allocator import tune_allocator
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.openmp import openmp_waits, tune_openmp
from fishswarm.sim.scenario import Scenario
from fishswarm.sim.tick import WorldSim

DURATION = {25: 600.0, 100: 120.0, 1000: 300.0, 10_000: 40.0}
WARM_UP_TICKS = 4
"""The tick is timed from the snapshot of this tick to the last, as the batch engine's is
timed without its start-up and first tick: the first ticks of a run load the compiled
kernels and warm the workers up (at 1 000 fish, 15 ticks averaged 54 ms where 150 averaged
14.5)."""
BATCH_DURATION = {25: 600.0, 1000: 300.0, 10_000: 40.0}


def swarm_row(fish: int, procs: int) -> dict[str, float]:
    """Run one swarm; return fish, procs, steps/s, real-time factor."""
    scenario = Scenario.crowded(fish, duration=DURATION.get(fish, 15.0), seed=1)
    settings = LaunchSettings(
        scenario, procs=procs, listen=free_loopback_endpoint(), start_timeout=120
    )
    seen: dict[int, float] = {}

    def progress(snapshot: Progress) -> None:
        seen.setdefault(snapshot.tick, time.perf_counter())

    launched = time.perf_counter()
    result = trio.run(lambda: launch_swarm(settings, on_progress=progress))
    summary = result.summary
    loop_time = summary["loop_time"]
    last = max(seen)
    steady = (seen[last] - seen[WARM_UP_TICKS]) / (last - WARM_UP_TICKS)
    return {
        "fish": fish,
        "procs": procs,
        "tick": steady,
        "loop_tick": loop_time / summary["counts"]["ticks"],
        "start_up": summary["wall_time"] - loop_time,
        "first_tick": seen[min(seen)] - launched,
        "ticks": summary["counts"]["ticks"],
        "steps_per_second": fish / steady,
        "real_time_factor": scenario.control_period / steady,
        "seen": summary["metrics"]["neighbors_seen"]["final"],
        **{f"world_{name}": value for name, value in summary["world_time"].items()},
        "answer": summary["answer_time"]["median"],
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


def batch_tick(fish: int) -> tuple[float, float]:
    """(seconds a tick, seconds of start-up and the first tick) of the batch engine on the
    scenario of :func:`swarm_row`: a run's time less the median of three one-tick runs,
    over its ticks after the first (runs long enough that start-up jitter stays small)."""
    scenario = Scenario.crowded(fish, duration=BATCH_DURATION.get(fish, 30.0), seed=1)
    first = scenario.replace(duration=1.0)
    simulate_batch(first)  # warm up: kernels, imports
    start_ups = []
    for _ in range(3):
        started = time.perf_counter()
        simulate_batch(first)
        start_ups.append(time.perf_counter() - started)
    start_up = statistics.median(start_ups)
    started = time.perf_counter()
    simulate_batch(scenario)
    return (time.perf_counter() - started - start_up) / (scenario.ticks - 1), start_up


def batch_phases(fish: int) -> dict[str, float]:
    """The median seconds of the batch engine's physics and vision on the scenario of
    :func:`swarm_row` (the world's own steps, each call timed, first tick left out), to set
    beside the same steps in the actor system's summary."""
    scenario = Scenario.crowded(fish, duration=BATCH_DURATION.get(fish, 30.0), seed=1)
    steps: dict[str, list[float]] = {"physics": [], "vision": []}

    def timed(name: str, step: Callable[[WorldSim], Any]) -> Callable[[WorldSim], Any]:
        def timed_step(world: WorldSim) -> Any:
            started = time.perf_counter()
            result = step(world)
            steps[name].append(time.perf_counter() - started)
            return result

        return timed_step

    with (
        patch.object(WorldSim, "next_event", timed("physics", WorldSim.next_event)),
        patch.object(WorldSim, "sense", timed("vision", WorldSim.sense)),
    ):
        simulate_batch(scenario)
    return {name: statistics.median(times[1:]) for name, times in steps.items()}


def median_round(
    rounds: list[tuple[float, dict[str, float]]], echo: float
) -> tuple[float, dict[str, float], dict[str, tuple[float, float]]]:
    """The round of the median actors / batch ratio, and each ratio's range over the rounds.

    ``rounds`` holds (batch engine tick, actor row) for one size, each pair measured in
    turn; of an even count the lower of the two middle rounds is taken. The ranges:
    ``echo`` (actors / (batch + echo)), ``batch`` (actors / batch) and ``share``
    (batch / actors)."""
    ordered = sorted(rounds, key=lambda measured: measured[1]["tick"] / measured[0])
    batch, row = ordered[(len(ordered) - 1) // 2]
    each = [ratios_of(batch, row["tick"], echo) for batch, row in rounds]
    return (
        batch,
        row,
        {name: (min(r[name] for r in each), max(r[name] for r in each)) for name in each[0]},
    )


def ratios_of(batch: float, tick: float, echo: float) -> dict[str, float]:
    """Issue 14's ratios of an actor tick to a batch engine tick, both s: ``echo`` (actors /
    (batch + echo)), ``batch`` (actors / batch) and ``share`` (batch / actors)."""
    return {"echo": tick / (batch + echo), "batch": tick / batch, "share": batch / tick}


def _with_range(ratio: float, spread: tuple[float, float]) -> str:
    """A ratio, and the range it took over the rounds when there were several."""
    low, high = spread
    return f"{ratio:.2f}" if low == high else f"{ratio:.2f} ({low:.2f}–{high:.2f})"


def plot_ticks(measured: list[tuple[int, int, float, float]], path: str) -> None:
    """Tick time against fish count, log-log: the batch engine and the actor system with
    each number of workers, from rows (fish, workers, batch s, actors s)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
    sizes = sorted({row[0] for row in measured})
    batch = {row[0]: row[2] for row in measured}
    axis.plot(sizes, [batch[n] * 1e3 for n in sizes], "o-", color="black", label="batch engine")
    for procs in sorted({row[1] for row in measured}):
        rows = sorted(row for row in measured if row[1] == procs)
        axis.plot(
            [r[0] for r in rows],
            [r[3] * 1e3 for r in rows],
            "s--",
            label=f"actor system, {where_fish_run(procs)}",
        )
    axis.set(
        xscale="log",
        yscale="log",
        xlabel="fish",
        ylabel="time per tick (ms)",
        title="One control period of a whole swarm, 2 cores",
    )
    # Plain numbers on both axes, not powers of ten: 25, 1,000, 10,000 fish; 1, 2, 5, 10 ms.
    times = [batch[n] * 1e3 for n in sizes] + [row[3] * 1e3 for row in measured]
    marks = [m * 10**e for e in range(-2, 5) for m in (1, 2, 5)]
    axis.set_xticks(sizes)
    axis.set_yticks([m for m in marks if min(times) / 2 <= m <= max(times) * 2])
    plain = matplotlib.ticker.FuncFormatter(lambda value, _: f"{value:,g}")
    axis.xaxis.set_major_formatter(plain)
    axis.yaxis.set_major_formatter(plain)
    axis.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axis.grid(True, which="both", alpha=0.3)
    axis.legend()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_sizes(parser, fish=[25, 1000, 10_000], procs=[0, 1, 2])
    parser.add_argument(
        "--round-trips",
        type=int,
        default=2000,
        help="one fish actor's perception-to-command round trips to time at the end "
        "(default 2000; 0 skips this part)",
    )
    parser.add_argument(
        "--rounds",
        type=int,
        default=1,
        help="time every size this many times, the batch engine and the actor system in turn, "
        "and report the round with the median ratio and the range of the ratios (the "
        "machine's speed moves within minutes; default 1)",
    )
    parser.add_argument("--plot", help="also draw tick time against fish count to this file")
    args = parser.parse_args()
    if args.rounds < 1:
        parser.error(f"--rounds must be 1 or more, got {args.rounds}")
    args.procs = list(dict.fromkeys(args.procs))  # each set-up once, however often named
    # As the fishswarm command and its workers do: the batch engine and the launcher run here.
    tuned = tune_allocator()
    tune_openmp()
    measured: list[tuple[int, int, float, float]] = []
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, compiled kernels: "
        f"{'yes' if kernels.available() else 'no (numba not installed)'}, allocator set: "
        f"{'yes' if tuned else 'no (not glibc)'}, {openmp_waits()}\n"
    )
    echo = float(np.median(echo_round_trips("zenoh", 1000))) / 1e3
    print(f"Zenoh echo floor: {echo * 1e3:.3f} ms (median of 1000)\n")
    print(
        "| fish | workers | batch ms/tick | actors ms/tick | whole loop ms/tick "
        "| actors / (batch + echo) | actors / batch | batch speed share | steps/s "
        "| to first tick s | start-up s | real-time factor |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    phases: list[tuple[int, int, dict[str, float], dict[str, float]]] = []

    def report(
        fish: int,
        procs: int,
        steps: dict[str, float],
        rounds: list[tuple[float, dict[str, float]]],
    ) -> None:
        """Print the row of one set-up, from its rounds (``steps``: the batch engine's)."""
        batch, row, spread = median_round(rounds, echo)
        tick = row["tick"]
        ratios = ratios_of(batch, tick, echo)
        measured.append((fish, procs, batch, tick))
        phases.append((fish, procs, steps, row))
        print(
            f"| {fish} | {procs} | {batch * 1e3:.1f} | {tick * 1e3:.1f} | "
            f"{row['loop_tick'] * 1e3:.1f} | "
            f"{' | '.join(_with_range(ratios[name], spread[name]) for name in ratios)} | "
            f"{row['steps_per_second']:,.0f} | {row['first_tick']:.2f} | "
            f"{row['start_up']:.1f} | "
            f"{row['real_time_factor']:.1f}× |",
            flush=True,
        )

    for fish in args.fish:
        batch_steps = batch_phases(fish)
        timed: dict[int, list[tuple[float, dict[str, float]]]] = {n: [] for n in args.procs}
        for number in range(1, args.rounds + 1):
            batch, _ = batch_tick(fish)
            for procs in args.procs:
                timed[procs].append((batch, swarm_row(fish, procs)))
                if args.rounds == 1:  # each row as soon as it is measured
                    report(fish, procs, batch_steps, timed[procs])
            if args.rounds > 1:
                ticks = ", ".join(
                    f"{timed[procs][-1][1]['tick'] * 1e3:.1f}" for procs in args.procs
                )
                workers = ", ".join(map(str, args.procs))
                print(
                    f"({fish} fish, round {number} of {args.rounds}: batch engine "
                    f"{batch * 1e3:.1f} ms, actors {ticks} ms with {workers} workers)",
                    file=sys.stderr,
                    flush=True,
                )
        if args.rounds > 1:
            for procs in args.procs:
                report(fish, procs, batch_steps, timed[procs])
    print()
    print(
        "Where the actor system's tick goes (medians, ms; the batch engine's own physics and "
        "vision beside them; the fish's answer counts from the perceptions sent to the last "
        "command taken):\n"
    )
    print(
        "| fish | workers | physics: batch, actors | vision: batch, actors "
        "| perceptions out | the fish's answer |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for fish, procs, steps, row in phases:
        print(
            f"| {fish} | {procs} | {steps['physics'] * 1e3:.2f}, "
            f"{row['world_physics'] * 1e3:.2f} | {steps['vision'] * 1e3:.2f}, "
            f"{row['world_vision'] * 1e3:.2f} | {row['world_perceptions'] * 1e3:.2f} | "
            f"{row['answer'] * 1e3:.2f} |"
        )
    if args.plot:
        plot_ticks(measured, args.plot)
    if args.round_trips:
        print()
        print(_describe("timed from Zenoh", round_trips_from_zenoh(args.round_trips)))
        print(_describe("timed from trio", trio.run(round_trips_from_trio, args.round_trips)))


if __name__ == "__main__":
    main()
