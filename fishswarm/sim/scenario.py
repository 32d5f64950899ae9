"""A scenario: everything that defines a run, with defaults from SPEC.md and TOML loading.

Settings come from defaults, then an optional TOML file, then command-line overrides. Every
value is checked when the scenario is built; a bad one raises :class:`ConfigError` that says
which setting is wrong and what would be right.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import FishParams
from fishswarm.behaviors.formation import (
    DEFAULT_EFFORT_MARGIN,
    DEFAULT_LEAD,
    LOCAL_RULES,
    SLOT_RULES,
)
from fishswarm.behaviors.lennard_jones import (
    STUDY_FORM_SWITCH,
    LennardJonesParams,
    steer_lennard_jones,
)
from fishswarm.behaviors.orbit import ORBIT_RADIUS
from fishswarm.behaviors.registry import (
    STUDY_HOMING_SWITCH,
    behavior_named,
    fish_params,
    names,
    plugin_failures,
)
from fishswarm.bluebot.control import CONTROLLERS
from fishswarm.bluebot.parameters import (
    BLIND_WIDTH,
    SPHERE_RADIUS,
    VISUAL_RANGE,
    BlueBot,
    Tank,
)
from fishswarm.bluebot.vision import Vision
from fishswarm.formations.maps import MAX_FISH as MAX_MAP_FISH
from fishswarm.protocols.checks import MAX_TICK
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import FORMATION_SHAPES, MAX_SETTING_TEXT
from fishswarm.sim.wake import WAKE_LENGTH, WAKE_WIDTH

SPAWN_REGIONS = ("ball", "tank")
TIME_MODES = ("lockstep", "jitter", "realtime")
VISION_MODELS = ("geometric", "camera")
FLAG_MEDIA = ("channel", "light", "beacon")
"""How formation flags travel in a simulation: the simulated channel (every flag, within its
range); light, as between robots (only "I hold my place", to the fish that see the sender);
or a beacon (only "I hold my place", within the channel's range: what a robot's medium would
need to reach fish that do not see it, docs/robot.md)."""
STUDY_CODE_SWITCHES = {
    "euler-step": "Euler step 0.1 s, yaw turned by the rate before each substep's update",
    "drag": "backward drag 1.0, lateral and yaw drag growing with forward speed",
    STUDY_FORM_SWITCH: "the force times the unscaled relative position, gamma*epsilon = "
    "100*100 in mm",
    STUDY_HOMING_SWITCH: "a target straight ahead or absent drives the right pectoral fin (a "
    "lone fish circles)",
    "manhattan": "neighbours linked within the visual range as |dx|+|dy|+|dz|",
    "start-delay": "fish are held still for the first two control periods",
    "side-settings": "the experiments' other vision setting: a 50-mm sphere in the blind-spot "
    "runs, a 50-mm blind spot in the blocking-sphere runs",
    "mean-distance": "experiments also report the study's mean distance (centroid of linked "
    "neighbours, third sample vs last)",
}
"""Ways the study's published code differs from its paper's equations (SPEC §8) that a
scenario can switch on one by one, with what each does; docs/fidelity.md measures them."""
EXPERIMENT_SWITCHES = ("side-settings", "mean-distance")
"""The switches that only ``fishswarm experiment`` acts on (a sweep's other settings, a
column of its table): a single run has nothing for them to change."""

PROFILES = ("paper", "study-code")
"""``paper``: the paper's equations, plus the switches named in ``study_code``;
``study-code``: every switch of :data:`STUDY_CODE_SWITCHES`."""

MAX_CONTROL_PERIOD = 60.0
"""The longest control period, s: a period's Euler steps are held in memory at once."""
MAX_TARGET_DISTANCE = 1000.0
"""The farthest Lennard-Jones r_t, m (beyond some 10²⁵ times the fish's distance, its
twelfth powers overflow)."""
START_TIMEOUT = 60.0
"""How long a run's world waits for its fish to come up by default, s."""
TURN_DELAY = 0.1
"""How long after it came up a world takes its turn at the earliest by default, s: the places
in the queue of the worlds of its swarm up before it reach it first."""
COMMAND_TIMEOUT = 10.0
"""How long a run's world waits for a fish's command before it marks the fish lost, by
default, s."""
START_DELAY_PERIODS = 2
"""Control periods the study code's fish stood still at the start of a run (its fish moved
only once their clock passed 1)."""


