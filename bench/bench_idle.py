"""Benchmark: what waiting costs the work that follows it.

An actor spends most of a tick waiting (a fish worker for the world's physics, the world for
the fish's commands), and each wait ends with a little work: decode a message, decide,
encode. This times one such piece of work — decoding and checking a 25-fish perception
batch, as a fish worker does every tick — back to back, and after each kind of pause an
actor may take:

- ``back to back``: no pause (the number a profile of a loop reports);
- ``after sleeping``: the thread sleeps (as trio's event loop does when idle) for the given
  time first;
- ``after spinning``: the thread stays busy in Python for the same time first.

On a virtual machine a sleeping core may be handed to someone else, and comes back with cold
caches: the difference between "after sleeping" and "back to back" is the part of an actor's
per-tick work that no profile of a hot loop shows. Results and conditions are kept in
docs/benchmarks.md.

Usage:
    python bench/bench_idle.py
    python bench/bench_idle.py --pauses 0.5 2.5 10 --samples 400
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import numpy as np


def perception_payload(fish: int) -> bytes:
    """The encoded perception batch of a ``fish``-fish school, two ticks into a crowded run."""
    from fishswarm.actors.perceptions import Schools, perception_messages
    from fishswarm.protocols.codec import encode
    from fishswarm.sim.physics import WorldParams
    from fishswarm.sim.scenario import Scenario
    from fishswarm.sim.tick import WorldSim

    scenario = Scenario.crowded(fish, duration=5.0, seed=1)
    world = WorldSim(WorldParams.of(scenario))
    world.join(list(range(fish)))
    world.next_event()
    world.next_event()
    perceived = world.sense()
    messages = perception_messages(
        scenario.keys,
        ids=world.ids,
        schools=Schools.of(world.ids, dict.fromkeys(range(fish), "school")),
        depth=world.state.position[:, 2],
        perceived=perceived,
        landmarks=world.sense_landmarks(),
        inbox_counts=np.zeros(fish, dtype=np.int64),
        tick=2,
        time=2.0,
        heading=world.state.yaw,
    )
    return encode(messages[0][1])


def timed_after(work: Callable[[], object], pause: Callable[[], None], samples: int) -> float:
    """Median seconds of ``work`` run right after ``pause``, over ``samples`` rounds."""
    times = []
    for _ in range(samples):
        pause()
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def spin(duration: float) -> Callable[[], None]:
    def pause() -> None:
        until = time.perf_counter() + duration
        while time.perf_counter() < until:
            pass

    return pause


def sleep(duration: float) -> Callable[[], None]:
    return lambda: time.sleep(duration)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fish", type=int, default=25, help="fish in the batch (default 25)")
    parser.add_argument(
        "--pauses",
        type=float,
        nargs="+",
        default=[0.5, 2.5],
        help="pauses before the work, ms (default 0.5 2.5: a fish worker waits about "
        "2.5 ms a tick at 25 fish)",
    )
    parser.add_argument("--samples", type=int, default=400, help="rounds per row")
    args = parser.parse_args()
    if args.fish < 1 or args.samples < 1 or any(pause < 0 for pause in args.pauses):
        parser.error("--fish and --samples must be at least 1, --pauses not negative")

    from fishswarm.protocols.codec import decode
    from fishswarm.protocols.messages import PerceptionBatch

    payload = perception_payload(args.fish)

    def work() -> object:
        return decode(payload, PerceptionBatch)

    for _ in range(200):
        work()
    hot = timed_after(work, lambda: None, args.samples)
    print(f"decoding a {args.fish}-fish perception batch ({len(payload)} bytes), medians:")
    print("| before it | µs | × back to back |")
    print("|---|---:|---:|")
    print(f"| nothing (back to back) | {hot * 1e6:.1f} | 1.00 |")
    for pause_ms in args.pauses:
        for name, pause in (("sleeping", sleep), ("spinning", spin)):
            took = timed_after(work, pause(pause_ms / 1e3), args.samples)
            print(f"| {name} {pause_ms:g} ms | {took * 1e6:.1f} | {took / hot:.2f} |")


if __name__ == "__main__":
    main()
