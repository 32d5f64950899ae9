"""``fishswarm experiment`` and ``fishswarm plot``: the study's experiments and pictures of runs."""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fishswarm.cli.common import (
    UserError,
    check_distinct_files,
    prepare_file,
    prepare_folder,
    read_recording_for,
)
from fishswarm.sim.scenario import (
    PROFILES,
    STUDY_CODE_SWITCHES,
    ConfigError,
    Scenario,
    behavior_text,
    switch_names,
)

if TYPE_CHECKING:
    from fishswarm.bluebot.vision import Vision
    from fishswarm.study.metrics import FormationTarget, FormationTargets, OrbitTarget
    from fishswarm.study.recording import Recording
    from fishswarm.study.sweep import Engine

MAX_FRAMES = 20_000
"""The most frames an animation may have (about half an hour at 10 frames a second)."""


def add_parsers(commands: Any) -> None:
    """Add the ``experiment`` and ``plot`` commands to the ``fishswarm`` parser."""
    from fishswarm.study.catalog import ENGINES, available

    names = ", ".join(available()) or "see experiments/"
    experiment = commands.add_parser(
        "experiment",
        help="run one of the study's experiments (tables and plots)",
        description="Run one of the study's simulator experiments: a scenario swept over a "
        "parameter, several seeds per value, settings in parallel on the available cores. "
        f"Experiments: {names} (the files in experiments/); or give the path of an experiment "
        "TOML file to run a changed copy. Writes table.md, table.csv, runs.csv, summary.json "
        "and plots (metrics vs parameter, metrics over time, tracks) to --out. Ctrl-C stops "
        "the sweep and writes the runs that finished, marked incomplete (exit 130).",
    )
    experiment.add_argument("name", help=f"experiment name ({names}) or TOML file")
    experiment.add_argument(
        "--seeds", type=int, help="runs per value (default: the experiment's, 5 in the study)"
    )
    experiment.add_argument("--duration", type=float, help="simulated time per run, s")
    experiment.add_argument(
        "--study-code",
        type=switch_names,
        metavar="SWITCH,…",
        help="run every run with these of the study code's ways instead of the paper's "
        f"equations ({', '.join(STUDY_CODE_SWITCHES)}; see docs/fidelity.md)",
    )
    experiment.add_argument(
        "--profile",
        choices=PROFILES,
        help="paper (default: the paper's equations) or study-code (every switch of "
        "--study-code: the model the study's published tables came from)",
    )
    experiment.add_argument(
        "--engine",
        choices=ENGINES,
        default="actors",
        help="actors: every run through the actor system over Zenoh (default); batch: the "
        "in-process batch engine, same trajectories, much faster for large sweeps",
    )
    experiment.add_argument(
        "--jobs", type=int, help="runs at a time in separate processes (default: one per core)"
    )
    experiment.add_argument(
        "--out",
        type=Path,
        help="output folder (default runs/experiments/NAME; for an experiment given as a file, "
        "the file's name without .toml, so that an edited copy keeps its own results)",
    )
    experiment.add_argument("--quiet", action="store_true", help="no progress lines")

    plot = commands.add_parser(
        "plot",
        help="draw a recorded run: tracks from above and from the side, metrics over time",
        description="Draw a recording made with 'fishswarm run --record' or 'fishswarm "
        "observe --record': every fish's track seen from above and from the side, and its "
        "metrics over time: the three mean distances and the neighbours seen; for circling "
        "fish the post, the radius against the expected one, revolutions and speed; for a "
        "formation the fish at the end coloured by role, the shape error against the "
        "tolerance, the share in place and the colliding pairs, each switch of shape marked.",
    )
    plot.add_argument("recording", type=Path, help="MCAP recording of a run")
    plot.add_argument(
        "--out", type=Path, help="picture to write, .png/.svg/.pdf (default RECORDING.png)"
    )

    animate = commands.add_parser(
        "animate",
        help="animate a recorded run: arrows in the tank, and what one fish sees",
        description="Animate a recording: the fish as arrows in the tank seen from above, "
        "from the side and from a circling camera, and through one fish's eyes (only the "
        "neighbours its vision model lets it see, at their bearing and elevation).",
    )
    animate.add_argument("recording", type=Path, help="MCAP recording of a run")
    animate.add_argument(
        "--out", type=Path, required=True, help="animation to write: FILE.gif or FILE.mp4"
    )
    animate.add_argument(
        "--fish", type=int, default=0, help="whose eyes the fourth view shows (default 0)"
    )
    animate.add_argument("--fps", type=int, default=10, help="frames per second (default 10)")
    animate.add_argument(
        "--speed",
        type=float,
        default=2.0,
        help=f"times real time (default 2; a speed that needs more than {MAX_FRAMES} frames "
        "is refused)",
    )
    animate.add_argument("--quiet", action="store_true", help="no progress line")