_FORMING = ("behavior", ("formation",))
APPLIES_WHEN: dict[str, tuple[tuple[str, tuple[object, ...] | None], ...]] = {
    **{
        name: (_FORMING,)
        for name in (
            "formation",
            "spacing",
            "tolerance",
            "formation_heading_deg",
            "formation_lead",
            "flags",
            "slot_rule",
            "local_rule",
            "switch_formation",
        )
    },
    "flag_medium": (_FORMING, ("flags", (True,))),
    # A swap is asked and agreed by the numbers of a flag: one bit by light or beacon
    # cannot carry them.
    "rotate_effort": (_FORMING, ("flags", (True,)), ("flag_medium", ("channel",))),
    "effort_margin": (
        _FORMING,
        ("rotate_effort", (True,)),
        ("flags", (True,)),
        ("flag_medium", ("channel",)),
    ),
    "switch_at": (_FORMING, ("switch_formation", None)),
    **{
        name: (("vision_model", ("geometric",)),)
        for name in ("visual_range", "blind_width", "sphere_radius", "vision_noise")
    },
    "model": (("behavior", ("replica",)),),
    "orbit_radius": (("behavior", ("orbit", "milling", "waltz")),),
    "jitter": (("time_mode", ("jitter",)),),
    "spawn_radius": (("spawn_region", ("ball",)),),
}
"""Settings that mean something only beside others: for each, (that setting, the values it
must have, None for any but none), in the order they are checked. Elsewhere they change
nothing, and are refused or warned of."""


def _sees_geometrically(scenario: Scenario) -> bool:
    """Whether the geometric vision model serves a run whose fish see each other through
    their cameras: landmarks, and formation flags by light, are seen by it."""
    by_light = scenario.behavior == "formation" and scenario.flags
    return scenario.landmarks().shape[0] > 0 or (by_light and scenario.flag_medium == "light")


_APPLIES_ANYWAY: dict[str, tuple[Callable[[Scenario], bool], str]] = dict.fromkeys(
    ("visual_range", "blind_width", "sphere_radius", "vision_noise"),
    (
        _sees_geometrically,
        "with cameras, vision settings still count where a landmark or formation flags "
        "by light are seen (the geometric model sees those)",
    ),
)
"""Settings that mean something, beside :data:`APPLIES_WHEN`'s conditions, when these say
so: (the test, the exception in words)."""


def applies_anyway(name: str) -> str:
    """The exception to setting ``name``'s conditions, in words, after a semicolon, to close a
    message saying it does not apply (empty when there is none)."""
    anyway = _APPLIES_ANYWAY.get(name)
    return "" if anyway is None else f"; {anyway[1]}"


def unmet_condition(name: str, scenario: Scenario) -> tuple[str, str] | None:
    """The first condition of :data:`APPLIES_WHEN` that ``scenario`` leaves setting ``name``
    without: (the setting, what it must be, in words: ``formation``, ``true`` or ``set``);
    None when ``name`` means something."""
    anyway = _APPLIES_ANYWAY.get(name)
    if anyway is not None and anyway[0](scenario):
        return None
    for setting, values in APPLIES_WHEN.get(name, ()):
        value = getattr(scenario, setting)
        if values is None and value is None:
            return setting, "set"
        if values is not None and value not in values:
            return setting, either(values)
    return None


def setting_text(value: object) -> str:
    """A setting's value as a scenario file spells it: ``true``, ``none``, ``formation``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return "none" if value is None else str(value)


def _own_settings(behavior: str, given: object) -> tuple[tuple[str, bool | int | float | str], ...]:
    """A behaviour's own settings, checked against what it declares: (name, value) pairs in
    name order, a number given as a whole number taken as a float where the default is one.

    Raises:
        ConfigError: not a table of names and values, a name the behaviour lacks, or a value
            of another kind than its default.
    """
    pairs = given.items() if isinstance(given, Mapping) else given
    try:
        settings = dict(pairs)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        raise ConfigError(
            f"behavior_settings must be a table of NAME = VALUE, e.g. {{ gain = 0.5 }}, got "
            f"{as_written(given)}"
        ) from None
    declared = behavior_named(behavior).settings
    checked: dict[str, bool | int | float | str] = {}
    for name, value in settings.items():
        if name not in declared:
            known = (
                f"its settings are {', '.join(declared)}"
                if declared
                else "it has no settings of its own"
            )
            raise ConfigError(f"behavior_settings: {behavior} has no setting {name!r}; {known}")
        default = declared[name]
        kind, words = _SETTING_KINDS[type(default).__name__]
        if isinstance(value, str) and len(value) > MAX_SETTING_TEXT:
            raise ConfigError(
                f"behavior_settings: {name} of {behavior} must be at most {MAX_SETTING_TEXT} "
                f"characters, got {len(value)}"
            )
        if not kind(value):
            raise ConfigError(
                f"behavior_settings: {name} of {behavior} must be {words} (its default is "
                f"{as_written(default)}), got {as_written(value)}"
            )
        checked[name] = float(value) if isinstance(default, float) else value
    return tuple(sorted(checked.items()))


def own_setting_from_text(behavior: str, name: str, text: str) -> bool | int | float | str:
    """``text`` given on a command line for the own setting ``name`` of ``behavior``, read
    as the kind of its default; as it is where it cannot be (the scenario then says why)."""
    try:
        default = behavior_named(behavior).settings.get(name)
    except ValueError:
        return text
    if isinstance(default, bool):
        return {"true": True, "false": False}.get(text, text)
    for kind in (int, float):
        if isinstance(default, kind):
            try:
                return kind(text)
            except ValueError:
                return text
    return text


def behavior_text(
    behavior: object, own: Mapping[str, object] | Iterable[tuple[str, object]] | None = ()
) -> str:
    """A behaviour and the own settings a run gave it, for a title or a first line:
    ``nearest (distance 0.3, cruise 0.5)``; the name alone when none were given.

    Args:
        behavior: its name (anything else, e.g. None from a file that lacks it: ``?``).
        own: its own settings, as a scenario holds them or a recording's table."""
    pairs = own.items() if isinstance(own, Mapping) else (own or ())
    given = ", ".join(f"{name} {setting_text(value)}" for name, value in pairs)
    name = behavior if isinstance(behavior, str) else "?"
    return f"{name} ({given})" if given else name


