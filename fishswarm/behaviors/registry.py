"""The behaviours fish can have, by name: the one table the command line, scenario files,
experiments, the batch engine and the fish actor all read.

A new behaviour family is a :class:`~fishswarm.behaviors.core.Behavior` (its steering, its
memory, its parameters). fishswarm's own are in :data:`BEHAVIORS` from the start. Another
package adds its own through an entry point in the group ``fishswarm.behaviors``, named as
the behaviour (``circle = "my_fish.circle:CIRCLE"`` under
``[project.entry-points."fishswarm.behaviors"]``): installed beside fishswarm, it is known
to every command, worker process and robot there, read the first time the table is asked
for a name it does not hold yet (docs/behaviors.md). For an experiment of one's own in one
process, :func:`register` adds one.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import pickle
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fishswarm.behaviors.core import Behavior, FishParams
from fishswarm.behaviors.formation import FORMATION
from fishswarm.behaviors.lennard_jones import AGGREGATION, DISPERSION, STUDY_FORM_SWITCH
from fishswarm.behaviors.orbit import MILLING, ORBIT, WALTZ
from fishswarm.behaviors.replica import REPLICA
from fishswarm.bluebot.control import CONTROLLERS, PidGains
from fishswarm.protocols.checks import MAX_TEXT
from fishswarm.protocols.messages import MAX_SETTING_LIST, MAX_SETTING_TEXT

STUDY_HOMING_SWITCH = "homing"
"""The study-code switch (a scenario's ``study_code``) that selects the study's homing
branch for a target dead ahead or none (:attr:`FishParams.right_when_ahead`)."""

BEHAVIORS: dict[str, Behavior] = {
    family.name: family
    for family in (DISPERSION, AGGREGATION, ORBIT, MILLING, WALTZ, REPLICA, FORMATION)
}
"""Every behaviour by name, in the order ``--help`` lists them: fishswarm's own, then those
of other packages (once :func:`names` or a lookup has read them), then any registered."""

PLUGIN_GROUP = "fishswarm.behaviors"
"""The entry-point group in which other packages name their behaviours."""


@dataclass(frozen=True)
class PluginFailure:
    """A behaviour another package names that could not be added to the table.

    Attributes:
        name: the entry point's name.
        source: where it points (``module:attribute``), and the package that names it.
        reason: what went wrong, and what to do.
    """

    name: str
    source: str
    reason: str

    def __str__(self) -> str:
        return f"the behaviour {self.name!r} ({self.source}) is left out: {self.reason}"


_plugins_read = False
_plugin_failures: list[PluginFailure] = []
_plugin_sources: dict[str, str] = {}


def _read_plugins() -> None:
    """Add the behaviours other packages name (once a process): each checked, those that
    fail noted (:func:`plugin_failures`), never raised, so that one broken package does not
    stop every command."""
    global _plugins_read
    if _plugins_read:
        return
    _plugins_read = True
    from importlib.metadata import entry_points  # read when asked for: not on every import

    for point in sorted(entry_points(group=PLUGIN_GROUP), key=lambda point: point.name):
        package = f"{point.dist.name} {point.dist.version}" if point.dist is not None else None
        source = point.value if package is None else f"{point.value} in {package}"
        try:
            family = point.load()
        except Exception as error:  # whatever importing another package's code raises
            failed = f"loading it raised {type(error).__name__}: {error}"
            _plugin_failures.append(PluginFailure(point.name, source, failed))
            continue
        unfit = _unfit(point.name, family)
        if unfit is None:
            BEHAVIORS[point.name] = family
            _plugin_sources[point.name] = source
        else:
            _plugin_failures.append(PluginFailure(point.name, source, unfit))


def _unfit(name: str, family: object) -> str | None:
    """Why ``family``, named ``name`` by an entry point, cannot be a behaviour; None if it can."""
    if not isinstance(family, Behavior):
        return f"it is a {type(family).__name__}, not a fishswarm.behaviors.core.Behavior"
    if family.name != name:
        return f"the behaviour calls itself {family.name!r}: name the entry point as the behaviour"
    if name in BEHAVIORS:
        return "a behaviour of that name is there already (fishswarm's own, or another package's)"
    malformed = _malformed(family)
    if malformed is not None:
        return malformed
    try:
        # Worker processes get a fish's behaviour by reference: module and name.
        pickle.dumps(family)
    except Exception as error:  # pickle raises several kinds for what it cannot reference
        return (
            "its parts must be functions and classes at the top level of a module, not "
            f"lambdas or nested functions: worker processes import them by name "
            f"({type(error).__name__}: {error})"
        )
    return None


PLAIN_SETTING_TYPES = (bool, int, float, str)
"""What a behaviour's own setting's default may be: Python's own (not NumPy's) number, text,
or true or false — what a scenario file, a command line and a message carry alike."""


def _malformed(family: Behavior) -> str | None:
    """What in ``family``'s parts fishswarm cannot use; None if nothing."""
    for part in ("steer", "fresh_memory", "parameters"):
        if not callable(getattr(family, part)):
            return f"its {part} is not a function"
    if family.controller not in CONTROLLERS:
        return f"its controller must be one of {', '.join(CONTROLLERS)}, got {family.controller!r}"
    radius = family.spawn_radius
    if not (isinstance(radius, int | float) and math.isfinite(radius) and radius > 0):
        return f"its spawn_radius must be a positive number of metres, got {radius!r}"
    if not isinstance(family.settings, Mapping):
        return (
            f"its settings must be a dict of names and defaults, e.g. {{'gain': 0.5}}, got a "
            f"{type(family.settings).__name__}"
        )
    if len(family.settings) > MAX_SETTING_LIST:
        # A run's settings travel in one message, which takes a table of at most this many.
        return f"it has {len(family.settings)} settings: at most {MAX_SETTING_LIST} can be sent"
    for setting, default in family.settings.items():
        if not (isinstance(setting, str) and setting.isidentifier() and len(setting) <= MAX_TEXT):
            return (
                f"its setting {setting!r} is not a name (letters, digits and _, at most "
                f"{MAX_TEXT} of them)"
            )
        if isinstance(default, str) and len(default) > MAX_SETTING_TEXT:
            return f"its setting {setting}'s default is longer than {MAX_SETTING_TEXT} characters"
        if type(default) not in PLAIN_SETTING_TYPES or (
            isinstance(default, float) and not math.isfinite(default)
        ):
            return (
                f"its setting {setting}'s default must be a finite number, text or true or "
                f"false, of Python's own types (float(...) of a NumPy number), got {default!r} "
                f"({type(default).__name__})"
            )
    return None


