"""Benchmark: seconds per Turing-learning generation at the study's size.

100 replica models and 100 classifiers, 25 fish, 15 s at 1 Hz: one ideal trial and 100
model trials per generation, 2525 samples judged by every classifier. Runs a few warm-up
generations, then times the next ones, for each classifier input choice given.

Usage:
    python bench/bench_learning.py
    python bench/bench_learning.py --generations 20 --inputs speed,neighbors2
    python bench/bench_learning.py --inputs speed,neighbors --hall-of-fame 0 --soft-weight 0.001
        (the study's method but for reduced virulence, which costs no time; the defaults are
        fishswarm learn's)

Results and conditions are kept in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import itertools
import os
import platform
import time

import numpy as np

from fishswarm.learning.arena import REPLICA_KINDS, Arena
from fishswarm.learning.coevolution import Coevolution, LearningSettings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--generations", type=int, default=10, help="generations timed (default 10)"
    )
    parser.add_argument(
        "--warm-up",
        type=int,
        default=2,
        help="generations run before the timing starts (default 2)",
    )
    parser.add_argument(
        "--inputs",
        nargs="+",
        default=["speed,counts", "speed,neighbors", "speed,angular-speed,neighbors2"],
        help="classifier input choices to time (default: learn's, speed,counts, then the "
        "study's, speed,neighbors, and two learned radii)",
    )
    parser.add_argument(
        "--hall-of-fame", type=int, default=10, help="past champions kept (0: no hall of fame)"
    )
    parser.add_argument(
        "--soft-weight",
        type=float,
        default=1.0,
        help="weight of the soft judgement (0.001: the study's)",
    )
    parser.add_argument(
        "--replica",
        nargs="+",
        choices=REPLICA_KINDS,
        default=["isotropic"],
        help="replica kinds to time (default: learn's, isotropic)",
    )
    args = parser.parse_args()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}\n"
    )
    print("| classifier inputs | replica | s/generation (mean) | min | 500 generations |")
    print("|---|---|---:|---:|---:|")
    for inputs, replica in itertools.product(args.inputs, args.replica):
        settings = LearningSettings(
            inputs=tuple(inputs.split(",")),
            hall_of_fame=args.hall_of_fame,
            soft_weight=args.soft_weight,
            arena=Arena(replica=replica),
        )
        run = Coevolution(settings)
        for _ in range(args.warm_up):
            run.step()
        times = []
        for _ in range(args.generations):
            started = time.perf_counter()
            run.step()
            times.append(time.perf_counter() - started)
        mean = float(np.mean(times))
        print(
            f"| {inputs} | {replica} | {mean:.2f} | {min(times):.2f} | {500 * mean / 60:.1f} min |",
            flush=True,
        )


if __name__ == "__main__":
    main()