def engine_named(name: str) -> Engine:
    """The experiment engine ``--engine NAME`` stands for."""
    if name == "actors":
        from fishswarm.actors.runs import simulate_on_actors

        return simulate_on_actors
    from fishswarm.study.sweep import simulate_on_batch_engine

    return simulate_on_batch_engine


def _results_name(asked: str, name: str) -> str:
    """The folder an experiment's results go to, under runs/experiments: a shipped
    experiment's ``name``; an experiment given as a file, that file's stem (a copy of a
    shipped one, edited, keeps its ``name`` but must not write over the original's)."""
    path = Path(asked)
    return path.stem if path.suffix == ".toml" or path.exists() else name


def experiment(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm experiment NAME``."""
    from fishswarm.study.experiment import find
    from fishswarm.study.progress import ProgressLine, bar
    from fishswarm.study.report import write_report
    from fishswarm.study.sweep import SweepFailed, SweepInterrupted, sweep_experiment

    chosen = find(args.name)
    if args.seeds is not None and args.seeds < 1:
        raise ConfigError("--seeds must be at least 1")
    if args.jobs is not None and args.jobs < 1:
        raise ConfigError("--jobs must be at least 1")
    chosen = chosen.with_changes(
        seeds=args.seeds,
        duration=args.duration,
        study_code=args.study_code,
        profile=args.profile,
    )
    for warning in chosen.study_code_warnings():
        print(f"fishswarm experiment: warning: {warning}", file=sys.stderr)
    out = args.out or Path("runs/experiments") / _results_name(args.name, chosen.name)
    earlier = out / "summary.json"
    if earlier.is_file():
        # Results are cheap to make again, so they are replaced, but not without a word.
        print(
            f"fishswarm experiment: note: replacing the results in {out} (of "
            f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(earlier.stat().st_mtime))}); "
            "give --out to keep them",
            file=sys.stderr,
        )
    prepare_folder(out, "--out")
    total = len(chosen.runs())
    groups = f" for {' and '.join(chosen.group_names)}" if chosen.groups else ""
    print(
        f"fishswarm: {chosen.title}: {chosen.parameter} in "
        f"{', '.join(f'{v:g}' for v in chosen.values)}{groups}, {chosen.seeds} seed(s) "
        f"each, {total} runs, engine {args.engine}",
        file=sys.stderr,
    )
    output = ProgressLine()
    started = time.perf_counter()

    def show(done: int, runs: int, outcome: Any) -> None:
        if args.quiet:
            return
        elapsed = time.perf_counter() - started
        left = elapsed / done * (runs - done)
        output.show(
            f"{bar(done, runs)} run {done}/{runs}  {outcome.group + ' ' if outcome.group else ''}"
            f"{chosen.parameter}={outcome.value:g} "
            f"seed {outcome.seed}  {outcome.wall_time:.1f} s  ~{left:.0f} s left",
            last=done == runs,
        )

    try:
        outcomes = sweep_experiment(
            chosen, engine=engine_named(args.engine), jobs=args.jobs, on_run=show
        )
    except (SweepInterrupted, SweepFailed) as stop:
        output.close()
        failed = isinstance(stop, SweepFailed)
        how = f"a run failed ({stop})" if failed else "interrupted"
        if not stop.outcomes:
            print(f"fishswarm: {how} before the first run finished; nothing written",
                  file=sys.stderr)  # fmt: skip
            return 1 if failed else 130
        values = tuple(v for v in chosen.values if any(o.value == v for o in stop.outcomes))
        with _interrupt_deferred():
            write_report(
                chosen.with_changes(values=values), stop.outcomes, out, engine=args.engine,
                wall_time=time.perf_counter() - started, runs_total=stop.total,
            )  # fmt: skip
        if len(stop.outcomes) == stop.total:  # Ctrl-C as the last run ended: nothing lost
            print(f"fishswarm: {how} as the last run ended: all {stop.total} runs done; "
                  f"wrote them to {out}", file=sys.stderr)  # fmt: skip
        else:
            print(
                f"fishswarm: {how} after {len(stop.outcomes)} of {stop.total} runs; wrote "
                f"what finished to {out} (marked incomplete in table.md and summary.json)",
                file=sys.stderr,
            )
        return 1 if failed else 130
    wall_time = time.perf_counter() - started
    with _interrupt_deferred() as later:
        paths = write_report(chosen, outcomes, out, engine=args.engine, wall_time=wall_time)
    print((out / "table.md").read_text(encoding="utf-8"))
    print(
        f"{total} runs in {wall_time:.1f} s; wrote {', '.join(p.name for p in paths)} to {out}",
        file=sys.stderr,
    )
    if later:
        print("fishswarm: interrupted while the report was written: finished it first",
              file=sys.stderr)  # fmt: skip
        return 130
    return 0


@contextlib.contextmanager
def _interrupt_deferred() -> Iterator[list[int]]:
    """Hold Ctrl-C off while a report is written (a few seconds of tables and pictures),
    so that it is whole; the list yielded holds the signals that came meanwhile."""
    came: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda number, frame: came.append(number))
    try:
        yield came
    finally:
        # None: a handler not installed from Python; the default is the nearest we can give.
        signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)


def _tank_of(settings: dict[str, Any], position: np.ndarray) -> list[float]:
    """The recorded run's tank; for a recording that does not say (an observer's whose
    world never told it), the study's tank, grown to hold every recorded position."""
    if "tank" in settings:
        return [float(v) for v in settings["tank"]]
    from fishswarm.bluebot.parameters import Tank

    reach = np.nanmax(position.reshape(-1, 3), axis=0) if position.size else np.zeros(3)
    return [float(v) for v in np.maximum(np.asarray(Tank().size), reach)]


