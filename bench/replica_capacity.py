"""Can a replica network do what the ideal fish do at all? Fit it straight to them.

Turing learning only ever tells a replica how well it fooled the classifiers. This script
asks an easier question first: with the target's own measures as the objective (the
largest relative spacing error from 5 s to 15 s, plus half the final speed difference,
over six training starts), how close does CMA-ES bring one replica network to the ideal
fish? What it cannot reach here, co-evolution cannot reach either. The best network is then
judged like a learned one, over the 20 fresh trials of ``fishswarm learn``'s summary.

Run: python bench/replica_capacity.py [--behavior dispersion] [--scales 100,40]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import cma
import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.arena import (
    SPREADS,
    ideal_velocity,
    initial_positions,
    replica_velocity,
    simulate,
    spacing_and_speed,
)
from fishswarm.learning.coevolution import LearningSettings
from fishswarm.learning.networks import REPLICA_SIZE
from fishswarm.learning.session import JUDGED_FROM, evaluate, target_report

FloatArray = NDArray[np.float64]


def fit(settings: LearningSettings, *, iterations: int, seed: int) -> FloatArray:
    """The replica weights CMA-ES finds with the target's measures as the objective."""
    arena = settings.arena
    starts = initial_positions(
        np.random.default_rng(seed), arena=arena, spread=SPREADS[settings.behavior], models=6
    )
    ideal = simulate(lambda p: ideal_velocity(p, arena=arena), starts, arena=arena)
    ideal_spacing, ideal_speed = spacing_and_speed(ideal, arena=arena)
    judged = slice(int(JUDGED_FROM / arena.period), None)

    def loss(weights: FloatArray) -> float:
        many = np.repeat(np.asarray(weights)[None], len(starts), axis=0)
        tracks = simulate(lambda p: replica_velocity(p, many, arena=arena), starts, arena=arena)
        spacing, speed = spacing_and_speed(tracks, arena=arena)
        wanted, got = ideal_spacing.mean(axis=0)[judged], spacing.mean(axis=0)[judged]
        speed_gap = abs(speed.mean(axis=0)[-1] - ideal_speed.mean(axis=0)[-1])
        return float(np.max(np.abs(got - wanted) / wanted) + speed_gap / 2)

    options = {"popsize": 30, "maxiter": iterations, "seed": seed + 1, "verbose": -9}
    strategy = cma.CMAEvolutionStrategy(np.zeros(REPLICA_SIZE), 1.0, options)
    while not strategy.stop():
        candidates = strategy.ask()
        strategy.tell(candidates, [loss(np.asarray(c)) for c in candidates])
    best: FloatArray = np.asarray(strategy.result.xbest)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--behavior",
        choices=sorted(SPREADS),
        default="dispersion",
        help="the ideal fish to fit (default: %(default)s)",
    )
    parser.add_argument("--scales", default="100,40", help="replica input scales to try")
    parser.add_argument("--iterations", type=int, default=300, help="CMA-ES iterations")
    parser.add_argument("--seed", type=int, default=0, help="seed of CMA-ES and the trials")
    args = parser.parse_args()
    print(
        f"{args.behavior}: a replica fitted straight to the ideal fish ({args.iterations} "
        "iterations of 30); judged over 20 fresh trials"
    )
    print("input scale | spacing error 5-15 s | final speed ideal / replica | fit time s")
    for scale in (float(s) for s in args.scales.split(",")):
        arena = dataclasses.replace(LearningSettings().arena, replica_input_scale=scale)
        settings = LearningSettings(behavior=args.behavior, arena=arena)
        started = time.perf_counter()
        weights = fit(settings, iterations=args.iterations, seed=args.seed)
        took = time.perf_counter() - started
        evaluation = evaluate(settings, weights)
        report = target_report(evaluation, arena)
        print(
            f"{scale:11g} | {100 * report['spacing_error']:19.1f} % | "
            f"{evaluation.speed[0, -1]:.2f} / {evaluation.speed[1, -1]:.2f}"
            f"{'':16} | {took:.0f}"
        )


if __name__ == "__main__":
    main()
