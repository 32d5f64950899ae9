"""What each ``fishswarm`` command does: the actors run from the command line."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import functools
import json
import math
import signal
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import trio
import zenoh

from fishswarm.actors.channel import Channel
from fishswarm.actors.control import (
    UnreadableSettings,
    ask_scenario,
    run_control,
    wait_for_scenario,
)
from fishswarm.actors.fish import Fish, FishSettings
from fishswarm.actors.launcher import (
    EXIT_DEGRADED,
    EXIT_OK,
    EXIT_WORKER_DIED,
    LaunchSettings,
    RunResult,
    WorkerFailed,
    launch_swarm,
    shared_memory_pool_bytes,
    where_fish_run,
)
from fishswarm.actors.observer import WORLD_END_SETTLE, Observer, Progress
from fishswarm.actors.security import (
    ACCESS_FILE,
    AUTHORITY,
    DEFAULT_DAYS,
    SecurityError,
    certified_subjects,
    init_secure,
    observer_subject,
    robot_subject,
    router_names,
    session_security,
)
from fishswarm.actors.session import SessionSettings, open_session, reaches_router
from fishswarm.actors.world import PULSE_PERIOD, StartTimeout, World, WorldSettings
from fishswarm.actors.zenoh_bus import ZenohBus, query
from fishswarm.behaviors.formation import FormationParams, formation_params
from fishswarm.bluebot.parameters import BODY_LENGTH
from fishswarm.cli.common import USER_ERRORS as COMMON_ERRORS
from fishswarm.cli.common import (
    UserError,
    check_distinct_files,
    check_secured_endpoint,
    client_settings,
    endpoint_of,
    prepare_file,
    read_recording_for,
    refuse_unused,
    run_trio,
    secure_extra,
)
from fishswarm.formations.local import LOCAL_SHAPES
from fishswarm.formations.maps import MAPS, target_map
from fishswarm.protocols.codec import MessageError, decode, encode
from fishswarm.protocols.keys import KeySpace, fish_id_of
from fishswarm.protocols.messages import ControlReply, ControlRequest, RobotOrder
from fishswarm.sim import kernels
from fishswarm.sim.decision_kernels import prepare, with_compiled_decisions
from fishswarm.sim.physics import WorldParams, spawn_spacing, start_layout
from fishswarm.sim.scenario import ConfigError, Scenario, behavior_text
from fishswarm.study.live_view import open_live_view
from fishswarm.study.progress import ProgressLine, bar, ids_text
from fishswarm.study.recording import (
    RecordingError,
    export_csv,
    export_npz,
    open_recorder,
)
from fishswarm.study.scene import stage_of
from fishswarm.study.view_settings import ViewError, ViewSettings


def _fish_subject(args: argparse.Namespace) -> str:
    """The certificate a ``fishswarm fish`` process uses: its robot's (one fish per process
    in a secured swarm)."""
    if getattr(args, "secure", None) is not None and len(args.ids) != 1:
        raise ConfigError(
            "with --secure, serve one fish per process (its robot's certificate, robot-ID): "
            f"got --id {' --id '.join(map(str, args.ids))}"
        )
    return robot_subject(args.ids[0])


USER_ERRORS = (*COMMON_ERRORS, StartTimeout, RecordingError, WorkerFailed, ViewError)
"""Errors the swarm's commands report as a message, not a traceback."""


def _run_trio(main: Callable[[], Any]) -> Any:
    """Run ``main`` under trio; errors a user can fix come out as one :class:`UserError`."""
    return run_trio(main, errors=USER_ERRORS)