def plugin_failures() -> tuple[PluginFailure, ...]:
    """The behaviours other packages name that could not be added, once read."""
    return tuple(_plugin_failures)


def plugin_source(name: str) -> str | None:
    """Where another package's behaviour ``name`` comes from (``module:attribute in package
    version``); None for fishswarm's own and for one registered in this process."""
    return _plugin_sources.get(name)


def names() -> tuple[str, ...]:
    """The names of the behaviours there are, other packages' included."""
    _read_plugins()
    return tuple(BEHAVIORS)


def behavior_named(name: str) -> Behavior:
    """The behaviour called ``name``.

    Raises:
        ValueError: no such behaviour, with the names there are.
    """
    family = BEHAVIORS.get(name)
    if family is None:
        _read_plugins()
        family = BEHAVIORS.get(name)
    if family is None:
        raise ValueError(f"behavior must be one of {', '.join(BEHAVIORS)}, got {name!r}")
    return family


def register(family: Behavior) -> None:
    """Add a behaviour to the table (it is known in this process only).

    Raises:
        ValueError: the name is taken by another behaviour.
    """
    _read_plugins()  # another package's behaviour of this name is refused, not replaced
    if BEHAVIORS.get(family.name, family) is not family:
        raise ValueError(f"a behaviour called {family.name!r} is registered already")
    malformed = _malformed(family)
    if malformed is not None:
        raise ValueError(f"the behaviour {family.name!r} cannot be registered: {malformed}")
    BEHAVIORS[family.name] = family


def fish_params(settings: Mapping[str, Any]) -> FishParams:
    """The parameters of a fish's decision from a scenario's settings.

    ``settings`` holds ``behavior``, ``controller``, ``control_period``, ``caudal_cap``,
    the study code's switches in effect (``study_code``) and whatever the behaviour reads
    (e.g. ``target_distance``, ``tank``, ``orbit_radius``, ``model``; its own settings,
    ``behavior_settings``, reach it with their defaults filled in).

    Raises:
        ValueError: an unknown behaviour or a bad parameter, with what is wrong.
    """
    family = behavior_named(str(settings["behavior"]))
    given = dict(settings.get("behavior_settings") or ())
    own = {**family.settings, **given}
    try:
        steering = family.parameters({**settings, "behavior_settings": own})
    except ValueError:
        raise  # a bad value, said by the behaviour
    except Exception as error:  # a behaviour's own code, failing otherwise
        raise ValueError(
            f"the behaviour {family.name!r} could not make its parameters from the settings: "
            f"{type(error).__name__}: {error}"
        ) from error
    return FishParams(
        family,
        steering,
        controller=str(settings.get("controller") or family.controller),
        control_period=float(settings.get("control_period", 1.0)),
        caudal_cap=float(settings.get("caudal_cap", 1.0)),
        pid_gains=family.pid_gains or PidGains(),
        right_when_ahead=STUDY_HOMING_SWITCH in settings.get("study_code", ()),
    )


