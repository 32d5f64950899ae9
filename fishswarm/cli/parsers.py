"""The ``fishswarm`` command line: every parser, its flags and help, and the scenario built."""

from __future__ import annotations

import argparse
import difflib
import math
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from fishswarm import __version__
from fishswarm.actors.driver import LINK_TIMEOUT
from fishswarm.actors.fish import PERCEPTION_TIMEOUT
from fishswarm.actors.robot import ROBOT_PERCEPTION_TIMEOUT
from fishswarm.behaviors.formation import DEFAULT_SPACING
from fishswarm.behaviors.lennard_jones import AGGREGATION_DISTANCE
from fishswarm.behaviors.registry import names as behavior_names
from fishswarm.behaviors.registry import plugin_failures
from fishswarm.bluebot.parameters import BLIND_WIDTH, SPHERE_RADIUS
from fishswarm.cli.study import add_parsers as add_study_parsers
from fishswarm.learning.arena import REPLICA_KINDS
from fishswarm.protocols.keys import MAX_FISH_ID, check_name
from fishswarm.protocols.messages import FORMATION_SHAPES
from fishswarm.sim.scenario import (
    APPLIES_WHEN,
    EXPERIMENT_SWITCHES,
    PROFILES,
    START_TIMEOUT,
    STUDY_CODE_SWITCHES,
    TURN_DELAY,
    ConfigError,
    Scenario,
    applies_anyway,
    own_setting_from_text,
    scenario_table,
    setting_text,
    switch_names,
    unmet_condition,
)
from fishswarm.study.view_settings import GRPC_PORT, WEB_PORT

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
SECURE_ENDPOINT = "tls/127.0.0.1:7447"
"""Where a command listens or connects by default: this machine, TLS in a secured swarm."""


class _Parser(argparse.ArgumentParser):
    """An argument parser that gives an endpoint not given on the command line its default:
    this machine's, over TLS when the swarm is secured (``--secure``), and takes no
    abbreviated option: ``experiment --seed 1`` was read as ``--seeds 1`` and replaced a
    study's five-seed table with a one-seed one, while ``run --seeds`` was refused."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        parsed, rest = super().parse_known_args(args, namespace)
        secured = getattr(parsed, "secure", None) is not None
        defaulted = []
        for name in ("connect", "listen"):
            if hasattr(parsed, name) and getattr(parsed, name) is None:
                setattr(parsed, name, SECURE_ENDPOINT if secured else DEFAULT_ENDPOINT)
                defaulted.append(name)
        # Which endpoints the user did not give (a command refuses one it would ignore);
        # a command's own parser fills them before the top-level one looks.
        parsed.defaulted_endpoints = (*getattr(parsed, "defaulted_endpoints", ()), *defaulted)
        return parsed, rest

    def parse_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> argparse.Namespace:
        parsed, rest = self.parse_known_args(args, namespace)
        misplaced = [word for word in rest if word.split("=")[0] in ("--log-level", "--version")]
        if misplaced:
            # The options of fishswarm itself, given after a command's name: say where they go.
            option = misplaced[0].split("=")[0]
            command = getattr(parsed, "command", None) or "COMMAND"
            self.error(
                f"{option} is an option of fishswarm itself: give it before the command, e.g. "
                f"fishswarm {option}{' INFO' if option == '--log-level' else ''} {command} …"
            )
        if rest:
            # Said by the command's own parser (its usage, not fishswarm's), with the option
            # a misspelt one was likely meant to be (--behaviour for --behavior).
            command = self._command_parser(parsed)
            options = [o for a in command._actions for o in a.option_strings if o.startswith("--")]
            meant = [
                close[0]
                for word in rest
                if word.startswith("--")
                and (close := difflib.get_close_matches(word.split("=")[0], options, 1, 0.8))
            ]
            hint = f" (did you mean {', '.join(meant)}?)" if meant else ""
            command.error(f"unrecognized arguments: {' '.join(rest)}{hint}")
        return parsed

    def _command_parser(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The parser of the command ``parsed`` names, down to a command of a command
        (``secure init``); this one when it names none."""
        parser: argparse.ArgumentParser = self
        while True:
            for action in parser._actions:
                if isinstance(action, argparse._SubParsersAction):
                    chosen = getattr(parsed, action.dest, None)
                    if chosen in action.choices:
                        parser = action.choices[chosen]
                        break
            else:
                return parser


def seconds(text: str) -> float:
    """A duration, s: a finite number, not negative (an argparse type)."""
    value = _number(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is negative: give seconds, 0 or more")
    return value


def listening_time(text: str) -> float:
    """How long to listen, s (an argparse type for ``robots`` and ``formation``, whose
    --listen is a time where other commands' is an endpoint: an endpoint says so)."""
    if "/" in text:
        raise argparse.ArgumentTypeError(
            f"{text!r} is an endpoint, but here --listen is how long to listen, s: give the "
            f"router with --connect {text}"
        )
    return seconds(text)


def longest_wait(text: str) -> float:
    """A longest wait, s: a finite number; a negative one waits forever (an argparse type)."""
    return _number(text)


def fish_id(text: str) -> int:
    """A fish's (or robot's) id: an integer from 0 to MAX_FISH_ID (an argparse type)."""
    value = _whole_number(text, negative="fish ids are 0 or more")
    if value > MAX_FISH_ID:
        raise argparse.ArgumentTypeError(f"{text} is too large: fish ids go up to {MAX_FISH_ID}")
    return value


def secure_folder(text: str) -> Path:
    """A secured swarm's folder, which must exist (an argparse type)."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(
            f"{text} is not a folder: give the one 'fishswarm secure init' wrote"
        )
    return path


def tick_number(text: str) -> int:
    """A tick: an integer, 0 or more (an argparse type)."""
    return _whole_number(text, negative="ticks count from 0")


def _whole_number(text: str, *, negative: str) -> int:
    """``text`` as an integer, 0 or more; ``negative`` says why a negative one is refused."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is negative: {negative}")
    return value