def _orbit_of(settings: dict[str, Any]) -> OrbitTarget | None:
    """The post and radius of a recorded orbit, milling or waltz run (None for other runs,
    and for recordings that do not say what ran: an observer's whose world never told it)."""
    from fishswarm.study.metrics import orbit_target_of

    try:
        return orbit_target_of(Scenario.as_recorded(settings))
    except ConfigError:
        return None


def _formations_of(recording: Recording) -> list[FormationTarget] | None:
    """The target of each snapshot of a recorded formation run: the shape the snapshot says
    the fish were told to take, or (recorded before snapshots said) the scenario's own
    switch. None for other runs, and for recordings that do not say what ran."""
    told = _shapes_told(recording)
    if told is None:
        return None
    targets, shapes = told
    return [targets.at(shape) for shape in shapes]


def _switches_of(recording: Recording) -> list[tuple[float, str]]:
    """When the shape a recorded formation's fish were told to take changed, s, and to
    which; none for other runs."""
    told = _shapes_told(recording)
    if told is None:
        return []
    _, shapes = told
    # A shape told is compared as a shape: an order for the configured one changes nothing.
    return [
        (snapshot.time, shape)
        for before, shape, snapshot in zip(
            shapes, shapes[1:], recording.snapshots[1:], strict=False
        )
        if shape != before
    ]