def rules_of(params: FishParams) -> str:
    """The rules a fish's decisions follow, as text: ``paper``, or the study code's
    fish-side switches in effect (``lennard-jones``, ``homing``), comma-separated — what a
    fish actor tells the world, so that a world can warn of fish started with other rules."""
    switches = [
        name
        for name, on in (
            (STUDY_FORM_SWITCH, bool(getattr(params.steering, "study_form", False))),
            (STUDY_HOMING_SWITCH, params.right_when_ahead),
        )
        if on
    ]
    return ",".join(switches) or "paper"


def settings_digest(params: FishParams) -> str:
    """A short fingerprint of what a fish's decisions depend on beyond its behaviour's name
    and control period: the behaviour's parameters (a formation's map and its size, the
    spacing, a replica's model), the controller and its gains, the study-code switches.
    Fish whose parameters are equal have one digest in any process (the compiled loops the
    parameters may carry are left out); a fish actor tells it to the world, which warns of
    fish started with other settings."""
    whole = (
        params.steering,
        params.controller,
        params.caudal_cap,
        params.pid_gains,
        params.right_when_ahead,
    )
    return _fingerprint(whole, 16)


PART_DIGEST_LENGTH = 8
"""Hexadecimal digits of each part's fingerprint in :func:`settings_parts`."""


def settings_parts(params: FishParams) -> dict[str, str]:
    """A short fingerprint of each part of what :func:`settings_digest` covers, by the
    part's name: the behaviour's parameters one by one (a dataclass's fields, a table's
    keys, else the whole as ``steering``), then ``controller``, ``caudal_cap``,
    ``pid_gains`` and ``right_when_ahead`` (a behaviour's parameter of one of these names
    is ``steering.NAME``). Fish tell these beside the digest, so that a world whose digest
    differs can name the parameters that do."""
    steering = params.steering
    if dataclasses.is_dataclass(steering) and not isinstance(steering, type):
        fields = dataclasses.fields(steering)
        inner = {field.name: getattr(steering, field.name) for field in fields}
    elif isinstance(steering, Mapping):
        inner = {str(key): value for key, value in steering.items()}
    else:
        inner = {"steering": steering}
    outer = {
        "controller": params.controller,
        "caudal_cap": params.caudal_cap,
        "pid_gains": params.pid_gains,
        "right_when_ahead": params.right_when_ahead,
    }
    parts = {f"steering.{name}" if name in outer else name: value for name, value in inner.items()}
    parts.update(outer)
    return {name: _fingerprint(value, PART_DIGEST_LENGTH) for name, value in parts.items()}


def differing_parts(ours: Mapping[str, str], theirs: Mapping[str, str]) -> list[str]:
    """The names of the parts (:func:`settings_parts`) that two fish's fingerprints differ
    in, or that only one of them has, in ``ours``'s order then ``theirs``'s."""
    names = [*ours, *(name for name in theirs if name not in ours)]
    return [name for name in names if ours.get(name) != theirs.get(name)]


def _fingerprint(value: object, length: int) -> str:
    """The first ``length`` hexadecimal digits of the SHA-256 of ``value``'s canonical
    lines."""
    return hashlib.sha256("\n".join(_canonical(value)).encode()).hexdigest()[:length]


def _canonical(value: object) -> Iterator[str]:
    """Lines that say ``value`` alike in every process: a dataclass by its fields, an array
    by its type, shape and bytes, a number or text by its repr; a function (a compiled
    loop) as None; any other object by its type alone (its repr holds an address)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        yield type(value).__qualname__
        for field in dataclasses.fields(value):
            yield field.name
            yield from _canonical(getattr(value, field.name))
    elif isinstance(value, np.ndarray):
        digest = hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest()
        yield f"array {value.dtype.str} {value.shape} {digest}"
    elif isinstance(value, tuple | list):
        yield f"{type(value).__name__} {len(value)}"
        for item in value:
            yield from _canonical(item)
    elif isinstance(value, dict):
        yield f"dict {len(value)}"
        for key in sorted(value, key=repr):
            yield repr(key)
            yield from _canonical(value[key])
    elif value is None or callable(value):
        # A compiled loop decides as the numpy code it stands for: present or not, the same.
        yield "None"
    elif isinstance(value, bool | int | float | str | np.generic):
        yield repr(value.item() if isinstance(value, np.generic) else value)
    else:
        yield type(value).__qualname__