def swarm_name(text: str) -> str:
    """A swarm's name, as keys can hold it (an argparse type)."""
    return _name("swarm", text)


def observer_name(text: str) -> str:
    """An observer's name, as a certificate's subject and keys can hold it (an argparse
    type)."""
    return _name("observer", text)


def _name(kind: str, text: str) -> str:
    try:
        return check_name(kind, text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number of seconds")
    return value


BEHAVIOR_NAMES = "{behaviors}"
"""Where a help text lists the behaviours there are."""

ONE_EACH = object()
"""The kind of a flag given once for each of a table's entries (NAME=VALUE)."""

SWITCH_ON = object()
"""The kind of a flag that turns a setting on (``bool``: one that turns it off)."""

_SCENARIO_FLAGS: dict[str, tuple[str, Any, str]] = {
    "fish": (
        "--fish",
        int,
        f"number of fish (default {Scenario.fish})",
    ),
    "behavior": (
        "--behavior",
        str,
        f"one of {BEHAVIOR_NAMES} (default {Scenario.behavior})",
    ),
    "duration": ("--duration", float, f"simulated seconds (default {Scenario.duration:g})"),
    "seed": (
        "--seed",
        int,
        f"master seed; the same seed gives the same run (default {Scenario.seed})",
    ),
    "control_period": (
        "--period",
        float,
        f"control period in s (default {Scenario.control_period:g}: "
        f"{1 / Scenario.control_period:g} Hz)",
    ),
    "controller": (
        "--controller",
        str,
        "homing (the research code's) or pid (default: pid for formation, homing otherwise)",
    ),
    "target_distance": (
        "--target-distance",
        float,
        f"Lennard-Jones target distance in m (default {AGGREGATION_DISTANCE:g} for "
        "aggregation, the tank diagonal for dispersion)",
    ),
    "spawn_region": (
        "--spawn",
        str,
        "where the fish start: ball (default: within --spawn-radius of the tank centre, "
        "clipped to the tank) or tank (anywhere in the tank; for hundreds of fish or more)",
    ),
    "spawn_radius": (
        "--spawn-radius",
        float,
        "with --spawn ball: radius of the start ball, m (default 0.26 for dispersion, 1.3 for "
        "the other behaviours)",
    ),
    "blind_width": ("--blind-width", float, f"blind-spot width in m (default {BLIND_WIDTH:g})"),
    "sphere_radius": (
        "--sphere-radius",
        float,
        f"blocking-sphere radius in m (default {SPHERE_RADIUS:g})",
    ),
    "vision_model": (
        "--vision",
        str,
        "geometric (default: the vision model of the study) or camera (every fish renders its "
        "two camera images and finds its neighbours with the robot's LED pipeline; slower, "
        "with the robot's misses and range errors; see docs/camera.md)",
    ),
    "orbit_radius": (
        "--orbit-radius",
        float,
        "orbit radius R of orbit and milling around the post at the tank centre, partner "
        f"distance of waltz, m (default {Scenario.orbit_radius:g})",
    ),
    "time_mode": (
        "--time",
        str,
        "lockstep (default: as fast as possible, deterministic), jitter (each fish on its own "
        "clock, periods drawn from N(period, --jitter); deterministic; no broadcasts, so a "
        "formation needs --no-flags) or realtime (one tick "
        "per control period of wall-clock time; late fish keep their last command)",
    ),
    "jitter": (
        "--jitter",
        float,
        f"with --time jitter: s.d. of each fish's control period, s (default {Scenario.jitter:g})",
    ),
    "formation": (
        "--formation",
        str,
        f"with --behavior formation: {', '.join(FORMATION_SHAPES)} (default pyramid)",
    ),
    "spacing": (
        "--spacing",
        float,
        f"distance between places of a formation, m (default {DEFAULT_SPACING:g})",
    ),
    "flags": (
        "--no-flags",
        bool,
        "with --behavior formation: fish neither send nor heed formation flags",
    ),
    "flag_medium": (
        "--flag-medium",
        str,
        "with --behavior formation: how the flags travel: channel (default: the simulated "
        "channel, every flag to every fish within its range), light (as between robots: "
        "only 'I hold my place', from a fish that holds it, to the fish that see it by the "
        "geometric vision model, even with --vision camera) or beacon (that one bit to every "
        "fish within the channel's range); docs/robot.md",
    ),
    "rotate_effort": (
        "--rotate-effort",
        SWITCH_ON,
        "with --behavior formation: a fish that has spent more effort than the most rested "
        "fish it hears (by effort_margin) swaps places with it, agreed by formation flags "
        "(docs/formations.md)",
    ),
    "study_code": (
        "--study-code",
        switch_names,
        "follow the study's published code instead of its paper's equations here, switches "
        f"separated by commas: {'; '.join(f'{k} ({v})' for k, v in STUDY_CODE_SWITCHES.items())}"
        " (default none; see docs/fidelity.md)",
    ),
    "profile": (
        "--profile",
        str,
        f"one of {', '.join(PROFILES)}: paper (default: the paper's equations, plus any "
        "--study-code switches) or study-code (every switch: the model the study's published "
        "tables came from; docs/fidelity.md)",
    ),
    "swarm": (
        "--swarm",
        swarm_name,
        "swarm name: several swarms can share a router (default default)",
    ),
    "model": (
        "--model",
        str,
        "learned replica (best_replica.npz from 'fishswarm learn') for --behavior replica",
    ),
    "behavior_settings": (
        "--behavior-setting",
        ONE_EACH,
        "NAME=VALUE: one of the behaviour's own settings (a package's behaviour, "
        "docs/behaviors.md), over the --config file's; repeat for each (a number, true or "
        "false, or text)",
    ),
}


_FISH_FLAGS = (
    "fish",
    "behavior",
    "target_distance",
    "controller",
    "control_period",
    "orbit_radius",
    "formation",
    "spacing",
    "flags",
    "rotate_effort",
    "swarm",
    "model",
    "study_code",
    "profile",
    "behavior_settings",
)
"""The scenario settings a fish actor reads (``fish`` and ``robot``)."""


_SWARM_FISH_HELP = (
    f"the swarm's number of fish, as its world's --fish (default {Scenario.fish}): a "
    "formation's map has a slot for each"
)
"""--fish of a command that runs some of a swarm's fish (``fish``, ``robot``)."""


def _add_scenario_flags(
    parser: argparse.ArgumentParser, names: Sequence[str], *, helps: Mapping[str, str] = {}
) -> None:
    """The scenario flags ``names`` (``helps``: a command's own help for some of them)."""
    group = parser.add_argument_group("scenario (override the --config file)")
    group.add_argument(
        "--config",
        type=Path,
        metavar="TOML",
        help="scenario file (TOML); its settings are listed in the README under 'Scenario files'",
    )
    for name in names:
        flag, kind, text = _SCENARIO_FLAGS[name]
        # Other packages' behaviours are read as the parser is built, not on import.
        text = helps.get(name, text).replace(BEHAVIOR_NAMES, _behaviors_listed())
        if kind is bool:  # a switch that turns a setting off
            group.add_argument(flag, dest=name, action="store_const", const=False, help=text)
        elif kind is SWITCH_ON:
            group.add_argument(flag, dest=name, action="store_const", const=True, help=text)
        elif kind is ONE_EACH:
            _add_behavior_settings(group, text)
        else:
            group.add_argument(flag, dest=name, type=kind, default=None, help=text)


def _add_behavior_settings(parser: argparse._ActionsContainer, text: str) -> None:
    """``--behavior-setting NAME=VALUE``, once for each of the behaviour's own settings
    (into ``behavior_settings``, a list of (name, text) pairs)."""
    parser.add_argument(
        _SCENARIO_FLAGS["behavior_settings"][0],
        dest="behavior_settings",
        action="append",
        type=_setting_pair,
        metavar="NAME=VALUE",
        help=text,
    )


def _behaviors_listed() -> str:
    """The behaviours there are, for a help text: those of packages left out named too (a
    --help exits before any warning is printed)."""
    listed = ", ".join(behavior_names())
    left_out = [failure.name for failure in plugin_failures()]
    if left_out:
        listed += f" ({', '.join(left_out)} left out: 'fishswarm behaviors' says why)"
    return listed


def _refuse_inapplicable(given: dict[str, Any], scenario: Scenario) -> None:
    """Refuse a scenario flag given on the command line that this scenario would ignore
    (``--formation`` in a dispersion run, say), rather than run without it unsaid.

    Raises:
        ConfigError: naming the flag and what it needs.
    """
    for name in APPLIES_WHEN:
        unmet = unmet_condition(name, scenario) if given.get(name) is not None else None
        if unmet is None:
            continue
        setting, wanted = unmet
        flag = _SCENARIO_FLAGS[name][0]
        shown, kind, _ = _SCENARIO_FLAGS.get(setting, (setting, str, ""))
        if kind is bool and given.get(setting) is not None:  # its flag turned it off
            raise ConfigError(f"{flag} applies only without {shown}: leave one of them out")
        if kind is bool:  # turned off in the scenario file
            raise ConfigError(
                f"{flag} applies only with {setting} {wanted}, and the scenario file's "
                f"{setting} is {setting_text(getattr(scenario, setting))}: leave {flag} out, "
                f"or set {setting} = {wanted} in the file"
            )
        needed = shown if kind is SWITCH_ON else f"{shown} {wanted}"
        actual = setting_text(getattr(scenario, setting))
        raise ConfigError(
            f"{flag} applies only with {needed}, and this {shown} is {actual}: add {needed}, "
            f"or leave {flag} out{applies_anyway(name)}"
        )


def _named_by_flag(message: str, given: Mapping[str, Any]) -> str:
    """A scenario's message about a setting given as a flag of another name, with the flag
    first: ``--period: control_period must be ...``."""
    for name, value in given.items():
        flag = _SCENARIO_FLAGS[name][0]
        if value is not None and message.startswith(f"{name}: "):  # the setting's own word
            return f"{flag}: {message.removeprefix(f'{name}: ')}"
        if value is not None and message.startswith(f"{name} ") and flag != f"--{name}":
            return f"{flag}: {message}"
    return message


def _setting_pair(text: str) -> tuple[str, str]:
    """``NAME=VALUE`` as a pair of texts (an argparse type): the value is read as its
    setting's kind once the behaviour is known (``own_setting_from_text``)."""
    name, equals, value = text.partition("=")
    if not equals or not name.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=VALUE, e.g. gain=0.5")
    return name.strip(), value.strip()


def scenario_from(args: argparse.Namespace) -> Scenario:
    """The scenario a command's arguments describe: its --config file, if any, with the
    scenario flags given on top (a flag that it would ignore is refused)."""
    path = getattr(args, "config", None)
    table = scenario_table(path) if path else {}
    overrides = {name: getattr(args, name, None) for name in _SCENARIO_FLAGS}
    if overrides["behavior_settings"] is not None:
        # Each NAME=VALUE over the file's table, the file's other entries kept.
        behavior = str(overrides["behavior"] or table.get("behavior") or Scenario.behavior)
        from_file = table.get("behavior_settings")
        overrides["behavior_settings"] = {
            **(dict(from_file) if isinstance(from_file, Mapping) else {}),
            **{
                name: own_setting_from_text(behavior, name, text)
                for name, text in overrides["behavior_settings"]
            },
        }
    try:
        base = Scenario.from_mapping(table, source=str(path)) if path else Scenario()
    except ConfigError:
        given = {name: value for name, value in overrides.items() if value is not None}
        if not given:
            raise
        # The file alone may be refused where the command line mends it (a switch_at past
        # the file's duration, with a longer --duration): checked with the flags on top.
        try:
            base = Scenario.from_mapping({**table, **given}, source=str(path))
        except ConfigError as error:
            # A flag's own error is the flag's, not the file's.
            text = str(error).removeprefix(f"{path}: ")
            named = _named_by_flag(text, overrides)
            raise ConfigError(named if named != text else str(error)) from None
    try:
        # A controller the file names stays when --behavior changes the behaviour.
        scenario = base.with_settings(overrides, controller_chosen="controller" in table)
    except (TypeError, ConfigError) as error:
        said = str(error)
        if (
            said.startswith("behavior_settings: ")
            and overrides["behavior"] is not None
            and overrides["behavior_settings"] is None
        ):
            raise ConfigError(
                f"{path}: {said} (the file's behavior_settings are for its behavior "
                f"{base.behavior}, and --behavior makes it {overrides['behavior']}: leave "
                "one of them out)"
            ) from None
        raise ConfigError(_named_by_flag(said, overrides)) from None
    _refuse_inapplicable(overrides, scenario)
    for warning in _unused_settings(table, overrides, scenario, path):
        print(f"fishswarm {args.command}: warning: {warning}", file=sys.stderr)
    # Only commands that run a scenario to its end take --duration.
    if not hasattr(args, "duration"):
        return scenario
    try:
        return scenario.check_duration()
    except ConfigError as error:
        timing = ("duration", "control_period")
        from_file = any(name in table and overrides.get(name) is None for name in timing)
        raise ConfigError(f"{path}: {error}" if from_file else str(error)) from None


def _unused_settings(
    table: dict[str, Any], given: dict[str, Any], scenario: Scenario, path: Path | None
) -> list[str]:
    """What to say of settings this run ignores: the scenario file's (a file may serve
    several runs, a flag on the command line changing its behaviour, so they are warned of,
    where the same flag given on the command line is refused), and study-code switches
    only experiments act on (named in ``study_code``, from the file or --study-code; the
    study-code profile turns every switch on, these too)."""
    unused: dict[tuple[str, str], list[str]] = {}
    for name in APPLIES_WHEN:
        unmet = unmet_condition(name, scenario) if name in table else None
        if unmet is not None and given.get(name) is None:
            unused.setdefault(unmet, []).append(name)
    warnings = [
        f"{path}: {', '.join(names)} {'apply' if names[1:] else 'applies'} only with "
        f"{setting} {needed}, and this run's {setting} is "
        f"{setting_text(getattr(scenario, setting))}: "
        f"here {'they change' if names[1:] else 'it changes'} nothing{applies_anyway(names[0])}"
        for (setting, needed), names in unused.items()
    ]
    switches = [name for name in EXPERIMENT_SWITCHES if name in scenario.study_code]
    if switches:
        warnings.append(
            f"the study-code switch(es) {', '.join(switches)} apply to 'fishswarm experiment' "
            "only: here they change nothing"
        )
    return warnings


def build_parser() -> argparse.ArgumentParser:
    """The ``fishswarm`` command line: every command and its options."""
    parser = _Parser(
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
    parser.add_argument("--version", action="version", version=f"fishswarm {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = commands.add_parser(
        "run",
        help="run a whole simulated swarm with one command",
        description="Start a router, the world, the channel and an observer, run the fish "
        "beside them (up to 2000 fish) or over worker processes, run the scenario, and write "
        "a recording and a summary.",
    )
    _add_scenario_flags(run, list(_SCENARIO_FLAGS))
    run.add_argument(
        "--procs",
        type=int,
        default=None,
        help="fish worker processes; 0 runs the fish in this process, beside the world, "
        "still over Zenoh (default: 0 up to 2000 fish, 2 beyond). Measured on two cores "
        "against one worker: 25 fish 5-31 %% shorter ticks, 1000 fish about even, the first "
        "tick after 0.2 s instead of 0.7 s; at 10 000 fish neither is clearly faster (runs "
        "of either way gave 0.6-0.85 of the batch engine's speed). Workers keep the "
        "fish apart from the world: a fish that crashes its process leaves the world "
        "running. docs/benchmarks.md",
    )
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
        default=None,
        help=f"endpoint to listen on (default {DEFAULT_ENDPOINT}, with --secure "
        f"{SECURE_ENDPOINT}; tcp/0.0.0.0:7447, or tls/0.0.0.0:7447 with --secure, lets "
        "observers on other machines attach)",
    )
    run.add_argument(
        "--secure",
        type=secure_folder,
        metavar="DIR",
        help="a secured swarm's folder (made by 'fishswarm secure init', with the authority's "
        "key): listen on TLS only (--listen tls/...), apply its access control, and give each "
        "worker process a certificate signed for this run",
    )
    run.add_argument(
        "--start-timeout",
        type=seconds,
        default=START_TIMEOUT,
        help=f"longest wait for all fish to come up, s (default {START_TIMEOUT:g})",
    )
    run.add_argument(
        "--perception-timeout",
        type=seconds,
        default=PERCEPTION_TIMEOUT,
        help="each fish's safety watchdog: fins off after this long without a perception or "
        "a pulse of the world, s (default %(default)g); a run in which it fired ends 'degraded', "
        "exit 4",
    )
    run.add_argument("--quiet", action="store_true", help="no progress lines")
    run.add_argument(
        "--view",
        action="store_true",
        help="serve a live 3-D view of the run in the browser (as 'fishswarm view' does; needs "
        "pip install -e '.[view]'); after the run it stays up until Ctrl-C (a Ctrl-C "
        "during the run ends both)",
    )
    _add_view_flags(run)

    fish = commands.add_parser(
        "fish",
        help="run fish actors alone (what runs on a robot)",
        description="Run one or more fish actors that connect to a router. The fish stop "
        "their fins when perceptions stop arriving.",
    )
    fish.add_argument(
        "--id",
        dest="ids",
        type=fish_id,
        action="append",
        required=True,
        help="fish id; repeat for several fish in one process",
    )
    _add_connect(fish)
    _add_scenario_flags(fish, _FISH_FLAGS, helps={"fish": _SWARM_FISH_HELP})
    fish.add_argument(
        "--perception-timeout",
        type=seconds,
        default=PERCEPTION_TIMEOUT,
        help="fins off after this long without a perception or a pulse of the world, s (default "
        "%(default)g)",
    )
    fish.add_argument(
        "--school",
        metavar="NAME",
        help="serve the fish as one school: one perception batch and one command batch per "
        "tick instead of a message per fish (for many simulated fish in one process; a robot "
        "keeps its own keys). One process per school: a second given a name already served "
        "is refused",
    )

    robot = commands.add_parser(
        "robot",
        help="run a robot: its driver and fish actor (on a BlueBot, or a mock one)",
        description="Run a robot's driver and its fish actor in one process, over an "
        "in-memory bus, bridged to the swarm's router. The driver sees through both cameras "
        "and the depth sensor, runs the fins and LEDs, stops the fins when commands stop "
        "(--command-timeout) or the link stays down (--link-timeout), obeys operators' "
        "stop and resume ('fishswarm robots --stop'), and reports its status. With "
        "--hardware mock it runs on gpiozero's mock pins and swims in a simulated world "
        "running on the same router ('fishswarm run --time realtime'), its camera images "
        "rendered from that world.",
    )
    robot.add_argument(
        "--id", dest="robot_id", type=fish_id, required=True, help="the robot's fish id"
    )
    robot.add_argument(
        "--hardware",
        choices=["bluebot", "mock"],
        default="bluebot",
        help="bluebot (default: gpiozero, picamera2, the MS5803 over I²C) or mock (a laptop)",
    )
    _add_connect(robot)
    _add_scenario_flags(robot, [*_FISH_FLAGS, "seed"], helps={"fish": _SWARM_FISH_HELP})
    robot.add_argument(
        "--command-timeout",
        type=seconds,
        help="fins off when no command arrives for this long, s (more than --period; "
        "default 2.5 periods, at least 1 s)",
    )
    robot.add_argument(
        "--link-timeout",
        type=seconds,
        default=LINK_TIMEOUT,
        help="with the link to the router lost, swim on the robot's own perception for this "
        "long, then stop the fins until it returns, s (default %(default)g)",
    )
    robot.add_argument(
        "--zenoh-config",
        type=Path,
        metavar="JSON5",
        help="a Zenoh configuration file to start the robot's session from (transport and "
        "security settings; --connect, client mode and the robot's 1-s lease apply over it)",
    )
    robot.add_argument(
        "--perception-timeout",
        type=seconds,
        default=ROBOT_PERCEPTION_TIMEOUT,
        help="the fish actor's own watchdog: fins off after this long without a perception, "
        "s (default %(default)g)",
    )

    robots = commands.add_parser(
        "robots",
        help="list the robots of a swarm, or stop and resume them",
        description="Listen for the robots' status messages and liveliness for --listen "
        "seconds and print the fleet: id, version, behaviour, state, depth, link, fin "
        "frequencies, CPU temperature and when each was last heard. --stop turns fins and "
        "LEDs off on the named robots (all when no id is given) until --resume.",
    )
    _add_connect(robots)
    robots.add_argument(
        "--swarm", type=swarm_name, default="default", help="swarm name (default default)"
    )
    robots.add_argument(
        "--listen",
        type=listening_time,
        default=1.5,
        help="how long to listen, s (default %(default)g)",
    )
    order = robots.add_mutually_exclusive_group()
    order.add_argument(
        "--stop", type=fish_id, nargs="*", metavar="ID", help="stop these robots (none given: all)"
    )
    order.add_argument(
        "--resume", type=fish_id, nargs="*", metavar="ID", help="resume these robots (none: all)"
    )
    robots.add_argument("--json", action="store_true", help="print the fleet as JSON")

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
        type=seconds,
        default=START_TIMEOUT,
        help=f"longest wait for the fish, s (default {START_TIMEOUT:g})",
    )
    world.add_argument(
        "--turn-delay",
        type=seconds,
        default=TURN_DELAY,
        help="worlds of one swarm run one after the other, first come first served: a world "
        "takes its turn no sooner than this after it came up, so that the places in the queue "
        "of worlds up before it reach it first; raise it where the worlds' links to the "
        f"router are slower than that, s (default {TURN_DELAY:g})",
    )

    world.add_argument(
        "--record",
        type=Path,
        help="MCAP recording of the run to write (plot, animate and export read it)",
    )
    world.add_argument("--quiet", action="store_true", help="no progress lines")

    channel = commands.add_parser(
        "channel",
        help="run the channel actor alone",
        description="Run the simulated broadcast medium: it delivers the fish's broadcasts "
        "(formation flags) to the fish in range, situated and with the scenario's seeded "
        "loss, and tells the world how many each fish gets. At the start of each run it "
        "asks that run's world for its settings and takes the world's medium: channel "
        "range, loss, seed, how formation flags travel and the vision that decides who "
        "sees whom; its own (--seed, --config) serve only if no world answers.",
    )
    _add_connect(channel)
    _add_scenario_flags(channel, ["seed", "swarm"])

    observe = commands.add_parser(
        "observe",
        help="attach an observer to a running swarm",
        description="Watch a swarm's snapshots and liveliness from this or another machine; "
        "print progress and optionally record. Stops when the run ends (the world leaves), after "
        "--ticks, or on Ctrl-C, and says what it saw; exits 1 if it lost the router before the "
        "run ended.",
    )
    _add_connect(observe)
    observe.add_argument(
        "--name",
        type=observer_name,
        help="with --secure: whose observer certificate to use (observer-NAME; default the "
        "plain observer certificate)",
    )
    observe.add_argument(
        "--swarm", type=swarm_name, default="default", help="swarm name (default default)"
    )
    observe.add_argument(
        "--record",
        type=Path,
        help="MCAP recording to write, with the run's settings as its world tells them (so "
        "plot, animate and view draw it as the run's own recording)",
    )
    observe.add_argument(
        "--ticks",
        type=tick_number,
        help="stop after the snapshot of this tick (0 or more; the run's tick, not a count: "
        "an observer that comes later stops at its first snapshot)",
    )

    view = commands.add_parser(
        "view",
        help="show a swarm in 3-D in a browser, live or from a recording",
        description="Serve a 3-D view of a swarm from this machine, in rerun's web viewer: "
        "the tank, the landmark, every fish as an arrow along its body (coloured by role in a "
        "formation: leader, in its place, seeking; a global map's fitted target as grey dots, "
        "a local shape's completed sides as green lines), and the "
        "metrics over time. With a RECORDING (an MCAP file of 'run', 'world' or 'observe' "
        "--record), replay it; "
        "otherwise attach to the running swarm at --connect as a read-only observer (with "
        "--secure, with an observer's certificate) and follow it live. Needs no internet: "
        "the viewer comes inside the rerun SDK (pip install -e '.[view]'). Runs until "
        "Ctrl-C.",
    )
    view.add_argument(
        "recording", nargs="?", type=Path, help="an MCAP recording to replay (default: live)"
    )
    _add_connect(view)
    view.add_argument(
        "--name",
        type=observer_name,
        help="with --secure: whose observer certificate to use (observer-NAME; default the "
        "plain observer certificate)",
    )
    view.add_argument("--swarm", type=swarm_name, help="swarm name (default default)")
    _add_view_flags(view)
    view.add_argument("--open", action="store_true", help="open this machine's browser on the page")

    formation = commands.add_parser(
        "formation",
        help="switch a running school to another formation",
        description="Ask the world of a running swarm to tell its formation fish to take "
        "another shape from the next tick on, and order the swarm's robots (which have no "
        "world to tell them) to do the same; the school re-forms. Prints the world's reply "
        "and which robots confirmed (exit 1 if one did not: send it again). In a secured "
        "swarm this takes the admin certificate.",
    )
    formation.add_argument("shape", choices=FORMATION_SHAPES, help="the new formation")
    _add_connect(formation)
    formation.add_argument(
        "--swarm", type=swarm_name, default="default", help="swarm name (default default)"
    )
    formation.add_argument(
        "--listen",
        type=listening_time,
        default=1.5,
        help="how long to listen for the robots' confirmations, s (default %(default)g)",
    )

    control = commands.add_parser(
        "control",
        help="a running world's status, or pause, resume or stop its run",
        description="Ask the world of a running swarm for its status, or to pause, resume "
        "or stop its run, from any machine that reaches the router (in a secured swarm, with "
        "the admin certificate). A pause holds the run at its next snapshot until resumed (the "
        "reply says 'pausing' until the tick under way is answered, then 'paused'); a stop "
        "ends it at once, at the last snapshot sent, "
        "and the world exits as at the run's end. A world waiting its turn behind another "
        "of the swarm answers nothing until its turn. Prints the world's reply: its state, "
        "tick, time and fish. (Robots have their own: fishswarm robots --stop.)",
    )
    control.add_argument(
        "action",
        choices=("status", "pause", "resume", "stop"),
        help="what to ask the world",
    )
    _add_connect(control)
    control.add_argument(
        "--swarm", type=swarm_name, default="default", help="swarm name (default default)"
    )

    router = commands.add_parser(
        "router",
        help="run a Zenoh router (e.g. on the base station)",
        description="Run a Zenoh router that robots, simulation actors and observers connect "
        "to as clients. Ctrl-C stops it.",
    )
    router.add_argument(
        "--listen",
        default=None,
        help=f"endpoint to listen on (default {DEFAULT_ENDPOINT}, with --secure "
        f"{SECURE_ENDPOINT}: this machine only, as for run; tcp/0.0.0.0:7447 lets robots "
        "and other machines connect, and anyone who reaches it can command the fish unless "
        "it is secured: with --secure a tls/ one, e.g. tls/0.0.0.0:7447)",
    )
    router.add_argument(
        "--secure",
        type=secure_folder,
        metavar="DIR",
        help="a secured swarm's folder (made by 'fishswarm secure init'): listen on TLS only, "
        "ask every client for a certificate of its authority, and apply its access control",
    )

    secure = commands.add_parser(
        "secure",
        help="make the certificates and access control of a secured swarm",
        description="Secure a swarm on Zenoh's own mechanisms: mutual TLS on the router and "
        "access control that denies by default and allows each certificate (by its common "
        "name) only the keys of its role. Pass the folder to every command as --secure DIR.",
    )
    secure_commands = secure.add_subparsers(dest="action", metavar="ACTION", required=True)
    init = secure_commands.add_parser(
        "init",
        help="create an authority, a certificate and key per role, and the access control",
        description="Write into DIR: ca.pem/ca.key (the authority: keep its key off the "
        "robots), a certificate and key for router, world, channel, admin (fishswarm robots, "
        "formation, control), observer, each --observers NAME (observer-NAME) and each --robots ID "
        "(robot-ID: the robot's fish and driver), and access_control.json for the router.",
    )
    init.add_argument("folder", type=Path, metavar="DIR", help="folder to write into")
    init.add_argument("--robots", type=fish_id, nargs="*", default=[], metavar="ID",
                      help="robot ids to make certificates for")  # fmt: skip
    init.add_argument(
        "--observers",
        type=observer_name,
        nargs="*",
        default=[],
        metavar="NAME",
        help="observer names to make certificates for (besides 'observer')",
    )
    init.add_argument("--host", action="append", default=None, metavar="NAME_OR_ADDRESS",
                      help="a name or address the router is reached by (repeat; localhost and "
                      "127.0.0.1 are always named, as a run reaches its router there)")  # fmt: skip
    init.add_argument(
        "--swarm", type=swarm_name, default="default", help="swarm name (default default)"
    )
    init.add_argument(
        "--days", type=int, help="how long the certificates made now are valid, 1 to 36500 "
        "(default 365)"
    )  # fmt: skip
    init.add_argument(
        "--force",
        action="store_true",
        help="make a new authority even if DIR holds one (without it, certificates for new "
        "robots and observers are added to DIR's authority, and those given out stay valid; "
        "with it, the old certificates in DIR are removed and those given out stop being "
        "accepted: name every robot and observer again)",
    )

    learn = commands.add_parser(
        "learn",
        help="learn fish behaviour from observation (Turing learning with CMA-ES)",
        description="Co-evolve replica fish and classifiers with CMA-ES until the replicas "
        "behave like the ideal fish (SPEC §4). Writes checkpoints, the best replica, fitness "
        "curves, spacing/speed and trajectory plots and the learned radii to --out.",
    )
    # Settings of the run default to None here: a resumed run takes the checkpoint's, and
    # refuses only those the user names and that differ.
    learn.add_argument(
        "--behavior",
        choices=["aggregation", "dispersion"],
        help="what the ideal fish do (default aggregation)",
    )
    learn.add_argument(
        "--inputs",
        help="classifier inputs, comma-separated, from speed, angular-speed, nearest "
        "(distance to the nearest schoolmate), counts (schoolmates within 15, 30 and 60 "
        "units), neighbors (count within one learned radius), neighbors2 (two) (default "
        "speed,counts; the study's: speed,neighbors)",
    )
    learn.add_argument(
        "--radii",
        choices=["bounded", "unbounded"],
        help="bounded: radii folded back into [0, 300] units (a triangle wave of the genome, "
        "not clipped); unbounded: started in [-40, 300] and free (default bounded)",
    )
    learn.add_argument(
        "--generations",
        type=int,
        help="generations to reach, counting those done (default 500; with --resume, the "
        "number the resumed run was started with)",
    )
    learn.add_argument("--models", type=int, help="replica population (default 100)")
    learn.add_argument("--classifiers", type=int, help="classifier population (default 100)")
    learn.add_argument("--seed", type=int, help="master seed (default 0)")
    learn.add_argument(
        "--hall-of-fame",
        type=int,
        help="past champions drawn into every generation, and the pool the kept replica is "
        "picked from (default 10; 0: the study's method)",
    )
    learn.add_argument(
        "--soft-weight",
        type=float,
        help="weight of the classifiers' soft judgement (the probability they give a sample "
        "of being an ideal fish) beside the thresholded one in both fitnesses (default 1; "
        "0.001 only breaks ties, as in the study)",
    )
    learn.add_argument(
        "--virulence",
        type=float,
        help="in (0, 1]: classifiers are fittest at this score rather than at the highest, "
        "so they leave replicas something to learn from (reduced virulence; default 0.75; 1: "
        "the study's method)",
    )
    learn.add_argument(
        "--trials",
        type=int,
        help="starts each generation is judged on, every fitness averaged over them (default "
        "1, as in the study; the time per generation grows with it)",
    )
    learn.add_argument(
        "--radius-start",
        type=float,
        metavar="UNITS",
        help="where the classifiers' learned radii start (default: the middle of their range, "
        "150 units bounded; a radius near the ideal fish's spacing, e.g. 30, lets classifiers "
        "judge spacing early)",
    )
    learn.add_argument(
        "--replica",
        choices=REPLICA_KINDS,
        help="how a replica's network makes a neighbour's contribution: isotropic (default): "
        "the network sees the neighbour straight ahead at its distance and its answer is "
        "turned by the neighbour's bearing, the same law in every direction; study: the "
        "network sees the neighbour's position in the arena's axes and its answer is the "
        "push (its replicas can drift as one school); reciprocal: the odd part of the "
        "study's, so that neighbours on opposite sides push opposite ways",
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
        "--resume",
        action="store_true",
        help="continue from OUT/checkpoint.npz up to --generations, with the settings it was "
        "learned with (naming a different one stops with a message)",
    )
    learn.add_argument(
        "--force",
        action="store_true",
        help="start over in an OUT that holds a learning run, replacing it (without it, such "
        "an OUT is refused)",
    )
    learn.add_argument("--quiet", action="store_true", help="no progress lines")

    behaviors = commands.add_parser(
        "behaviors",
        help="list the behaviours there are, other packages' too, with their own settings",
        description="List the behaviours fish can have: fishswarm's own and those other "
        "installed packages add (docs/behaviors.md), each with what it does, the package it "
        "comes from, and its own settings with their defaults (set with --behavior-setting "
        "NAME=VALUE or behavior_settings in a scenario file); and any package's behaviour "
        "that was left out, with why.",
    )
    behaviors.add_argument(
        "--check",
        metavar="NAME",
        help="check the behaviour NAME against the rules every behaviour keeps, on random "
        "perceptions (seeded): it decides when no fish sees anyone; a batch gives what each "
        "fish alone gives, memory included; padding rows change nothing; the same inputs give "
        "the same outputs. Exit 1 if it breaks one",
    )
    _add_behavior_settings(
        behaviors, "with --check: one of the behaviour's own settings to check it with (repeat)"
    )
    export = commands.add_parser(
        "export",
        help="export a recording to NumPy or CSV",
        description="Write arrays t (T,), pos (T,N,3), vel (T,N,3), "
        "yaw (T,N), ids (N,) in SI units to .npz, and/or a flat CSV.",
    )
    export.add_argument("recording", type=Path, help="MCAP recording of a run")
    export.add_argument("--npz", type=Path, help="NumPy archive to write")
    export.add_argument("--csv", type=Path, help="CSV table to write")
    add_study_parsers(commands)
    return parser


