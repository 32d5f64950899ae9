"""``fishswarm learn``: Turing learning from the command line, with a progress line."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from fishswarm.cli.common import UserError, prepare_folder
from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.study.progress import ProgressLine, bar

DEFAULT_GENERATIONS = 500
"""Generations a new learning run goes to unless ``--generations`` says otherwise."""


def learn_command(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm learn``."""
    try:
        from fishswarm.learning.coevolution import LearningSettings
    except ModuleNotFoundError as error:
        if error.name != "cma":
            raise
        raise UserError("Turing learning needs pycma: pip install -e '.[learn]'") from None
    from fishswarm.learning.arena import Arena
    from fishswarm.learning.checkpoint import checkpoint_progress
    from fishswarm.learning.session import CHECKPOINT, OUTPUTS, LearningError, learn

    named = {
        "behavior": args.behavior,
        "inputs": None
        if args.inputs is None
        else tuple(name.strip() for name in args.inputs.split(",") if name.strip()),
        "radii": args.radii,
        "models": args.models,
        "classifiers": args.classifiers,
        "seed": args.seed,
        "hall_of_fame": args.hall_of_fame,
        "soft_weight": args.soft_weight,
        "virulence": args.virulence,
        "trials": args.trials,
        "replica": args.replica,
        "radius_start": args.radius_start,
    }
    given = {name: value for name, value in named.items() if value is not None}
    values = dict(given)
    if "replica" in values:
        values["arena"] = Arena(replica=values.pop("replica"))
    # Resuming, the checkpoint's settings rule (what is given is only compared with them):
    # a value checked against a fresh run's defaults could be refused wrongly (a radius
    # start of an unbounded run against bounded radii).
    if args.resume and args.force:
        raise ConfigError(
            "--resume continues the learning run in --out and --force starts it over: give one"
        )
    for flag, value in (
        ("--generations", args.generations),
        ("--checkpoint-every", args.checkpoint_every),
    ):
        if value is not None and value < 1:
            raise ConfigError(f"{flag} must be at least 1, got {value}")
    settings = None
    if not args.resume:
        try:
            settings = LearningSettings(**values)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        if args.radii is not None and settings.radius_count == 0:
            # As a radius start is refused: a setting that would change nothing.
            raise ConfigError(
                f"--radii {args.radii} says how learned radii move, but the inputs "
                f"{','.join(settings.inputs)} learn none: give inputs that count neighbours "
                "within learned radii (e.g. speed,neighbors2), or leave it out"
            )
    held = [name for name in OUTPUTS if (args.out / name).is_file()]
    if not args.resume and not args.force and held:
        resumable = CHECKPOINT in held
        raise ConfigError(
            f"--out {args.out} holds a learning run ({', '.join(held)}): "
            + ("--resume continues it, " if resumable else "")
            + "--force starts over and replaces it, or give another --out"
        )
    prepare_folder(args.out, "--out")
    # A resumed run goes on to the generation it was started for, unless told otherwise.
    done, told = checkpoint_progress(args.out / CHECKPOINT) if args.resume else (None, None)
    generations = args.generations
    if generations is not None and done is not None and generations < done:
        raise ConfigError(
            f"--out {args.out} has done {done} generations, more than --generations "
            f"{generations}: give more to go on"
            + (f", or leave --generations out to go on to {told}" if told and told > done else "")
        )
    if generations is None:
        generations = told if told is not None else DEFAULT_GENERATIONS
    every = max(1, generations // 50)
    output = ProgressLine()

    def started(run: Any, resumed: bool) -> None:
        chosen = run.settings
        radii_setting = (
            f"radii {chosen.radii} from {chosen.first_radius:g} units"
            if chosen.radius_count
            else "no learned radii"
        )
        print(
            f"fishswarm learn: {chosen.behavior} ideal fish; classifier inputs "
            f"{','.join(chosen.inputs)}, "
            f"{radii_setting}; "
            f"{chosen.models} replicas × "
            f"{chosen.classifiers} classifiers, seed {chosen.seed}, hall of fame "
            f"{chosen.hall_of_fame}, soft weight {chosen.soft_weight:g}, virulence "
            f"{chosen.virulence:g}, {chosen.trials} start(s) a generation, {chosen.replica} "
            f"replicas; up to generation "
            f"{generations}; output {args.out}",
            file=sys.stderr,
        )
        if resumed:
            print(
                f"resumed from generation {run.generation} ({args.out / 'checkpoint.npz'})",
                file=sys.stderr,
            )

    def progress(run: Any, record: dict[str, float], seconds: float) -> None:
        done = run.generation
        if args.quiet or (done % every and done != generations):
            return
        left = (generations - done) * seconds
        line = (
            f"{bar(done, generations)} "
            f"generation {done}/{generations}  models best {record['model_best']:.3f} "
            f"mean {record['model_mean']:.3f}  classifiers best {record['classifier_best']:.3f} "
            f"mean {record['classifier_mean']:.3f}  {seconds:.2f} s/gen  ~{left / 60:.1f} min left"
        )
        output.show(line)

    try:
        summary = learn(
            settings,
            generations=generations,
            out=args.out,
            checkpoint_every=args.checkpoint_every,
            resume=args.resume,
            given=given,
            on_start=started,
            on_generation=progress,
        )
    except LearningError as error:
        raise ConfigError(str(error)) from None
    except KeyboardInterrupt:
        output.close()
        print(f"fishswarm: interrupted; {_kept(args.out, args.checkpoint_every)}", file=sys.stderr)
        return 130
    if output.tty and not args.quiet:
        sys.stderr.write("\n")
    ideal, replica = summary["ideal"], summary["replica"]
    print(
        f"done: {summary['generations']} generations in {args.out}\n"
        f"  final spacing  ideal {ideal['final_spacing']:.1f}  replica "
        f"{replica['final_spacing']:.1f} units\n"
        f"  final speed    ideal {ideal['final_speed']:.2f}  replica {replica['final_speed']:.2f}"
        " units/s\n"
        f"  learned radii  {radii_text(summary['radii'])}\n"
        f"  {target_text(summary['target'])}",
        file=sys.stderr,
    )
    return 0


def _kept(out: Path, every: int) -> str:
    """What an interrupted learning run kept in ``out``, and how to go on: its last
    checkpoint's generation; or nothing, before the first (then the folder it made empty
    is removed)."""
    from fishswarm.learning.checkpoint import checkpoint_progress
    from fishswarm.learning.session import CHECKPOINT

    done, _ = checkpoint_progress(out / CHECKPOINT)
    if done:
        return (
            f"{out / CHECKPOINT} holds generation {done} (checkpoints every {every}): "
            f"fishswarm learn --out {out} --resume goes on from there"
        )
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()
    return f"nothing kept: interrupted before the first checkpoint (every {every} generations)"


def radii_text(radii: dict[str, list[float]]) -> str:
    """``r1 45.2 ± 3.1, r2 80.0 ± 5.4 units`` (mean ± s.d. over the final classifiers)."""
    if not radii["mean"]:
        return "none (the classifiers did not count neighbours)"
    pairs = zip(radii["mean"], radii["sd"], strict=True)
    return ", ".join(f"r{n} {m:.1f} ± {sd:.1f}" for n, (m, sd) in enumerate(pairs, 1)) + " units"


def target_text(target: dict[str, Any]) -> str:
    """The replica against the target (spacing within 15 % from 5 to 15 s, final speed within
    0.5 units/s of the ideal fish's), in one line."""
    verdict = "met" if target["met"] else "missed"
    return (
        f"target {verdict}: spacing at most {100 * target['spacing_error']:.0f} % off the "
        f"ideal's from 5 to 15 s (≤ 15 %), final speed {target['speed_difference']:.2f} "
        "units/s apart (≤ 0.5)"
    )
