"""The ``fishswarm`` command: run a swarm, run one actor alone, export recordings."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fishswarm.progress import ProgressLine, bar
from fishswarm.scenario import BEHAVIORS, ConfigError, Scenario

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

_SCENARIO_FLAGS: dict[str, tuple[str, type, str]] = {
    "fish": ("--fish", int, "number of fish (default 25)"),
    "behavior": ("--behavior", str, f"one of {', '.join(BEHAVIORS)} (default dispersion)"),
    "duration": ("--duration", float, "simulated seconds (default 15)"),
    "seed": ("--seed", int, "master seed; the same seed gives the same run (default 0)"),
    "control_period": ("--period", float, "control period in s (default 1: 1 Hz)"),
    "controller": ("--controller", str, "homing (default, the research code's) or pid"),
    "target_distance": (
        "--target-distance",
        float,
        "Lennard-Jones target distance in m (default 0.26 for aggregation, "
        "the tank diagonal for dispersion)",
    ),
    "blind_width": ("--blind-width", float, "blind-spot width in m (default 0.05)"),
    "sphere_radius": ("--sphere-radius", float, "blocking-sphere radius in m (default 0.065)"),
    "orbit_radius": (
        "--orbit-radius",
        float,
        "orbit radius R of orbit and milling around the post at the tank centre, partner "
        "distance of waltz, m (default 0.45)",
    ),
    "time_mode": (
        "--time",
        str,
        "lockstep (default: as fast as possible, deterministic), jitter (each fish on its own "
        "clock, periods drawn from N(period, --jitter); deterministic) or realtime (one tick "
        "per control period of wall-clock time; late fish keep their last command)",
    ),
    "jitter": (
        "--jitter",
        float,
        "with --time jitter: s.d. of each fish's control period, s (default 0.05)",
    ),
    "swarm": ("--swarm", str, "swarm name: several swarms can share a router (default default)"),
    "model": (
        "--model",
        str,
        "learned replica (best_replica.npz from 'fishswarm learn') for --behavior replica",
    ),
}


def _add_scenario_flags(parser: argparse.ArgumentParser, names: Sequence[str]) -> None:
    group = parser.add_argument_group("scenario (override the --config file)")
    group.add_argument(
        "--config",
        type=Path,
        metavar="TOML",
        help="scenario file (TOML); its settings are listed in the README under 'Scenario files'",
    )
    for name in names:
        flag, kind, text = _SCENARIO_FLAGS[name]
        group.add_argument(flag, dest=name, type=kind, default=None, help=text)


def _scenario(args: argparse.Namespace) -> Scenario:
    base = Scenario.from_toml(args.config) if getattr(args, "config", None) else Scenario()
    overrides = {name: getattr(args, name, None) for name in _SCENARIO_FLAGS}
    try:
        return base.replace(**overrides)
    except TypeError as error:
        raise ConfigError(str(error)) from None


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fishswarm",
        description="Run BlueBot robot-fish swarms as async actors over Eclipse Zenoh.",
        epilog="Run 'fishswarm COMMAND --help' for the options of a command.",
    )
    parser.add_argument(
        "--log-level",
        default="WARNING",
        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
        help="default WARNING",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = commands.add_parser(
        "run",
        help="run a whole simulated swarm with one command",
        description="Start a router, the world, the channel and an observer, spawn the fish "
        "over worker processes, run the scenario, and write a recording and a summary.",
    )
    _add_scenario_flags(run, list(_SCENARIO_FLAGS))
    run.add_argument("--procs", type=int, default=1, help="fish worker processes (default 1)")
    run.add_argument(
        "--record",
        type=Path,
        default=Path("runs/latest.mcap"),
        help="MCAP recording to write (default runs/latest.mcap)",
    )
    run.add_argument(
        "--summary",
        type=Path,
        default=Path("runs/latest.json"),
        help="JSON summary to write (default runs/latest.json)",
    )
    run.add_argument(
        "--listen",
        default=DEFAULT_ENDPOINT,
        help=f"endpoint to listen on (default {DEFAULT_ENDPOINT}; "
        "tcp/0.0.0.0:7447 lets observers on other machines attach)",
    )
    run.add_argument(
        "--start-timeout",
        type=float,
        default=60.0,
        help="longest wait for all fish to come up, s (default 60)",
    )
    run.add_argument("--quiet", action="store_true", help="no progress lines")

    fish = commands.add_parser(
        "fish",
        help="run fish actors alone (what runs on a robot)",
        description="Run one or more fish actors that connect to a router. The fish stop "
        "their fins when perceptions stop arriving.",
    )
    fish.add_argument(
        "--id",
        dest="ids",
        type=int,
        action="append",
        required=True,
        help="fish id; repeat for several fish in one process",
    )
    _add_connect(fish)
    _add_scenario_flags(
        fish,
        [
            "behavior",
            "target_distance",
            "controller",
            "control_period",
            "orbit_radius",
            "swarm",
            "model",
        ],
    )
    fish.add_argument(
        "--perception-timeout",
        type=float,
        default=5.0,
        help="fins off after this long without a perception, s (default 5)",
    )
    fish.add_argument(
        "--school",
        metavar="NAME",
        help="serve the fish as one school: one perception batch and one command batch per "
        "tick instead of a message per fish (for many simulated fish in one process; a robot "
        "keeps its own keys)",
    )

    world = commands.add_parser(
        "world",
        help="run the world actor alone",
        description="Run the simulated world; it waits for --fish fish "
        "(ids 0..N-1) and then runs the scenario.",
    )
    _add_connect(world)
    _add_scenario_flags(world, list(_SCENARIO_FLAGS))
    world.add_argument(
        "--start-timeout",
        type=float,
        default=60.0,
        help="longest wait for the fish, s (default 60)",
    )

    channel = commands.add_parser("channel", help="run the channel actor alone")
    _add_connect(channel)
    _add_scenario_flags(channel, ["seed", "swarm"])

    observe = commands.add_parser(
        "observe",
        help="attach an observer to a running swarm",
        description="Watch a swarm's snapshots and liveliness from this or another machine; "
        "print progress and optionally record. Stops on Ctrl-C, or after --ticks snapshots.",
    )
    _add_connect(observe)
    observe.add_argument("--swarm", default="default", help="swarm name (default default)")
    observe.add_argument("--record", type=Path, help="MCAP recording to write")
    observe.add_argument("--ticks", type=int, help="stop after the snapshot of this tick")

    router = commands.add_parser("router", help="run a Zenoh router (e.g. on the base station)")
    router.add_argument(
        "--listen",
        default="tcp/0.0.0.0:7447",
        help="endpoint to listen on (default tcp/0.0.0.0:7447)",
    )

    learn = commands.add_parser(
        "learn",
        help="learn fish behaviour from observation (Turing learning with CMA-ES)",
        description="Co-evolve replica fish and classifiers with CMA-ES until the replicas "
        "behave like the ideal fish (SPEC §4). Writes checkpoints, the best replica, fitness "
        "curves, spacing/speed and trajectory plots and the learned radii to --out.",
    )
    learn.add_argument(
        "--behavior",
        choices=["aggregation", "dispersion"],
        default="aggregation",
        help="what the ideal fish do (default aggregation)",
    )
    learn.add_argument(
        "--inputs",
        default="speed,neighbors",
        help="classifier inputs, comma-separated, from speed, angular-speed, "
        "neighbors (one learned radius), neighbors2 (two) (default "
        "speed,neighbors)",
    )
    learn.add_argument(
        "--radii",
        choices=["bounded", "unbounded"],
        default="bounded",
        help="radii clipped to [0, 300] or free from a start in [-40, 300] (default bounded)",
    )
    learn.add_argument("--generations", type=int, default=500, help="default 500")
    learn.add_argument("--models", type=int, default=100, help="replica population (100)")
    learn.add_argument("--classifiers", type=int, default=100, help="classifier population (100)")
    learn.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    learn.add_argument(
        "--hall-of-fame",
        type=int,
        default=0,
        help="past champions drawn into every generation (default 0: the study's method)",
    )
    learn.add_argument(
        "--out", type=Path, default=Path("runs/learn"), help="output folder (default runs/learn)"
    )
    learn.add_argument(
        "--checkpoint-every",
        type=int,
        default=10,
        help="generations between checkpoints (default 10)",
    )
    learn.add_argument(
        "--resume", action="store_true", help="continue from OUT/checkpoint.pkl up to --generations"
    )
    learn.add_argument("--quiet", action="store_true", help="no progress lines")

    export = commands.add_parser(
        "export",
        help="export a recording to NumPy or CSV",
        description="Write arrays t (T,), pos (T,N,3), vel (T,N,3), "
        "yaw (T,N), ids (N,) in SI units to .npz, and/or a flat CSV.",
    )
    export.add_argument("recording", type=Path, help="MCAP recording of a run")
    export.add_argument("--npz", type=Path, help="NumPy archive to write")
    export.add_argument("--csv", type=Path, help="CSV table to write")
    from fishswarm.actors import study_commands

    study_commands.add_parsers(commands)
    return parser


def _add_connect(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--connect",
        default=DEFAULT_ENDPOINT,
        help=f"router endpoint to connect to (default {DEFAULT_ENDPOINT})",
    )
    parser.add_argument(
        "--connect-timeout",
        type=float,
        default=10.0,
        help="longest wait for the router, s; negative waits forever (default 10)",
    )


def _learn(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm learn``."""
    from fishswarm.learning.coevolution import LearningSettings
    from fishswarm.learning.session import LearningError, learn

    try:
        settings = LearningSettings(
            behavior=args.behavior,
            inputs=tuple(name.strip() for name in args.inputs.split(",") if name.strip()),
            radii=args.radii,
            models=args.models,
            classifiers=args.classifiers,
            seed=args.seed,
            hall_of_fame=args.hall_of_fame,
        )
    except ValueError as error:
        raise ConfigError(str(error)) from None
    every = max(1, args.generations // 50)
    output = ProgressLine()

    def progress(run: Any, record: dict[str, float], seconds: float) -> None:
        done = run.generation
        if args.quiet or (done % every and done != args.generations):
            return
        left = (args.generations - done) * seconds
        line = (
            f"{bar(done, args.generations)} "
            f"generation {done}/{args.generations}  models best {record['model_best']:.3f} "
            f"mean {record['model_mean']:.3f}  classifiers best {record['classifier_best']:.3f} "
            f"mean {record['classifier_mean']:.3f}  {seconds:.2f} s/gen  ~{left / 60:.1f} min left"
        )
        output.show(line)

    try:
        summary = learn(
            settings,
            generations=args.generations,
            out=args.out,
            checkpoint_every=args.checkpoint_every,
            resume=args.resume,
            on_generation=progress,
        )
    except LearningError as error:
        raise ConfigError(str(error)) from None
    if output.tty and not args.quiet:
        sys.stderr.write("\n")
    ideal, replica = summary["ideal"], summary["replica"]
    print(
        f"done: {summary['generations']} generations in {args.out}\n"
        f"  final spacing  ideal {ideal['final_spacing']:.1f}  replica "
        f"{replica['final_spacing']:.1f}\n"
        f"  final speed    ideal {ideal['final_speed']:.2f}  replica {replica['final_speed']:.2f}\n"
        f"  learned radii  mean {summary['radii']['mean']}  s.d. {summary['radii']['sd']}",
        file=sys.stderr,
    )
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``fishswarm`` console script."""
    parser = _parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level, format="%(levelname)s %(name)s: %(message)s")
    from fishswarm.actors import commands, study_commands

    handlers: dict[str, Any] = {
        "run": commands.run,
        "fish": commands.fish,
        "world": commands.world,
        "channel": commands.channel,
        "observe": commands.observe,
        "router": commands.router,
        "export": commands.export,
        "learn": _learn,
        "experiment": study_commands.experiment,
        "plot": study_commands.plot,
        "animate": study_commands.animate,
    }
    try:
        scenario = _scenario(args) if hasattr(args, "config") else None
        code = int(handlers[args.command](args, scenario))
    except ConfigError as error:
        parser.exit(2, f"fishswarm {args.command}: error: {error}\n")
    except commands.UserError as error:
        print(f"fishswarm {args.command}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("fishswarm: interrupted", file=sys.stderr)
        return 130
    return code


if __name__ == "__main__":
    sys.exit(main())