SECURE_HELP = (
    "a secured swarm's folder (made by 'fishswarm secure init'): connect over mutual TLS "
    "with this command's certificate; --connect must then be a tls/ endpoint"
)


def _add_view_flags(parser: argparse.ArgumentParser) -> None:
    # No defaults here (ViewSettings has them): a flag given where no view is served is
    # refused, not ignored.
    parser.add_argument(
        "--host",
        help="with a live view: the name or address browsers reach this machine by; the page "
        "streams from it (default localhost: a browser on this machine)",
    )
    parser.add_argument(
        "--web-port",
        type=int,
        help=f"with a live view: port of the page (default {WEB_PORT})",
    )
    parser.add_argument(
        "--grpc-port",
        type=int,
        help=f"with a live view: port of the data stream the page reads (default {GRPC_PORT})",
    )


def _add_connect(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--connect",
        default=None,
        help=f"router endpoint to connect to (default {DEFAULT_ENDPOINT}, with --secure "
        f"{SECURE_ENDPOINT})",
    )
    parser.add_argument("--secure", type=secure_folder, metavar="DIR", help=SECURE_HELP)
    parser.add_argument(
        "--connect-timeout",
        type=longest_wait,
        default=10.0,
        help="longest wait for the router, s; negative waits forever (default %(default)g)",
    )