def as_written(value: object) -> str:
    """A value read from a TOML file, spelled as the file spells it, to show what it holds:
    ``true``, not ``True``; ``"ten"`` in double quotes; lists in brackets (where
    :func:`setting_text` names a setting's value in words)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list | tuple):
        return f"[{', '.join(as_written(item) for item in value)}]"
    return repr(value)


def either(values: tuple[object, ...]) -> str:
    """``values`` as words: ``a``, ``a or b``, ``a, b or c``."""
    words = [setting_text(value) for value in values]
    return " or ".join([", ".join(words[:-1]), words[-1]] if words[1:] else words)


def switch_names(text: str) -> tuple[str, ...]:
    """Study-code switches as written on a command line: ``drag,euler-step`` → ("drag",
    "euler-step"); an empty text → none."""
    return tuple(name.strip() for name in text.split(",") if name.strip())


FloatArray = NDArray[np.float64]


class ConfigError(ValueError):
    """A scenario setting is missing, unknown or out of range; the message says how to fix it."""


@dataclass(frozen=True)
class Scenario:
    """The settings of one run.

    Attributes:
        fish: number of fish.
        behavior: ``dispersion``, ``aggregation`` or ``replica`` (a learned replica, see
            ``fishswarm learn``; needs ``model``).
        duration: simulated time, s.
        control_period: time between two decisions of a fish, s (1 Hz in the study).
        seed: master seed; every random stream derives from (seed, role, id).
        controller: ``homing`` (the research code's) or ``pid``; default: the behaviour's
            (``pid`` for ``formation``, ``homing`` for the others).
        caudal_cap: largest caudal gain the homing controller uses.
        target_distance: Lennard-Jones r_t, m; default 0.26 for aggregation, the tank
            diagonal for dispersion.
        spawn_radius: fish start uniformly within this distance of the tank centre, m; default
            2 body lengths for dispersion, 10 for aggregation (the study's set-ups).
        spawn_region: ``ball`` (within ``spawn_radius`` of the centre, clipped to the tank) or
            ``tank`` (uniform over the whole tank).
        tank: tank size (x, y, z), m.
        visual_range, blind_width, sphere_radius, vision_noise: the vision model (SPEC §1.2).
        vision_model: ``geometric`` (who is in range, outside the blind strip and not behind
            another's blocking sphere is seen exactly, plus ``vision_noise``) or ``camera``
            (both camera images of every fish rendered and read by the robot's LED pipeline:
            misses, false pairs and range errors as on a BlueBot; docs/camera.md).
        channel_range: how far a broadcast carries, m.
        channel_loss: probability that one delivery is lost, in [0, 1).
        swarm: swarm name in the key space.
        model: a learned replica (``best_replica.npz``) for the ``replica`` behaviour.
        orbit_radius: R of ``orbit`` and ``milling``; the partner distance of ``waltz``, m.
        landmark: position (x, y, z) of a fixed, visible landmark in the tank, m; the orbit
            centre. Default for ``orbit`` and ``milling``: the tank centre; otherwise none.
        time_mode: ``lockstep`` (every tick waits for every live fish: as fast as the machine
            allows, deterministic), ``jitter`` (each fish decides on its own clock, periods
            drawn from N(control_period, jitter); simulated time goes event by event;
            deterministic) or ``realtime`` (one tick per control period of wall-clock time; a
            fish that misses its deadline keeps its last command, as on hardware).
        jitter: standard deviation of a fish's control period in ``jitter`` mode, s.
        formation: the ``formation`` behaviour's shape: a global map (fibonacci, pyramid,
            column, tetrahedral-pyramid, diamond, phalanx) or a local shape (triangle,
            trigonal-planar, tetrahedron); default pyramid.
        spacing: distance between neighbouring places of a formation, m (default 0.3).
        tolerance: a formation fish this close to its place has joined, m (default
            spacing / 4).
        formation_heading_deg: the direction a formation faces, degrees in the tank frame.
        formation_lead: a formation fish aims short of its place by the drift it predicts
            over this time from its velocity relative to the place, s (0: at the place).
        flags: whether formation fish broadcast and heed formation flags.
        flag_medium: how the flags travel (:data:`FLAG_MEDIA`): ``channel`` (default: the
            simulated channel, every flag to every fish within ``channel_range``), ``light``
            (as between robots, docs/robot.md: only a flag that says its sender holds its
            place, telling nothing else, to the fish that see the sender — by the geometric
            vision model, whatever ``vision_model`` says) or ``beacon`` (the same flag, to
            every fish within ``channel_range``).
        slot_rule: how formation fish pick slots of a global map: ``share`` (default) or
            ``study`` (the study's rank rule).
        local_rule: how formation fish make a local shape: ``lattice`` (default: places on
            a map where every fish completes the shape, anchored at the leader, for shapes
            that have one — trigonal planar and tetrahedron) or ``neighbors`` (spots next
            to their nearest neighbours; triangles are always made so).
        switch_formation: a shape formation fish switch to during the run (as an operator
            would with ``fishswarm formation``), at ``switch_at`` s.
        switch_at: when the switch happens, s of simulated time.
        flow: the water's velocity in the tank frame (a flow tank), m/s; still by default.
        wake_saving: how much of its surge drag a fish right behind another saves (0: no
            wake model, the default; :mod:`fishswarm.sim.wake`), in [0, 1).
        wake_length: how far behind a swimming fish its wake reaches, m.
        wake_width: the radius of a fish's wake about its axis, m.
        station_distance: with a ``landmark``, a formation's leader holds station this far
            behind it (against the formation's heading), m; None: the leader stays where it
            is (no station).
        rotate_effort: a formation fish that has spent ``effort_margin`` (gain-weighted fin
            beats) more than the most rested fish it hears swaps places with it (formation
            flags carry each fish's effort; global maps with flags).
        effort_margin: the margin of ``rotate_effort``, gain-weighted fin beats.
        study_code: where to follow the study's code instead of its paper's equations, by
            name (:data:`STUDY_CODE_SWITCHES`); none by default.
        profile: ``paper`` (default: the paper's equations and the ``study_code`` switches)
            or ``study-code`` (every switch: the model the study's tables came from).
        behavior_settings: the behaviour's own settings (those its family declares, e.g.
            a package's behaviour, docs/behaviors.md), as (name, value) pairs in name order;
            given as a mapping (a TOML table) too. Each of the kind of its default (a whole
            number given for a number is taken as one); the rest keep their defaults.
    """

    fish: int = 25
    behavior: str = "dispersion"
    duration: float = 15.0
    control_period: float = 1.0
    seed: int = 0
    controller: str | None = None
    caudal_cap: float = 1.0
    target_distance: float | None = None
    spawn_radius: float | None = None
    spawn_region: str = "ball"
    tank: tuple[float, float, float] = Tank().size
    visual_range: float = VISUAL_RANGE
    blind_width: float = BLIND_WIDTH
    sphere_radius: float = SPHERE_RADIUS
    vision_noise: float = 0.0
    vision_model: str = "geometric"
    channel_range: float = 3.0
    channel_loss: float = 0.0
    swarm: str = "default"
    model: str | None = None
    orbit_radius: float = ORBIT_RADIUS
    landmark: tuple[float, float, float] | None = None
    time_mode: str = "lockstep"
    jitter: float = 0.05
    formation: str | None = None
    spacing: float | None = None
    tolerance: float | None = None
    formation_heading_deg: float = 0.0
    formation_lead: float = DEFAULT_LEAD
    flags: bool = True
    flag_medium: str = "channel"
    slot_rule: str = "share"
    local_rule: str = "lattice"
    switch_formation: str | None = None
    switch_at: float = 0.0
    flow: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wake_saving: float = 0.0
    wake_length: float = WAKE_LENGTH
    wake_width: float = WAKE_WIDTH
    station_distance: float | None = None
    rotate_effort: bool = False
    effort_margin: float = DEFAULT_EFFORT_MARGIN
    study_code: tuple[str, ...] = ()
    profile: str = "paper"
    behavior_settings: tuple[tuple[str, bool | int | float | str], ...] = ()

    def __post_init__(self) -> None:
        def need(ok: bool, message: str) -> None:
            if not ok:
                raise ConfigError(message)

        need(
            isinstance(self.fish, int) and 1 <= self.fish <= 100_000,
            f"fish must be a whole number from 1 to 100000, got {self.fish!r}",
        )
        need(
            isinstance(self.flags, bool) and isinstance(self.rotate_effort, bool),
            f"flags and rotate_effort must be true or false, got {self.flags!r} and "
            f"{self.rotate_effort!r}",
        )
        need(
            len(self.flow) == 3 and all(math.isfinite(v) for v in self.flow),
            f"flow must be a velocity (x, y, z) in m/s, got {self.flow!r}",
        )
        need(
            0.0 <= self.wake_saving < 1.0,
            f"wake_saving must be a fraction in [0, 1), got {self.wake_saving!r}",
        )
        need(
            self.wake_length > 0 and self.wake_width > 0,
            f"wake_length and wake_width must be positive lengths, got {self.wake_length!r} "
            f"and {self.wake_width!r}",
        )
        need(
            self.station_distance is None or self.station_distance >= 0,
            f"station_distance must be a length of 0 m or more, got {self.station_distance!r}",
        )
        need(
            self.station_distance is None or self.landmark is not None,
            "station_distance needs a landmark to hold station behind (landmark = [x, y, z])",
        )
        need(
            self.effort_margin >= 0,
            "effort_margin must be 0 or more (gain-weighted fin beats), got "
            f"{self.effort_margin!r}",
        )
        if self.behavior not in names():
            left_out = [str(f) for f in plugin_failures() if f.name == self.behavior]
            raise ConfigError(
                f"behavior must be one of {', '.join(names())}, got {self.behavior!r}"
                + (f": {left_out[0]}" if left_out else "")
            )
        object.__setattr__(
            self, "behavior_settings", _own_settings(self.behavior, self.behavior_settings)
        )
        if self.controller is None:
            object.__setattr__(self, "controller", behavior_named(self.behavior).controller)
        need(
            self.controller in CONTROLLERS,
            f"controller must be one of {', '.join(CONTROLLERS)}, got {self.controller!r}",
        )
        need(
            self.behavior != "replica" or self.model is not None,
            "the replica behavior needs a learned model: --model runs/learn/best_replica.npz "
            "(make one with 'fishswarm learn')",
        )
        if self.model is not None and Path(self.model).is_dir():
            inside = Path(self.model) / "best_replica.npz"
            hint = (
                f": give {inside}" if inside.is_file() else " ('fishswarm learn --out' writes one)"
            )
            need(False, f"model {self.model} is a folder, not a learned replica file{hint}")
        need(
            self.model is None or Path(self.model).is_file(),
            f"model file {self.model} does not exist",
        )
        need(
            self.spawn_region in SPAWN_REGIONS,
            f"spawn_region must be one of {', '.join(SPAWN_REGIONS)}, got {self.spawn_region!r}",
        )
        for name in ("duration", "control_period"):
            value = getattr(self, name)
            need(_positive(value), f"{name} must be a positive number of seconds, got {value!r}")
        need(
            self.control_period <= MAX_CONTROL_PERIOD,
            f"control_period must be at most {MAX_CONTROL_PERIOD:g} s (a fish decides at least "
            f"once a minute; the physics takes {1 / BlueBot().euler_step:g} steps a second), "
            f"got {self.control_period:g}",
        )
        need(
            isinstance(self.seed, int) and 0 <= self.seed <= MAX_TICK,
            # The bound: the world tells its settings in a message, whose integers are held
            # to it.
            f"seed must be a whole number from 0 to 2**62 ({MAX_TICK}), got {self.seed!r}",
        )
        need(
            _positive(self.caudal_cap) and self.caudal_cap <= 1,
            f"caudal_cap must be in (0, 1], got {self.caudal_cap!r}",
        )
        for name in ("target_distance", "spawn_radius"):
            value = getattr(self, name)
            need(
                value is None or _positive(value), f"{name} must be positive metres, got {value!r}"
            )
        need(
            self.target_distance is None or self.target_distance <= MAX_TARGET_DISTANCE,
            f"target_distance must be at most {MAX_TARGET_DISTANCE:g} m (farther, the "
            f"Lennard-Jones forces overflow), got {self.target_distance!r}",
        )
        try:
            Tank(tuple(self.tank))  # type: ignore[arg-type]
            self.vision()
            KeySpace(self.swarm)
        except ValueError as error:
            raise ConfigError(str(error)) from None
        need(_positive(self.orbit_radius), "orbit_radius must be positive metres")
        need(
            isinstance(self.jitter, int | float)
            and math.isfinite(self.jitter)
            and self.jitter >= 0,
            f"jitter must be a non-negative standard deviation, s, got {self.jitter!r}",
        )
        # Settings checked together, naming both (the user may have set only one of them).
        need(
            self.time_mode != "jitter" or self.jitter <= self.control_period,
            f"jitter ({self.jitter:g} s) must not exceed the control period "
            f"({self.control_period:g} s) in jitter mode: lower the jitter or lengthen the "
            "control period",
        )
        need(
            self.duration >= self.control_period,
            f"duration ({self.duration:g} s) is shorter than one control period "
            f"({self.control_period:g} s): nothing would happen; lengthen the duration or "
            "shorten the control period",
        )
        # Around a post the circle's radius is R; partners R apart circle at R/2.
        widest = min(self.tank[0], self.tank[1]) / (1 if self.behavior == "waltz" else 2)
        need(
            self.behavior not in ("orbit", "milling", "waltz") or self.orbit_radius < widest,
            f"orbit_radius ({self.orbit_radius:g} m) does not fit in the tank "
            f"({self.tank[0]:g} × {self.tank[1]:g} m): keep it below {widest:g} m",
        )
        unknown = [name for name in self.study_code if name not in STUDY_CODE_SWITCHES]
        need(
            not unknown,
            f"study_code: unknown switch(es) {', '.join(map(repr, unknown))}; the switches are "
            f"{', '.join(STUDY_CODE_SWITCHES)}",
        )
        need(
            self.profile in PROFILES,
            f"profile must be one of {', '.join(PROFILES)}, got {self.profile!r}",
        )
        need(
            "manhattan" not in self.study_switches or self.vision_model == "geometric",
            "the study code's Manhattan links change the geometric vision model; with "
            "vision_model camera the cameras decide what is seen: drop 'manhattan' from "
            "study_code, or use profile paper with the other switches",
        )
        need(
            self.vision_model in VISION_MODELS,
            f"vision_model must be one of {', '.join(VISION_MODELS)}, got {self.vision_model!r}",
        )
        need(
            self.time_mode in TIME_MODES,
            f"time_mode must be one of {', '.join(TIME_MODES)}, got {self.time_mode!r}",
        )
        need(
            self.slot_rule in SLOT_RULES,
            f"slot_rule must be one of {', '.join(SLOT_RULES)}, got {self.slot_rule!r}",
        )
        need(
            self.local_rule in LOCAL_RULES,
            f"local_rule must be one of {', '.join(LOCAL_RULES)}, got {self.local_rule!r}",
        )
        need(
            not (self.behavior == "formation" and self.flags and self.time_mode == "jitter"),
            "formation flags are not delivered in jitter mode (each fish decides on its own "
            "clock; docs/architecture.md): use --time lockstep or realtime, or --no-flags",
        )
        if self.landmark is not None:
            size = self.tank
            need(
                len(self.landmark) == 3
                and all(0 <= v <= s for v, s in zip(self.landmark, size, strict=True)),
                f"landmark must be a point (x, y, z) inside the tank {tuple(size)}, "
                f"got {self.landmark!r}",
            )
        need(_positive(self.channel_range), "channel_range must be positive metres")
        need(
            self.flag_medium in FLAG_MEDIA,
            f"flag_medium must be one of {', '.join(FLAG_MEDIA)}, got {self.flag_medium!r}",
        )
        need(
            isinstance(self.channel_loss, int | float) and 0 <= self.channel_loss < 1,
            f"channel_loss must be a probability in [0, 1), got {self.channel_loss!r}",
        )
        need(
            self.switch_formation is None or self.switch_formation in FORMATION_SHAPES,
            f"switch_formation must be one of {', '.join(FORMATION_SHAPES)}, "
            f"got {self.switch_formation!r}",
        )
        need(
            self.behavior != "formation" or self.fish <= MAX_MAP_FISH,
            f"a formation is for at most {MAX_MAP_FISH} fish (its map's places), got "
            f"{self.fish}: give --fish {MAX_MAP_FISH} or fewer",
        )
        need(
            isinstance(self.formation_lead, int | float) and 0 <= self.formation_lead < 60,
            f"formation_lead must be a time in [0, 60) s, got {self.formation_lead!r}",
        )
        need(
            isinstance(self.switch_at, int | float) and 0 <= self.switch_at <= self.duration,
            f"switch_at must be a time within the run, [0, {self.duration:g}] s (its duration), "
            f"got {self.switch_at!r}",
        )
        need(
            _real(self.formation_heading_deg),
            f"formation_heading_deg must be a finite angle, got {self.formation_heading_deg!r}",
        )
        for name in ("spacing", "tolerance"):
            value = getattr(self, name)
            need(
                value is None or _positive(value), f"{name} must be positive metres, got {value!r}"
            )

    def check_duration(self) -> Scenario:
        """This scenario, checked to run for a whole number of control periods (called
        where a run of it starts: ``run``, ``world``, experiments; a robot's fish never
        uses the duration, and a recording says what already ran).

        Raises:
            ConfigError: it does not, with the two nearest durations that do.
        """
        periods = self.duration / self.control_period
        if abs(periods - round(periods)) > 1e-9 * max(1.0, periods):
            raise ConfigError(
                f"duration ({self.duration:g} s) must be a whole number of control periods "
                f"({self.control_period:g} s): e.g. "
                f"{math.floor(periods) * self.control_period:g} or "
                f"{math.ceil(periods) * self.control_period:g} s"
            )
        return self

    @property
    def ticks(self) -> int:
        """Number of control periods in the run (a whole number: checked on construction)."""
        return max(1, round(self.duration / self.control_period))

    @property
    def keys(self) -> KeySpace:
        """The key space of this scenario's swarm."""
        return KeySpace(self.swarm)

    def the_tank(self) -> Tank:
        """The tank as a :class:`Tank`."""
        return Tank(tuple(self.tank))  # type: ignore[arg-type]

    @classmethod
    def crowded(cls, fish: int, *, neighbors: float = 25.0, **settings: Any) -> Scenario:
        """A scenario whose tank grows with the swarm so that each fish has about
        ``neighbors`` others within visual range (for benchmarks of large swarms).

        The study's tank is kept up to 25 fish. Beyond, the horizontal area is chosen so that
        a disc of visual range holds ``neighbors`` fish on average; fish start uniformly over
        the whole tank.
        """
        base = cls(**settings)
        if fish <= 25:
            return base.replace(fish=fish)
        area = fish * math.pi * base.visual_range**2 / neighbors
        side = math.sqrt(area)
        return base.replace(fish=fish, tank=(side, side, base.tank[2]), spawn_region="tank")

    @property
    def study_switches(self) -> tuple[str, ...]:
        """The study code's switches in effect: every one under the ``study-code`` profile,
        else those named in :attr:`study_code`."""
        if self.profile == "study-code":
            return tuple(STUDY_CODE_SWITCHES)
        return self.study_code

    @property
    def still_until(self) -> float:
        """Until when fish are held still at the start, s (0 but for the start delay)."""
        if "start-delay" in self.study_switches:
            return START_DELAY_PERIODS * self.control_period
        return 0.0

    def robot(self) -> BlueBot:
        """The simulated BlueBot: the paper's, with the study code's integration and drag
        where :attr:`study_switches` say so."""
        study = set(self.study_switches)
        return BlueBot(
            euler_step=0.1 if "euler-step" in study else BlueBot.euler_step,
            yaw_before_update="euler-step" in study,
            speed_dependent_drag="drag" in study,
        )

    @property
    def flag_sight(self) -> Vision | None:
        """The vision by which formation flags travel: with flags by light, the fish that
        see a flag's sender receive it; None: those within ``channel_range``."""
        return self.vision() if self.flag_medium == "light" else None

    @property
    def one_bit_flags(self) -> bool:
        """Whether formation flags say only "I hold my place" (by light or by beacon)."""
        return self.flag_medium in ("light", "beacon")

    def vision(self) -> Vision:
        """The vision model."""
        return Vision(
            self.visual_range,
            self.blind_width,
            self.sphere_radius,
            self.vision_noise,
            manhattan="manhattan" in self.study_switches,
        )

    def fish_params(self) -> FishParams:
        """What the fish's decisions depend on: behaviour, controller and their parameters
        (reads a replica's model file).

        Raises:
            ConfigError: a parameter the behaviour cannot take, or an unreadable model.
        """
        settings = dataclasses.asdict(self)
        settings["study_code"] = self.study_switches
        try:
            return fish_params(settings)
        except ValueError as error:
            raise ConfigError(str(error)) from None

    def resolved_target_distance(self) -> float | None:
        """Lennard-Jones r_t after defaults: 0.26 m for aggregation, the tank diagonal for
        dispersion; None for behaviours that have none."""
        family = behavior_named(self.behavior)
        if self.target_distance is not None or family.steer is not steer_lennard_jones:
            return self.target_distance
        params: LennardJonesParams = family.parameters(dataclasses.asdict(self))
        return params.target_distance

    def landmarks(self) -> FloatArray:
        """(L, 3) positions of the fixed landmarks in the tank, m (the orbit centre first)."""
        if self.landmark is not None:
            return np.array([self.landmark], dtype=np.float64)
        if behavior_named(self.behavior).circles_landmark:
            return np.array([self.the_tank().center], dtype=np.float64)
        return np.zeros((0, 3))

    def resolved_spawn_radius(self) -> float:
        """Spawn radius after defaults: 2 body lengths (dispersion) or 10 (aggregation and
        replica)."""
        if self.spawn_radius is not None:
            return self.spawn_radius
        return behavior_named(self.behavior).spawn_radius

    def replace(self, **changes: Any) -> Scenario:
        """A copy with some settings changed (``None`` values are ignored); see
        :meth:`with_settings`, whose guess it takes on whether the controller was chosen."""
        return self.with_settings(changes)

    def with_settings(
        self, changes: Mapping[str, Any], *, controller_chosen: bool | None = None
    ) -> Scenario:
        """A copy with some settings changed (``None`` values are ignored). Another
        behaviour without a controller named brings its own default controller, unless this
        scenario's controller was chosen: ``controller_chosen`` says whether it was (e.g.
        named in its file); None guesses it from whether it differs from its behaviour's
        default."""
        given = {k: v for k, v in changes.items() if v is not None}
        behavior = given.get("behavior", self.behavior)
        if controller_chosen is None:
            controller_chosen = self.controller != behavior_named(self.behavior).controller
        if behavior != self.behavior and "controller" not in given and not controller_chosen:
            given["controller"] = None  # resolved again from the new behaviour
        return dataclasses.replace(self, **given)

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain data (for the summary and the recording); a behaviour's own
        settings as a mapping, left out when there are none (as before there were any)."""
        data = dataclasses.asdict(self)
        if self.behavior_settings:
            data["behavior_settings"] = dict(self.behavior_settings)
        else:
            del data["behavior_settings"]
        data["tank"] = list(self.tank)
        data["target_distance"] = self.resolved_target_distance()
        data["spawn_radius"] = self.resolved_spawn_radius()
        return data

    @classmethod
    def as_recorded(cls, data: Mapping[str, Any], *, source: str = "the recording") -> Scenario:
        """The scenario a recording (or summary, or running world) says ran, read as it ran:
        a formation in jitter mode recorded with flags on, from before such runs were
        refused, ran without them (flags are not delivered in that mode)."""
        settings = dict(data)
        forming = settings.get("behavior") == "formation"
        if forming and settings.get("time_mode") == "jitter" and settings.get("flags", True):
            settings["flags"] = False
        return cls.from_mapping(settings, source=source)

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], *, source: str = "scenario") -> Scenario:
        """Build from a mapping (a parsed TOML table, or :meth:`to_dict`'s settings read back
        from a recording or summary, where None means "not set"), rejecting unknown keys."""
        known = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - set(known))
        if unknown:
            raise ConfigError(
                f"{source}: unknown setting(s) {', '.join(unknown)}; known settings are "
                f"{', '.join(sorted(known))}"
            )
        values = {name: value for name, value in data.items() if value is not None}
        if "study_code" in values:
            given = values["study_code"]
            if isinstance(given, str) or not isinstance(given, list | tuple):
                raise ConfigError(
                    f'{source}: study_code must be a list of switch names, e.g. ["drag"], '
                    f"got {as_written(given)}"
                )
            values["study_code"] = tuple(given)
        # The tank's size and the landmark's place are lengths; the flow is a velocity.
        for point, kind, unit in (
            ("tank", "lengths", "m"), ("landmark", "lengths", "m"), ("flow", "speeds", "m/s"),
        ):  # fmt: skip
            if point in values:
                given = values[point]
                if not isinstance(given, list | tuple) or len(given) != 3:
                    raise ConfigError(
                        f"{source}: {point} must be a list of three {kind} (x, y, z, {unit}), "
                        f"got {as_written(given)}"
                    )
                if not all(_real(v) for v in given):
                    raise ConfigError(
                        f"{source}: {point} must be a list of three numbers ({unit}), got "
                        f"{as_written(given)}"
                    )
                values[point] = tuple(float(v) for v in given)
        for name in (
            "duration",
            "control_period",
            "caudal_cap",
            "target_distance",
            "spawn_radius",
            "visual_range",
            "blind_width",
            "sphere_radius",
            "vision_noise",
            "channel_range",
            "channel_loss",
            "orbit_radius",
            "jitter",
            "spacing",
            "tolerance",
            "formation_heading_deg",
            "formation_lead",
            "switch_at",
            "wake_saving",
            "wake_length",
            "wake_width",
            "station_distance",
            "effort_margin",
        ):
            if isinstance(values.get(name), int) and not isinstance(values[name], bool):
                values[name] = float(values[name])
        for name, value in values.items():
            wanted = _SETTING_KINDS.get(str(known[name].type).split(" | ")[0])
            if wanted is not None and not wanted[0](value):
                raise ConfigError(f"{source}: {name} must be {wanted[1]}, got {as_written(value)}")
        try:
            return cls(**values)
        except ConfigError as error:
            raise ConfigError(f"{source}: {error}") from None
        except TypeError as error:
            raise ConfigError(f"{source}: {error}") from None

    @classmethod
    def from_toml(cls, path: Path) -> Scenario:
        """Load a scenario from a TOML file (keys as the attribute names; all optional)."""
        return cls.from_mapping(scenario_table(path), source=str(path))


def scenario_table(path: Path) -> dict[str, Any]:
    """The settings a scenario file names (its ``[scenario]`` table, or the whole file).

    Raises:
        ConfigError: the file cannot be read, is an experiment, or its table is not one.
    """
    data = read_toml(path, "scenario")
    if "experiment" in data:
        raise ConfigError(
            f"{path} is an experiment (it has an [experiment] table), not a scenario: run "
            f"it with 'fishswarm experiment {path}'"
        )
    table = data.get("scenario", data)
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [scenario] must be a table")
    outside = sorted(name for name in data if name != "scenario") if table is not data else []
    if outside:
        raise ConfigError(
            f"{path}: {', '.join(outside)} outside the [scenario] table would be ignored: "
            "put every setting in [scenario] (or leave the table out and write them at the "
            "top)"
        )
    return table


def read_toml(path: Path, kind: str) -> dict[str, Any]:
    """Parse a settings file.

    Raises:
        ConfigError: the ``kind`` file (e.g. "scenario") is missing, a folder, unreadable,
            not text (UTF-8) or not valid TOML.
    """
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{kind} file {path} does not exist") from None
    except IsADirectoryError:
        raise ConfigError(f"{path} is a folder, not {_a(kind)} file (a .toml file)") from None
    except OSError as error:
        raise ConfigError(f"{kind} file {path} cannot be read: {error.strerror}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path} is not a text file (UTF-8): not {_a(kind)} file") from None
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(f"{path} is not valid TOML: {error}") from None


def _a(noun: str) -> str:
    """``noun`` with its indefinite article: a scenario, an experiment."""
    return f"{'an' if noun[:1] in ('a', 'e', 'i', 'o', 'u') else 'a'} {noun}"


def _real(value: object) -> TypeGuard[float]:
    """A finite number (a bool is not one, though Python counts it as an int)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


_SETTING_KINDS: dict[str, tuple[Callable[[object], bool], str]] = {
    "float": (_real, "a finite number"),
    "int": (lambda value: isinstance(value, int) and not isinstance(value, bool), "a whole number"),
    "str": (lambda value: isinstance(value, str), "text (in quotes)"),
    "bool": (lambda value: isinstance(value, bool), "true or false"),
}
"""What a setting read from a file must be, by the type its field declares (a setting given
as None is "not set", and never checked)."""


def _positive(value: object) -> bool:
    return _real(value) and value > 0