def _shapes_told(recording: Recording) -> tuple[FormationTargets, list[str]] | None:
    """A recorded formation run's targets and the shape its fish were told to take at each
    snapshot (:meth:`FormationTargets.shape_told
    <fishswarm.study.metrics.FormationTargets.shape_told>`); None for other runs, and for
    recordings that do not say what ran."""
    from fishswarm.study.metrics import FormationTargets

    try:
        ran = Scenario.as_recorded(recording.scenario)
    except ConfigError:
        return None
    targets = FormationTargets.of(ran)
    if targets is None:
        return None
    return targets, [targets.shape_told(s.formation, s.time) for s in recording.snapshots]


def plot(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm plot RECORDING``."""
    from fishswarm.study.figures import FiguresUnavailable, figure_of_run
    from fishswarm.study.metrics import (
        FORMATION_METRIC_NAMES,
        METRIC_NAMES,
        ORBIT_METRIC_NAMES,
        OrbitTracker,
    )

    out = args.out or args.recording.with_suffix(".png")
    if out.suffix not in (".png", ".svg", ".pdf"):
        raise ConfigError(f"--out must end in .png, .svg or .pdf, got {out.name}")
    check_distinct_files({"--out": out}, read={"the recording": args.recording})
    prepare_file(out, "--out", example="runs/latest.png")
    recording = read_recording_for(args.recording, at_least=1, purpose="draw")
    arrays = recording.arrays()
    metrics = {
        name: np.array([m[name] for m in recording.metrics])
        for name in (*METRIC_NAMES, "neighbors_seen")
    }
    settings = recording.scenario
    orbit = _orbit_of(settings)
    formations = _formations_of(recording)
    formation = None if formations is None else formations[-1]
    switches = _switches_of(recording) if formations is not None else []
    if formations is not None:
        series = [
            target.metrics(s.position)
            for target, s in zip(formations, recording.snapshots, strict=True)
        ]
        metrics |= {name: np.array([m[name] for m in series]) for name in FORMATION_METRIC_NAMES}
    if orbit is not None:
        # From the positions, so that recordings made before the observer measured orbits
        # are drawn the same way.
        tracker = OrbitTracker(orbit)
        series = [tracker.metrics(s.ids, s.position, s.time) for s in recording.snapshots]
        metrics |= {name: np.array([m[name] for m in series]) for name in ORBIT_METRIC_NAMES}
    title = (
        f"{_fish_recorded(arrays['ids'])}, "
        f"{behavior_text(settings.get('behavior'), settings.get('behavior_settings'))}, "
        f"seed {settings.get('seed', '?')} ({args.recording.name})"
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        tank = _tank_of(settings, arrays["pos"])
        figure = figure_of_run(
            arrays["t"], arrays["pos"], metrics, tank, title=title, orbit=orbit,
            formation=formation, switches=switches,
        )  # fmt: skip
        figure.savefig(out, dpi=110)
    except FiguresUnavailable as error:
        raise UserError(str(error)) from None
    print(f"wrote {out}", file=sys.stderr)
    return 0


def _rounded_up(value: float, digits: int = 3) -> float:
    """``value`` rounded up to ``digits`` significant digits (advice that is then taken
    must not fall short)."""
    unit = 10.0 ** (math.floor(math.log10(value)) - digits + 1)
    # Less a hair, so that a value already on the grid (0.002 as 200.00000000000003 units)
    # is not pushed a step up.
    return float(f"{math.ceil(value / unit - 1e-9) * unit:.{digits}g}")


def _fish_recorded(ids: np.ndarray) -> str:
    """How many fish a recording holds, for a title: every fish it saw, those that joined
    later (a robot, a fish started by hand) too, not the run's configured count."""
    return f"{ids.size} fish"


def animate(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm animate RECORDING --out FILE``."""
    from fishswarm.study.animation import (
        AnimationError,
        AnimationInterrupted,
        AnimationUnavailable,
        frame_duration,
        resample,
    )
    from fishswarm.study.animation import animate as make_animation
    from fishswarm.study.progress import ProgressLine, bar

    if not 0 < args.speed < math.inf:
        raise ConfigError(
            f"--speed must be a positive finite number (times real time), got {args.speed:g}"
        )
    try:
        shown = frame_duration(args.out.suffix, args.fps)
    except AnimationError as error:
        raise ConfigError(f"--fps: {error}") from None
    check_distinct_files({"--out": args.out}, read={"the recording": args.recording})
    prepare_file(args.out, "--out", example="runs/latest.gif")
    recording = read_recording_for(args.recording, at_least=2, purpose="animate")
    arrays = recording.arrays()
    settings = recording.scenario
    span = float(arrays["t"][-1] - arrays["t"][0])
    if span / (args.speed * shown) > MAX_FRAMES:
        raise ConfigError(
            f"--speed {args.speed:g} makes {span / (args.speed * shown):.0f} frames of this "
            f"{span:g}-s run, more than {MAX_FRAMES}: give --speed "
            f"{_rounded_up(span / (MAX_FRAMES * shown)):g} or more"
        )
    frames = resample(
        arrays["t"], arrays["pos"], arrays["yaw"], arrays["ids"], step=args.speed * shown
    )
    vision = _vision_of(settings)
    output = ProgressLine()
    started = time.perf_counter()

    def show(done: int, total: int) -> None:
        if not args.quiet and (done % 10 == 0 or done == total):
            left = (time.perf_counter() - started) / done * (total - done)
            output.show(
                f"{bar(done, total)} frame {done}/{total}  ~{_duration_text(left)} left",
                last=done == total,
            )

    try:
        make_animation(
            frames,
            tank=_tank_of(settings, arrays["pos"]),
            vision=vision,
            viewer=args.fish,
            out=args.out,
            fps=args.fps,
            title=f"{_fish_recorded(arrays['ids'])}, "
            f"{behavior_text(settings.get('behavior'), settings.get('behavior_settings'))}",
            on_frame=show,
            **_animated_formation(recording),
        )
    except AnimationUnavailable as error:
        raise UserError(str(error)) from None
    except AnimationError as error:
        raise ConfigError(str(error)) from None
    except AnimationInterrupted as stop:
        output.close()
        held = (
            f"{args.out} holds its first {stop.written} frames"
            if stop.written and args.out.exists() and args.out.stat().st_size
            else "nothing written"
        )
        print(f"fishswarm: interrupted at frame {stop.written} of {stop.total}; {held}",
              file=sys.stderr)  # fmt: skip
        return 130
    print(f"wrote {args.out} ({frames.t.size} frames)", file=sys.stderr)
    return 0


def _duration_text(seconds: float) -> str:
    """``42 s``, ``3.5 min`` or ``1.2 h``: how long is left, at a glance."""
    if seconds < 100:
        return f"{seconds:.0f} s"
    if seconds < 6000:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def _vision_of(settings: dict[str, Any]) -> Vision:
    """The geometric vision model the recorded run's fish saw with (range, blind spot,
    occlusion, the study code's Manhattan range), without noise: the fish's-eye view draws
    where the neighbours it sees are. A recording that does not say what ran (an
    observer's whose world never told it) gets a BlueBot's; a run with camera vision, the
    geometric model of the same settings."""
    from fishswarm.bluebot.vision import Vision

    try:
        ran = Scenario.as_recorded(settings)
    except ConfigError:
        return Vision()
    return ran.vision().exact()


def _animated_formation(recording: Recording) -> dict[str, Any]:
    """The animation's formation arguments: the first snapshot's target, and each later
    target from the time the fish were told to take it."""
    formations = _formations_of(recording)
    if formations is None:
        return {}
    times = [snapshot.time for snapshot in recording.snapshots]
    switches = [
        (time, target)
        for time, target, before in zip(times[1:], formations[1:], formations[:-1], strict=True)
        if target is not before
    ]
    return {"formation": formations[0], "switches": switches}