def progress_printer(
    ticks: int | None, output: ProgressLine | None = None
) -> Callable[[Progress], None]:
    """Print a progress line per snapshot (about 20 lines for long runs; one updating line on
    a terminal). With ``ticks`` None (an observer that does not know when the run ends),
    no bar and no total: every snapshot on a terminal, every tenth otherwise. The caller
    that passes ``output`` closes it (:meth:`~ProgressLine.close` ends an updating line
    the run left open)."""
    output = ProgressLine(sys.stderr) if output is None else output
    every = (1 if output.tty else 10) if ticks is None else max(1, ticks // 20)

    def show(progress: Progress) -> None:
        if progress.tick % every and progress.tick != ticks:
            return
        m = progress.metrics
        # An observer that came after the tick it was to stop at sees one snapshot past it.
        late = ticks is not None and progress.tick > ticks
        prefix = bar(progress.tick, ticks) + " " if ticks and not late else ""
        measures = (
            "no fish in the world"
            if progress.fish == 0
            else f"radius {m['radius']:.3f} m  revolutions {m['revolutions']:.2f}  "
            f"speed {m['speed']:.3f} m/s"
            if "radius" in m
            else f"centroid {m['centroid_distance']:.3f} m  "
            f"pairwise {m['pairwise_distance']:.3f} m  "
            f"nearest {m['nearest_neighbor_distance']:.3f} m"
        )
        count = (
            f"{progress.tick}"
            if ticks is None
            else f"{progress.tick} (after the last tick asked for, {ticks})"
            if late
            else f"{progress.tick:>{len(str(ticks))}}/{ticks}"
        )
        seen = f"  seen {m['neighbors_seen']:.1f}" if progress.fish else ""
        line = (
            f"{prefix}tick {count}  t={progress.time:7.1f} s  fish {progress.fish}  "
            f"{measures}{seen}"
        )
        output.show(line, last=ticks is not None and progress.tick >= ticks)

    return show


CROWDED_SPACING = BODY_LENGTH / 4
"""Fish starting closer than this to their nearest neighbour (the median fish) are warned
of, m: a quarter of a BlueBot's length, about half the spacing of the study's own start."""


def start_warnings(scenario: Scenario) -> list[str]:
    """What to say of how the fish start, each with the way out: put on the tank's walls by
    a start ball larger than the tank, or piled on one another (hundreds of fish in the
    study's start ball)."""
    params = WorldParams.of(scenario)
    layout = start_layout(params, scenario.fish)
    warnings = []
    if scenario.fish >= kernels.COMPILED_MIN_FISH and not kernels.available():
        warnings.append(
            f"numba is not installed: the world sees {scenario.fish} fish on the numpy path, "
            "5-7 times slower than compiled from 1 000 fish on, and seconds a tick where every "
            "fish sees every other (4.4 s at 1 000 fish in the study's tank, 33 s at 2 000): "
            "pip install -e '.[fast]'"
        )
    # Past the corners, the ball holds the whole tank: a larger one spreads no fish more,
    # it only puts more on the walls. (Within them some may start on a wall, as the
    # study's formation start of 1.3 m puts them.)
    # Rounded down as it is shown: the radius the warning gives must not set it off again.
    corner = math.floor(float(np.linalg.norm(scenario.tank)) / 2 * 100) / 100
    past_walls = scenario.spawn_region == "ball" and params.spawn_radius > corner
    if past_walls:
        warnings.append(
            f"the start ball's radius, {params.spawn_radius:g} m, reaches past the tank's "
            f"corners ({corner:g} m from its centre), and {layout.on_walls} of the "
            f"{scenario.fish} fish start on its walls: give a --spawn-radius of at most "
            f"{corner:g} m, or --spawn tank to spread them evenly over the tank"
        )
    if layout.spacing >= CROWDED_SPACING:
        return warnings
    study = Scenario()  # the study's dispersion start, the tightest of its set-ups
    usual = spawn_spacing(WorldParams.of(study), study.fish)
    if scenario.spawn_region == "tank":
        way_out = "a larger tank (tank = [x, y, z] in a --config file)"
    else:
        way_out = (
            "--spawn tank (anywhere in the tank; with a larger tank = [x, y, z] in a "
            "--config file for more room)" + ("" if past_walls else " or a larger --spawn-radius")
        )
    warnings.append(
        f"the {scenario.fish} fish start a median {layout.spacing * 100:.1f} cm from their "
        f"nearest neighbour (a BlueBot is {BODY_LENGTH * 100:.0f} cm long; the study's "
        f"dispersion start puts {study.fish} fish {usual * 100:.0f} cm apart): spread them "
        f"with {way_out}"
    )
    return warnings


def _formations_told(scenario: Scenario) -> list[FormationParams]:
    """The parameters of each formation a run's fish are told to take: the one they start
    with, and the one they switch to (none but a formation run's)."""
    if scenario.behavior != "formation":
        return []
    first = formation_params(dataclasses.asdict(scenario))
    shapes = dict.fromkeys([first.shape, scenario.switch_formation or first.shape])
    return [dataclasses.replace(first, shape=shape) for shape in shapes]


def local_shape_warning(scenario: Scenario) -> str | None:
    """What to say when a formation's local shape (the shape it starts with, or switches
    to) needs more fish than the run has: no fish can complete it, and its shape error is
    not measured. None when it does not."""
    short = [
        (told.shape, LOCAL_SHAPES[told.shape] + 1)
        for told in _formations_told(scenario)
        if told.shape in LOCAL_SHAPES and told.count < LOCAL_SHAPES[told.shape] + 1
    ]
    if not short:
        return None
    needs = "; ".join(f"a {shape} needs at least {fish} fish" for shape, fish in short)
    return (
        f"{needs}: with {scenario.fish} fish none can complete "
        f"{'them' if short[1:] else 'it'}, and the shape error is not measured (give more "
        "--fish)"
    )


def map_warnings(scenario: Scenario) -> list[str]:
    """What to say when a formation's places cannot all be held: a global map (the shape
    it starts with, or switches to) larger than the tank, or places closer than a BlueBot
    is long (neighbours in place touch, and count as colliding)."""
    told = _formations_told(scenario)
    if not told:
        return []
    warnings = []
    spacing, heading = told[0].spacing, told[0].orientation
    if spacing < BODY_LENGTH:
        warnings.append(
            f"the spacing, {spacing:g} m, is less than a BlueBot's length "
            f"({BODY_LENGTH * 100:.0f} cm): fish in their places would touch (give a --spacing "
            f"of at least {BODY_LENGTH:g} m)"
        )
    turn = np.array(
        [[math.cos(heading), -math.sin(heading)], [math.sin(heading), math.cos(heading)]]
    )
    tank = np.asarray(scenario.tank)
    for params in told:
        if params.shape not in MAPS:
            continue
        slots = target_map(params.shape, params.count, spacing=spacing)
        turned = np.column_stack([slots[:, :2] @ turn.T, slots[:, 2]])
        span = np.ptp(turned, axis=0)
        if (span > tank).any():
            warnings.append(
                f"a {params.shape} of {params.count} fish at a spacing of {spacing:g} m spans "
                f"{' × '.join(f'{v:.2f}' for v in span)} m, more than the tank's "
                f"{' × '.join(f'{v:g}' for v in tank)} m: the fish cannot all take their places "
                "(give fewer --fish, a smaller --spacing, or another --formation)"
            )
    return warnings


def _warn_of_the_start(command: str, scenario: Scenario) -> None:
    warnings = [*start_warnings(scenario), local_shape_warning(scenario), *map_warnings(scenario)]
    for warning in warnings:
        if warning is not None:
            print(f"fishswarm {command}: warning: {warning}", file=sys.stderr)


def _watchdog_warning(timeout: float, scenario: Scenario) -> str | None:
    """What is wrong with a fish watchdog that would stop the fins between two signs of
    life of the world (None: nothing): its pulse comes every PULSE_PERIOD, and in real
    time a perception every control period; in lockstep or jitter (not paced by the wall
    clock) a slow tick may leave only the pulse. Such a run ends 'degraded', which a test
    of the watchdog may want."""
    gap = PULSE_PERIOD
    why = f"its pulse comes every {PULSE_PERIOD:g} s"
    if scenario.time_mode == "realtime" and scenario.control_period < PULSE_PERIOD:
        gap = scenario.control_period
        why = f"a perception comes every control period, {gap:g} s"
    if timeout > gap:
        return None
    return (
        f"--perception-timeout {timeout:g} will stop the fins between two signs of life of the "
        f"world ({why}), and the run will end 'degraded' (exit 4): give more than {gap:g} s, "
        f"e.g. --perception-timeout {2 * gap:g}"
    )


def run(args: argparse.Namespace, scenario: Scenario) -> int:
    """``fishswarm run``."""
    if not args.view:
        refuse_unused(args, VIEW_FLAGS, applies="with --view", fix="add --view, or leave {it} out")
    if args.procs is not None and args.procs < 0:
        raise ConfigError(
            f"--procs must be 0 (the fish in this process) or more worker processes, got "
            f"{args.procs}"
        )
    if not args.perception_timeout > 0:
        raise ConfigError(
            f"--perception-timeout must be a positive number of seconds, got "
            f"{args.perception_timeout:g}"
        )
    if (warning := _watchdog_warning(args.perception_timeout, scenario)) is not None:
        print(f"fishswarm run: warning: {warning}", file=sys.stderr)
    scenario.fish_params()  # reads a replica model now: a bad one is a usage error, not a crash
    check_distinct_files({"--record": args.record, "--summary": args.summary})
    prepare_file(args.record, "--record", example="runs/latest.mcap")
    prepare_file(args.summary, "--summary", example="runs/latest.json")
    settings = LaunchSettings(
        scenario=scenario,
        procs=args.procs,
        listen=endpoint_of(args.listen, "--listen"),
        record=args.record,
        summary=args.summary,
        start_timeout=args.start_timeout,
        perception_timeout=args.perception_timeout,
        log_level=args.log_level,
        handle_signals=True,
        secure=args.secure,
    )
    check_secured_endpoint(settings.listen, flag="--listen", secured=args.secure is not None)
    if args.secure is not None:  # what the router needs is said before the run is announced
        try:
            session_security(args.secure, "router", router=True)
        except SecurityError as error:
            raise UserError(str(error)) from None
    print(
        f"fishswarm: {scenario.fish} fish, "
        f"{behavior_text(scenario.behavior, scenario.behavior_settings)}, "
        f"{scenario.duration:g} s at "
        f"{1 / scenario.control_period:g} Hz, seed {scenario.seed}, "
        f"{where_fish_run(settings.worker_processes)}, listening on "
        f"{settings.listen}",
        file=sys.stderr,
    )
    _warn_of_the_start("run", scenario)
    show = None if args.quiet else progress_printer(scenario.ticks)
    with contextlib.ExitStack() as serving:
        view = None
        if args.view:
            try:
                view = serving.enter_context(open_live_view(view_settings(args), name="run"))
            except ViewError as error:
                raise UserError(str(error)) from None
            view.show_stage(stage_of(scenario))
            print(f"open {view.settings.page_url} in a browser to watch", file=sys.stderr)
        on_scene = None if view is None else view.show
        result = _run_trio(lambda: launch_swarm(settings, on_progress=show, on_scene=on_scene))
        _report(result)
        if view is not None and result.summary["status"] != "interrupted":
            # The run is over: its exit code stands, whenever the Ctrl-C comes (even on the
            # heels of the announcement, as a script's would). A Ctrl-C that interrupted
            # the run ends the view too: one is enough.
            with contextlib.suppress(KeyboardInterrupt):
                wait_for_ctrl_c("fishswarm run: the view stays up until Ctrl-C")
    return int(result.exit_code)


def wait_for_ctrl_c(announcement: str | None = None) -> None:
    """Sleep until Ctrl-C or SIGTERM (either a KeyboardInterrupt) while other threads
    serve; ``announcement`` goes to stderr once both are caught."""

    def interrupt(number: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        if announcement is not None:
            print(announcement, file=sys.stderr)
        while True:
            # Plain sleeps: a KeyboardInterrupt inside threading.Event.wait can leave its
            # lock broken ("release unlocked lock").
            time.sleep(3600)
    finally:
        signal.signal(signal.SIGTERM, previous)


VIEW_FLAGS = {"host": "--host", "web_port": "--web-port", "grpc_port": "--grpc-port"}
"""Where a live view is served: each argument's name and flag."""


def view_settings(args: argparse.Namespace) -> ViewSettings:
    """Where ``--host``, ``--web-port`` and ``--grpc-port`` say to serve a live view (the
    defaults for those not given)."""
    given = {name: getattr(args, name) for name in VIEW_FLAGS if getattr(args, name) is not None}
    try:
        return ViewSettings(**given)
    except ValueError as error:  # in the command line's words: --web-port, not web_port
        message = str(error).replace("web_port", "--web-port").replace("grpc_port", "--grpc-port")
        raise ConfigError(f"--{message}" if message.startswith("host ") else message) from None


def refuse_observer_name(args: argparse.Namespace) -> None:
    """Refuse ``--name`` without ``--secure``: it picks an observer's certificate."""
    if args.secure is None:
        refuse_unused(
            args,
            {"name": "--name"},
            applies="with --secure (it picks an observer certificate of a secured swarm)",
            fix="add --secure DIR, or leave {it} out",
        )


def _report(result: RunResult) -> None:
    """Say how a run ended."""
    summary = result.summary
    if summary["status"] == "interrupted":
        held = (
            "recording and summary hold the run so far"
            if summary.get("recording")
            else "nothing recorded (the recording file is as it was); the summary holds the run"
        )
        print(f"\nfishswarm run: interrupted; {held}", file=sys.stderr)
    # Each failure of the fish was said as it was seen (the launcher logs it).
    print(_summary_text(summary), file=sys.stderr)
    if result.exit_code == EXIT_WORKER_DIED:
        who = "a worker process died" if summary["procs"] else "the fish failed"
        how = (
            f"the run stopped at tick {summary['counts']['ticks']}, every fish lost"
            if summary["status"] == "failed"
            else "the run finished without those fish"
        )
        print(f"fishswarm run: {who}; {how} (see 'lost' in the summary)", file=sys.stderr)


def _measured(
    value: float | None, form: str, unit: str = "", missing: str = "none (no fish)"
) -> str:
    """A summary's number with its unit, or what to say where a world without fish left it
    undefined (None in JSON, NaN in memory)."""
    return missing if value is None or not math.isfinite(value) else f"{value:{form}}{unit}"


def _ninety_text(ninety: float | None, switched_at: float | None) -> str:
    """When 90 % of the fish were first in their places, counted from the last switch of
    shape (``switched_at``; None: never switched)."""
    if switched_at is None:
        return "never 90 %" if ninety is None else f"90 % first at {ninety:g} s"
    if ninety is None:
        return "never 90 % since the switch"
    return f"90 % first at {ninety:g} s, {ninety - switched_at:g} s after the switch"


def _summary_text(summary: dict[str, Any]) -> str:
    lines = [f"status: {summary['status']}"]
    stops = summary.get("fish", {}).get("watchdog_stops", 0)
    if stops:
        lines[0] += (
            f" — fish were stopped {stops} time(s) by their watchdog (no perception in time), "
            "so their fins were off for part of the run"
        )
    if summary["status"] == "degraded" and summary["lost"]:
        lost = [(f["id"], f["tick"], f["reason"]) for f in summary["lost"]]
        joined = [(f["id"], f["tick"]) for f in summary.get("joined", [])]
        lines[0] += f" — fish were lost on the way: {_lost_text(lost, joined)}"
    orbit = summary.get("orbit")
    if orbit:
        post = orbit["post"]
        around = (
            f"around the post at ({post[0]:.2f}, {post[1]:.2f}) m"
            if post is not None
            else "around the partners' centre"
        )
        lines.append(f"  orbit {around}, R {orbit['orbit_radius']:g} m:")
        lines.append(
            f"    radius {orbit['radius']:.3f} m (± {orbit['radius_wobble']:.3f} m in time, "
            "2nd half), "
            f"{orbit['revolutions']:.2f} revolutions, speed {orbit['speed']:.3f} m/s, "
            f"collisions {orbit['collisions']:.0f} pair-ticks"
        )
    for name, values in summary["metrics"].items():
        if orbit and name != "neighbors_seen":
            continue  # the distances say little about circling fish (one fish: all zero)
        change = values["change_percent"]
        change_text = "" if change is None else f" ({change:+.1f} %)"
        initial, final = (_measured(values[when], ".3f") for when in ("initial", "final"))
        lines.append(f"  {name}: {initial} → {final}{change_text}")
    formation = summary.get("formation")
    if formation:
        ninety = formation["time_to_90_percent_joined"]
        # Every shape the fish were told, from when: the metrics measure the last.
        told = " → ".join(
            told["shape"] + (f" (from {told['time']:g} s)" if turn else "")
            for turn, told in enumerate(formation.get("shapes", []))
        )
        joined = formation["joined_fraction"]
        shapes = formation.get("shapes", [])
        switched, told_last = len(shapes) > 1, shapes[-1]["time"] if shapes else 0.0
        lines.append(
            f"  formation {told}: shape error "
            f"{_measured(formation['shape_error'], '.3f', ' m', 'not measured (too few fish)')}, "
            f"{_measured(joined and 100 * joined, '.0f', ' % joined', 'none joined (no fish)')} "
            f"({_ninety_text(ninety, told_last if switched else None)}), "
            f"lattice energy {_measured(formation['lattice_energy'], '.3f')}, "
            f"collisions at most {_measured(formation['most_collisions'], '.0f')}"
        )
        if formation.get("fitness_total") is not None:
            lines.append(
                f"  the study's fitness ΣF: {formation['fitness']:.2f} m at the end, "
                f"{formation['fitness_total']:.1f} m summed over {formation['snapshots']} snapshots"
                + (f" (from {told_last:g} s, the last shape's)" if switched else "")
            )
    effort = summary.get("effort")
    if effort:
        lines.append(
            f"  effort: {effort['school']:.0f} gain-weighted fin beats in all, the busiest fish "
            f"{effort['spread']:.2f}× the mean"
        )
    sight = summary.get("vision")
    if sight and sight["recall"] is not None:
        lines.append(
            f"  camera vision: found {sight['recall']:.0%} of the neighbours the geometric "
            f"model sees, {sight['false']} false detections of {sight['detected']}"
            + (
                f", range error {sight['mean_range_error']:.1%} on average"
                if sight["mean_range_error"] is not None
                else ""
            )
        )
    counts = summary["counts"]
    rejected = sum(counts["rejected"].values())
    rtf = summary["real_time_factor"]
    lines.append(
        f"  ticks {counts['ticks']}, messages {counts['messages']}, rejected {rejected}, "
        f"lost fish {counts['lost_fish']}, broadcasts {counts['broadcasts']}, "
        f"deliveries {counts['deliveries']}"
        + (
            f" ({counts['unannounced_broadcasts']} broadcasts not delivered: sent with a late "
            "or lost command)"
            if counts.get("unannounced_broadcasts")
            else ""
        )
        + f", wall {summary['wall_time']:.2f} s"
        + (
            f" (ticks {summary['loop_time']:.2f} s of it"
            + (f", paused {paused:.2f} s" if (paused := summary.get("paused_time", 0.0)) else "")
            + f": {rtf:.{2 if rtf < 1 else 0}f}× real time)"
            if rtf
            else ""
        )
    )
    world_time = summary.get("world_time") or {}
    if world_time.get("physics"):
        lines.append(
            "  the world's steps (medians): physics "
            f"{world_time['physics'] * 1e3:.1f} ms, vision {world_time['vision'] * 1e3:.1f} ms, "
            f"perceptions out {world_time['perceptions'] * 1e3:.1f} ms"
        )
    answer = summary.get("answer_time") or {}
    if answer.get("median"):
        lines.append(
            f"  fish answered a tick in {answer['median'] * 1e3:.1f} ms (median), "
            f"{answer['p90'] * 1e3:.1f} ms (90 %)"
        )
    if summary.get("recording"):
        lines.append(f"  recording: {summary['recording']}")
    if summary.get("summary"):
        lines.append(f"  summary: {summary['summary']}")
    return "\n".join(lines)


def _say_recording(observers: list[Observer], path: Path | None) -> None:
    """Name the recording the observer of a command wrote, if it wrote one (a run that
    never started leaves the file as it was)."""
    recorder = observers[0].recorder if observers else None
    if recorder is not None and recorder.begun:
        print(f"recording: {path}", file=sys.stderr)


def _lost_text(lost: list[tuple[int, int, str]], joined: list[tuple[int, int]]) -> str:
    """Fish lost on the way, (id, tick, why) each, as a run's last words say them, with
    when each came back, if it did (``joined``: (id, tick) of the fish that joined late)."""
    words = []
    for fish_id, tick, why in lost:
        back = [later for joiner, later in joined if joiner == fish_id and later > tick]
        words.append(
            f"{fish_id} at tick {tick} ({why}" + (f"; back at tick {back[0]})" if back else ")")
        )
    return ", ".join(words)


def fish(args: argparse.Namespace, scenario: Scenario) -> int:
    """``fishswarm fish``: fish actors alone, connected to a router."""
    # Compiled decisions as the launcher's workers have them (the same bits either way).
    params = with_compiled_decisions(scenario.fish_params(), scenario.fish)
    keys = scenario.keys

    repeated = sorted({fish_id for fish_id in args.ids if args.ids.count(fish_id) > 1})
    if repeated:
        raise ConfigError(f"--id {ids_text(repeated)} given more than once: give each fish once")
    try:
        settings = FishSettings(
            tuple(args.ids),
            params,
            keys,
            perception_timeout=args.perception_timeout,
            school=args.school,
        )
    except ValueError as error:
        raise ConfigError(str(error)) from None
    prepare(params)

    async def main() -> None:
        async with (
            open_session(client_settings(args, _fish_subject(args), swarm=keys.swarm)) as session,
            trio.open_nursery() as nursery,
        ):
            served = await trio.to_thread.run_sync(_served_fish, session, keys)
            _refuse_served(served, args.ids, args.school)
            await nursery.start(Fish(settings).run, ZenohBus(session))
            print(f"fish {', '.join(map(str, args.ids))} up on {args.connect}", file=sys.stderr)

    _run_trio(main)
    return 0


SERVED_QUERY_TIMEOUT = 2.0
"""How long ``fishswarm fish`` asks the router which fish are served already, s."""


def _served_fish(session: zenoh.Session, keys: KeySpace) -> list[tuple[int, str | None]]:
    """The fish whose liveliness tokens are up now: each id with its school (None: on its
    own keys)."""
    served = []
    for reply in session.liveliness().get(keys.alive_all("fish"), timeout=SERVED_QUERY_TIMEOUT):
        if reply.ok is None:
            continue
        try:
            member = keys.parse_alive(str(reply.ok.key_expr))
        except ValueError:
            continue
        fish_id = fish_id_of(member.member_id)
        if fish_id is not None:
            served.append((fish_id, member.school))
    return served


def _refuse_served(
    served: list[tuple[int, str | None]], ids: list[int], school: str | None
) -> None:
    """Refuse to serve fish another process serves already, or a school it serves.

    Raises:
        ConfigError: naming them: two processes of one fish both answer for it; two of one
            school each refuse the world's batch for both, and the school's fish are lost.
    """
    taken = sorted({fish_id for fish_id, _ in served} & set(ids))
    if taken:
        raise ConfigError(
            f"fish {ids_text(taken)} served already, by another process: give each "
            "'fishswarm fish' process its own ids (a process that just ended is forgotten "
            "within seconds)"
        )
    others = sorted({fish_id for fish_id, theirs in served if school and theirs == school})
    if others:
        raise ConfigError(
            f"school {school!r} is served already, by another process with fish "
            f"{ids_text(others)}: give each 'fishswarm fish' process its own --school"
        )


def world(args: argparse.Namespace, scenario: Scenario) -> int:
    """``fishswarm world``: the world alone."""
    _warn_of_the_start("world", scenario)
    actor = World(
        WorldSettings(
            scenario,
            tuple(range(scenario.fish)),
            args.start_timeout,
            turn_delay=args.turn_delay,
            vouched_only=args.secure is not None,
        )
    )
    show = None if args.quiet else progress_printer(scenario.ticks)

    async def main() -> None:
        settings = dataclasses.replace(
            client_settings(args, "world", swarm=scenario.swarm),
            shared_memory_pool_bytes=shared_memory_pool_bytes(scenario.fish),
        )
        # The session first: a world that cannot reach its router writes no recording.
        async with open_session(settings) as session, contextlib.AsyncExitStack() as files:
            recorder = (
                files.enter_context(open_recorder(args.record, scenario.to_dict()))
                if args.record is not None
                else None
            )
            observer = Observer.of(
                scenario, recorder=recorder, on_progress=show, observer_id="world-cli"
            )
            observer.world_run = actor.run_id  # its world's run only, not another's on the router
            observers.append(observer)
            async with trio.open_nursery() as nursery:
                bus = ZenohBus(session)
                await nursery.start(observer.run, bus)
                await nursery.start(run_control, session, actor)
                nursery.start_soon(_say_when_the_router_goes, session, "world", args.connect)
                async with trio.open_nursery() as running:  # until the world's run ends
                    await running.start(actor.run, bus)
                    print(
                        f"world up on {args.connect} for swarm {scenario.swarm!r}: the run "
                        f"starts when its {scenario.fish} fish are up, after any world of the "
                        "swarm that runs or came up first",
                        file=sys.stderr,
                    )
                # Its own last snapshot comes back through the session: record it too.
                with trio.move_on_after(WORLD_END_SETTLE):
                    await observer.wait_for_tick(actor.tick)
                nursery.cancel_scope.cancel()

    prepare_file(args.record, "--record", example="runs/world.mcap")
    observers: list[Observer] = []
    try:
        _run_trio(main)
    finally:  # an interrupted run's recording is kept too (read_recording marks it cut short)
        _say_recording(observers, args.record)
    statistics = actor.statistics()
    # As `fishswarm run` says it: fish lost on the way leave a trajectory that is not what
    # they decided (the world cannot tell a fish's process dying from its hanging or its
    # robot going: all are lost fish to it).
    degraded = actor.state_name == "finished" and bool(actor.lost)
    status = "degraded" if degraded else actor.state_name
    print(
        f"status: {status} at tick {statistics.ticks} "
        f"({actor.time:g} s simulated, "
        f"{actor.wall_time:.1f} s wall time); {statistics.lost_fish} fish lost, "
        f"{statistics.rejected_total} messages rejected by the world",
        file=sys.stderr,
    )
    if degraded:
        lost = [(f.fish_id, f.tick, f.reason) for f in actor.lost]
        print(f"fish were lost on the way: {_lost_text(lost, actor.joined)}", file=sys.stderr)
    print(json.dumps(dataclasses.asdict(statistics)), file=sys.stderr)
    return EXIT_DEGRADED if degraded else EXIT_OK


WORLD_ANSWER_TIMEOUT = 2.0
"""How long a standalone channel waits for a run's world to tell its settings, s (well within
the world's wait for the channel's first report)."""


def channel(args: argparse.Namespace, scenario: Scenario) -> int:
    """``fishswarm channel``: the channel alone."""
    served: list[Channel] = []

    async def main() -> None:
        async with open_session(client_settings(args, "channel", swarm=scenario.swarm)) as session:

            async def ask_world() -> Scenario | None:
                return await ask_scenario(session, scenario.keys, timeout=WORLD_ANSWER_TIMEOUT)

            async with trio.open_nursery() as nursery:
                served.append(Channel(scenario, ask_world=ask_world))
                await nursery.start(served[0].run, ZenohBus(session))
                print(
                    f"channel up on {args.connect} for swarm {scenario.swarm!r}: it takes each "
                    "run's medium (range, loss, seed, how flags travel, vision) from the run's "
                    "world",
                    file=sys.stderr,
                )

    try:
        _run_trio(main)
    finally:  # said however it ends (Ctrl-C, SIGTERM): what the channel did
        if served:
            statistics = served[0].statistics()
            print(
                f"channel: {statistics.delivered} deliveries made, "
                f"{statistics.missing_broadcasts} broadcasts announced but missing, "
                f"{statistics.unannounced} broadcasts not delivered (sent with a late or "
                f"lost command), {statistics.rejected} messages rejected by the channel",
                file=sys.stderr,
            )
    return 0


ROUTER_CHECK_EVERY = 0.5
"""How often a client command looks whether it still reaches its router, s."""


async def _say_when_the_router_goes(
    session: zenoh.Session,
    command: str,
    endpoint: str,
    *,
    expected: Callable[[], bool] = lambda: False,
) -> None:
    """Say when this client loses its router, and when it has it again: everything it talks
    to goes through the router (a world's fish are lost with it, one by one). Not when
    ``expected()`` says the router was to go: an observer's run has ended, and a
    ``fishswarm run``'s router ends with it."""
    up = True
    while True:
        await trio.sleep(ROUTER_CHECK_EVERY)
        now = reaches_router(session)
        if now == up or (not now and expected()):
            continue  # an expected loss is not news, nor the router's return after it
        up = now
        if up:
            print(f"fishswarm {command}: the router at {endpoint} is back", file=sys.stderr)
        else:
            print(
                f"fishswarm {command}: lost the router at {endpoint}: the swarm is out of reach "
                "until it is back (Ctrl-C to stop)",
                file=sys.stderr,
            )


QUIET_OBSERVER_NOTE = 10.0
"""After this long without a snapshot an observer says what it waits for, s."""


async def _say_if_nothing_comes(observer: Observer, swarm: str) -> None:
    await trio.sleep(QUIET_OBSERVER_NOTE)
    if not observer.history:
        print(
            f"no snapshot of swarm {swarm!r} after {QUIET_OBSERVER_NOTE:g} s: waiting for its "
            "world (is a fishswarm run or world going on this router, and under this "
            "--swarm?); Ctrl-C to stop",
            file=sys.stderr,
        )


async def wait_for_run_end(observer: Observer, session: zenoh.Session, endpoint: str) -> str | None:
    """Wait until the world of the run ``observer`` watches leaves; None when it said its
    run was over, else why it left unfinished: ``lost the router at ENDPOINT`` or ``the
    world left``."""
    # A world's token is gone for everyone who loses the router too: whether the router is
    # still there is noted the moment the world leaves.
    router: list[bool] = []
    run = await observer.wait_for_world_end(on_left=lambda: router.append(reaches_router(session)))
    said = observer.world_said_ended(run)
    if said is True or (said is None and router and router[0]):
        return None
    lost = not (router and router[0] and reaches_router(session))
    return f"lost the router at {endpoint}" if lost else "the world left"


def say_waiting_for_world(command: str, keys: KeySpace, endpoint: str) -> None:
    """Say that ``fishswarm COMMAND`` waits for a world to tell it what runs."""
    print(
        f"fishswarm {command}: waiting for the world of swarm {keys.swarm!r} on {endpoint} "
        "(is a run going, and under this --swarm?)",
        file=sys.stderr,
    )


def observe(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm observe``: watch a swarm from anywhere."""
    refuse_observer_name(args)
    keys = KeySpace(args.swarm)
    ticks = args.ticks
    prepare_file(args.record, "--record", example="runs/observed.mcap")

    async def main() -> None:
        show = progress_printer(ticks, line)
        settings = client_settings(args, observer_subject(args.name), swarm=keys.swarm)
        # The session first: an observer that cannot reach the router writes no recording.
        async with open_session(settings) as session, contextlib.AsyncExitStack() as files:
            recorder = (
                files.enter_context(open_recorder(args.record, {"observed": True}))
                if args.record
                else None
            )
            observer = Observer(keys, recorder=recorder, on_progress=show, observer_id="cli")
            observers.append(observer)

            async def learn_the_run() -> None:
                """Ask the world what runs (until it answers), then measure and record the
                run as its own recording would: its scenario, its formation's metrics."""
                try:
                    ran = await wait_for_scenario(session, keys)
                except ConfigError as error:
                    print(f"fishswarm observe: warning: {error}", file=sys.stderr)
                    if recorder is not None and isinstance(error, UnreadableSettings):
                        recorder.scenario(error.settings)  # as told, for whoever reads it
                    return
                observer.measure_as(ran)
                if recorder is not None:
                    recorder.scenario(ran.to_dict())

            async with trio.open_nursery() as nursery:
                await nursery.start(observer.run, ZenohBus(session))
                print(f"observing swarm {args.swarm!r} on {args.connect}", file=sys.stderr)
                nursery.start_soon(learn_the_run)
                nursery.start_soon(_say_if_nothing_comes, observer, args.swarm)
                nursery.start_soon(
                    functools.partial(
                        _say_when_the_router_goes,
                        session,
                        "observe",
                        args.connect,
                        expected=lambda: observer.world_said_ended() is True,
                    )
                )
                # Until the snapshot of --ticks, or the end of the run (the world leaves).
                async with trio.open_nursery() as waiting:

                    async def wait_then_stop(wait: Callable[[], Awaitable[None]]) -> None:
                        await wait()
                        waiting.cancel_scope.cancel()

                    async def wait_for_world_end() -> None:
                        why = await wait_for_run_end(observer, session, args.connect)
                        if why is not None:
                            unfinished.append(why)

                    waiting.start_soon(wait_then_stop, wait_for_world_end)
                    if ticks is not None:
                        waiting.start_soon(wait_then_stop, lambda: observer.wait_for_tick(ticks))
                nursery.cancel_scope.cancel()

    observers: list[Observer] = []
    unfinished: list[str] = []
    line = ProgressLine(sys.stderr)
    try:
        _run_trio(main)
    finally:  # at the end of the run, after --ticks, or on Ctrl-C: what it saw
        line.close()
        history = observers[0].history if observers else []
        if history:
            last = history[-1]
            print(
                f"observed ticks {history[0].tick}–{last.tick} ({len(history)} snapshots), "
                f"{last.fish} fish at the end",
                file=sys.stderr,
            )
        _say_recording(observers, args.record)
    if unfinished:
        print(
            f"fishswarm observe: {unfinished[0]} before the run ended (its world never said "
            "the run was over): what became of the run is not known here",
            file=sys.stderr,
        )
        return 1
    return 0


CONTROL_TIMEOUT = 5.0
"""How long an operator's command waits for the world's answer, s."""


def _ask_world(args: argparse.Namespace, request: ControlRequest) -> ControlReply:
    """The answer of the world of ``--swarm`` to an operator's control request.

    Raises:
        UserError: no world answered, or its answer is not a control reply.
    """
    keys = KeySpace(args.swarm)

    async def main() -> ControlReply | None:
        async with open_session(client_settings(args, "admin", swarm=keys.swarm)) as session:
            return await _ask_control(session, keys, request)

    reply: ControlReply | None = _run_trio(main)
    if reply is None:
        raise UserError(
            f"no world of swarm {args.swarm!r} answered on {args.connect}: is a run going, "
            "and under this --swarm?"
        )
    return reply


async def _ask_control(
    session: zenoh.Session, keys: KeySpace, request: ControlRequest
) -> ControlReply | None:
    """The reply of the world of ``keys``'s swarm to an operator's control request (None:
    no world answered).

    Raises:
        UserError: its answer is not a control reply.
    """
    replies = await query(session, keys.control, encode(request), timeout=CONTROL_TIMEOUT)
    if not replies:
        return None
    try:
        return decode(replies[0], ControlReply)
    except MessageError as error:
        raise UserError(f"the world's answer is not a control reply: {error}") from None


def formation(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm formation SHAPE``: switch a running school's formation, in the world and
    on the robots (which have no world to tell them)."""
    from fishswarm.actors.robot import FleetEntry, order_fleet, survey_fleet
    from fishswarm.cli.robot import say_unconfirmed

    keys = KeySpace(args.swarm)
    request = ControlRequest("formation", formation=args.shape)

    async def main() -> tuple[ControlReply | None, RobotOrder | None, list[FleetEntry]]:
        async with open_session(client_settings(args, "admin", swarm=keys.swarm)) as session:
            reply = await _ask_control(session, keys, request)
            if reply is not None and reply.refused is not None:
                return reply, None, []
            bus = ZenohBus(session)
            order = order_fleet(bus, keys, "formation", [], formation=args.shape)
            return reply, order, await survey_fleet(bus, keys, listen=args.listen)

    reply, order, fleet = _run_trio(main)
    if reply is not None and reply.refused is not None:
        raise UserError(f"the world did not switch to {args.shape}: {reply.refused}")
    if reply is None and not fleet:
        raise UserError(
            f"no world of swarm {args.swarm!r} answered on {args.connect}, and no robot was "
            "heard from: is a run going, and under this --swarm?"
        )
    if reply is not None:
        print(
            f"formation {args.shape} from tick {reply.tick + 1} (world {reply.state}, "
            f"{reply.live_fish} fish)"
        )
    if not fleet or order is None:
        return 0
    missing = say_unconfirmed(fleet, order)
    confirmed = sorted({entry.robot_id for entry in fleet} - set(missing))
    if confirmed:
        print(f"formation {args.shape} on robots {ids_text(confirmed)}")
    return 1 if missing else 0


def control(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm control ACTION``: a running world's status, or pause, resume or stop."""
    reply = _ask_world(args, ControlRequest(args.action))
    print(
        f"swarm {args.swarm!r}: {reply.state} at tick {reply.tick} (t = {reply.time:g} s), "
        f"{reply.live_fish} fish"
    )
    return 0


def router(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm router``: a Zenoh router for robots and observers."""
    listen = endpoint_of(args.listen, "--listen")
    secured = f", secured by {args.secure}" if args.secure else ""

    async def main() -> None:
        extra = secure_extra(args, "router", endpoint=listen, router=True)
        async with open_session(SessionSettings(mode="router", listen=[listen], extra=extra)):
            print(f"router listening on {args.listen}{secured}; Ctrl-C stops it",
                  file=sys.stderr)  # fmt: skip
            await trio.sleep_forever()

    _run_trio(main)
    return 0


def secure(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm secure init DIR``: a secured swarm's authority, certificates and access
    control."""
    try:
        before = certified_subjects(args.folder, KeySpace(args.swarm))
        named = router_names(args.folder)
        written = init_secure(
            args.folder,
            robots=args.robots,
            observers=args.observers,
            # The run's own processes reach the router on this machine: always named.
            hosts=("localhost", "127.0.0.1", *(args.host or ())),
            swarm=args.swarm,
            days=DEFAULT_DAYS if args.days is None else args.days,
            replace=args.force,
        )
    except ValueError as error:
        raise ConfigError(str(error)) from None
    except SecurityError as error:
        raise UserError(str(error)) from None
    except OSError as error:
        raise UserError(f"cannot write into {args.folder}: {error}") from None
    subjects = sorted({p.stem for p in written if p.suffix == ".pem"} - {AUTHORITY})
    if args.folder / f"{AUTHORITY}.pem" not in written:  # added to the folder's authority
        renewed = "router" in subjects and "router" in before
        added = [subject for subject in subjects if subject not in before]
        made = (
            f"certificates for {', '.join(added)}"
            if added
            else "no new certificate"
            + (" (--days counts for certificates made now only)" if args.days else "")
        )
        if renewed:
            new = [name for name in router_names(args.folder) if name not in named]
            made += (
                f"; renewed the router's certificate to name {', '.join(new)} too (its other "
                "names kept)"
            )
        print(
            f"{args.folder} already holds an authority: added {made} (signed by it; those "
            f"given out stay valid) and rewrote the router's access control in {ACCESS_FILE}. "
            "Restart the router with the folder: it reads both when it starts. --force makes "
            "a new authority instead.",
            file=sys.stderr,
        )
        return 0
    gone = sorted(set(before) - set(subjects))
    removed = f" Removed the old authority's certificates of {', '.join(gone)}." if gone else ""
    print(
        f"wrote {len(written)} files to {args.folder}: certificates for {', '.join(subjects)}; "
        f"the router's access control in {ACCESS_FILE}. Keep ca.key off the robots; give "
        f"each machine ca.pem and its own certificate and key.{removed}",
        file=sys.stderr,
    )
    return 0


def export(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm export``."""
    if args.npz is None and args.csv is None:
        raise ConfigError("say what to write: --npz OUT.npz and/or --csv OUT.csv")
    check_distinct_files(
        {"--npz": args.npz, "--csv": args.csv}, read={"the recording": args.recording}
    )
    prepare_file(args.npz, "--npz", example="runs/latest.npz", suffix=".npz")
    prepare_file(args.csv, "--csv", example="runs/latest.csv")
    recording = read_recording_for(args.recording, at_least=1, purpose="export")
    if args.npz is not None:
        export_npz(recording, args.npz)
        print(f"wrote {args.npz}", file=sys.stderr)
    if args.csv is not None:
        export_csv(recording, args.csv)
        print(f"wrote {args.csv}", file=sys.stderr)
    return 0
