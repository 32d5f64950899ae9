"""The study's simulator experiments: one scenario swept over a parameter, several seeds each.

An experiment is a TOML file (``experiments/<name>.toml``): an ``[experiment]`` table naming
the scenario setting to sweep, its values and the number of seeds, and a ``[scenario]``
table with the study's set-up. An optional ``[experiment.groups]`` table compares the sweep
under several named sets of settings (e.g. ``"flags" = {flags = true}``, ``"no flags" =
{flags = false}``): every group runs every value and seed. This module defines experiments
and turns their runs into tables and pictures; :mod:`fishswarm.study.sweep` runs them.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.registry import behavior_named
from fishswarm.bluebot.parameters import BODY_LENGTH
from fishswarm.formations.local import LOCAL_SHAPES
from fishswarm.sim.scenario import (
    ConfigError,
    Scenario,
    applies_anyway,
    as_written,
    read_toml,
    setting_text,
    unmet_condition,
)
from fishswarm.study.catalog import EXPERIMENTS_FOLDER, available
from fishswarm.study.metrics import (
    FORMATION_METRIC_NAMES,
    ORBIT_BEHAVIORS,
    ORBIT_METRIC_NAMES,
    FormationTargets,
    effort_spread,
    linked_centroid_distance,
    orbit_metrics,
    orbit_target_of,
    swarm_metrics,
)

FloatArray = NDArray[np.float64]

log = logging.getLogger(__name__)

METRICS = ("centroid_distance", "pairwise_distance", "nearest_neighbor_distance", "neighbors_seen")
"""Columns of a swarm run's metric series: the three mean distances (m) of SPEC §3 and
neighbours seen."""


METRIC_LABELS = {
    "centroid_distance": "distance to centroid of others (m)",
    "pairwise_distance": "mean pairwise distance (m)",
    "nearest_neighbor_distance": "nearest-neighbour distance (m)",
    "neighbors_seen": "neighbours seen",
    "linked_centroid_distance": "mean distance, study code (m)",
    "radius": "radius (m)",
    "revolutions": "revolutions",
    "speed": "speed (m/s)",
    "collisions": "colliding pairs",
    "shape_error": "shape error (m)",
    "joined_fraction": "fraction in their slots",
    "lattice_energy": "lattice energy",
    "fitness": "the study's fitness ΣF (m)",
    "effort_spread": "effort spread (max/mean)",
}


def change_percent(series: FloatArray) -> float:
    """Change of a metric from its first to its last value, per cent of the first."""
    first, last = float(series[0]), float(series[-1])
    return math.nan if first == 0 else 100.0 * (last - first) / first


def change_from_third_percent(series: FloatArray) -> float:
    """Change of a metric from its third to its last value, per cent of the third (how the
    study's code compared its "mean distance": its fish moved from the third sample on)."""
    return change_percent(series[2:]) if len(series) > 2 else math.nan


def _first(series: FloatArray) -> float:
    return float(series[0])


def _last(series: FloatArray) -> float:
    return float(series[-1])


def _second_half(series: FloatArray) -> FloatArray:
    return series[len(series) // 2 :]


def _late_mean(series: FloatArray) -> float:
    return float(_second_half(series).mean())


def _late_sd(series: FloatArray) -> float:
    return float(_second_half(series).std())


def _total(series: FloatArray) -> float:
    return float(series.sum())


@dataclass(frozen=True)
class Summary:
    """One column of an experiment's table: a number per run, then mean ± s.d. over seeds.

    Attributes:
        key: column name in table.csv.
        label: column heading in table.md and on plots.
        metric: the metric series it reduces.
        reduce: series (T,) → the number of one run.
        digits: decimals shown in table.md.
    """

    key: str
    label: str
    metric: str
    reduce: Callable[[FloatArray], float]
    digits: int


SWARM_SUMMARIES = (
    Summary(
        "centroid_distance_change_percent",
        "centroid distance change (%)",
        "centroid_distance",
        change_percent,
        1,
    ),
    Summary(
        "pairwise_distance_change_percent",
        "pairwise distance change (%)",
        "pairwise_distance",
        change_percent,
        1,
    ),
    Summary(
        "nearest_neighbor_distance_change_percent",
        "nearest-neighbour distance change (%)",
        "nearest_neighbor_distance",
        change_percent,
        1,
    ),
    Summary("neighbors_seen_initial", "neighbours seen, initial", "neighbors_seen", _first, 1),
    Summary("neighbors_seen_final", "neighbours seen, final", "neighbors_seen", _last, 1),
)

STUDY_MEAN_DISTANCE = Summary(
    "study_mean_distance_change_percent",
    "mean distance change, study code (%)",
    "linked_centroid_distance",
    change_from_third_percent,
    1,
)
"""The column the ``mean-distance`` switch adds: the study code's own measure."""

ORBIT_SUMMARIES = (
    Summary("radius", "radius, 2nd half (m)", "radius", _late_mean, 3),
    Summary("radius_wobble", "radius s.d. in time, 2nd half (m)", "radius", _late_sd, 3),
    Summary("revolutions", "revolutions", "revolutions", _last, 2),
    Summary("speed", "speed, 2nd half (m/s)", "speed", _late_mean, 3),
    Summary("collisions", "collisions (pair-ticks)", "collisions", _total, 1),
)


def _late_mean_percent(series: FloatArray) -> float:
    return 100.0 * _late_mean(series)


def _last_percent(series: FloatArray) -> float:
    return 100.0 * _last(series)


FORMATION_SUMMARIES = (
    Summary("shape_error", "shape error, end (m)", "shape_error", _last, 3),
    Summary("shape_error_late", "shape error, 2nd half (m)", "shape_error", _late_mean, 3),
    Summary("joined", "in their slots, end (%)", "joined_fraction", _last_percent, 0),
    Summary(
        "joined_late", "in their slots, 2nd half (%)", "joined_fraction", _late_mean_percent, 0
    ),
    Summary("lattice_energy", "lattice energy, end", "lattice_energy", _last, 3),
    Summary("collisions", "collisions (pair-snapshots)", "collisions", _total, 0),
    Summary("effort_spread", "effort spread, end (max/mean)", "effort_spread", _last, 3),
)

STUDY_FITNESS_SUMMARIES = (
    Summary("fitness", "study's fitness ΣF, end (m)", "fitness", _last, 2),
    Summary("fitness_total", "study's fitness ΣF, summed over time (m)", "fitness", _total, 1),
)
"""The columns a global map's table adds: SPEC §5's fitness of the school (lower is better),
at the end and summed over the snapshots as the study sums it."""

SWEEPABLE = (
    "blind_width",
    "sphere_radius",
    "visual_range",
    "target_distance",
    "fish",
    "orbit_radius",
    "tolerance",
    "spacing",
    "channel_loss",
    "effort_margin",
)


def _number_settings(behavior: str) -> dict[str, int | float]:
    """The settings of ``behavior``'s own that are numbers, with their defaults: what an
    experiment may sweep beside :data:`SWEEPABLE` (none for an unknown behaviour)."""
    try:
        declared = behavior_named(behavior).settings
    except ValueError:
        return {}
    return {
        name: default
        for name, default in declared.items()
        if isinstance(default, int | float) and not isinstance(default, bool)
    }


OWN_SETTING_PREFIX = "behavior_settings."
"""How an experiment's parameter names the behaviour's own setting where a scenario setting
has the same name."""

RunKey = tuple[str, float, int]
"""One run of an experiment: (group, value, seed)."""


@dataclass(frozen=True)
class Experiment:
    """One experiment of the study.

    Attributes:
        name: short name, e.g. ``blindspot``.
        title: what it shows, for tables and plots.
        parameter: the scenario setting swept (e.g. ``blind_width``).
        label: the parameter as an axis label, with its unit.
        values: the settings of the parameter.
        seeds: runs per value (seeds 0 … seeds−1).
        scenario: the set-up every run starts from.
        study_settings: the settings the study's code used instead in this experiment
            (its ``[study_code]`` table), applied under the ``side-settings`` switch.
        groups: named sets of scenario settings compared (each runs every value and seed);
            none: one unnamed group, the scenario as it is.
        controller_named: the file's ``[scenario]`` names its controller, which then stays
            when a group or the study's settings change the behaviour.
    """

    name: str
    title: str
    parameter: str
    label: str
    values: tuple[float, ...]
    seeds: int
    scenario: Scenario
    study_settings: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    groups: tuple[tuple[str, Mapping[str, Any]], ...] = ()
    controller_named: bool = False

    def __post_init__(self) -> None:
        behavior = self.scenario.behavior
        own = _number_settings(behavior)
        swept_own = self.own_setting_swept
        if (swept_own is None and self.parameter not in SWEEPABLE) or (
            swept_own is not None and swept_own not in own
        ):
            of_behavior = (
                f", or a number of {behavior}'s own settings: {', '.join(own)}" if own else ""
            )
            raise ConfigError(
                f"experiment {self.name}: parameter must be one of {', '.join(SWEEPABLE)}"
                f"{of_behavior}; got {self.parameter!r}"
            )
        if self.parameter in SWEEPABLE and self.parameter in own:
            raise ConfigError(
                f"experiment {self.name}: {self.parameter} is a scenario setting and one of "
                f'{behavior}\'s own: write parameter = "behavior_settings.{self.parameter}" '
                "to sweep the behaviour's"
            )
        if isinstance(own.get(swept_own or ""), int) and not all(
            float(v).is_integer() for v in self.values
        ):
            raise ConfigError(
                f"experiment {self.name}: {self.parameter} must be whole numbers, got "
                f"{', '.join(map(str, self.values))}"
            )
        if not self.values:
            raise ConfigError(f"experiment {self.name}: values must not be empty")
        if len(set(self.values)) < len(self.values):
            repeated = sorted({v for v in self.values if list(self.values).count(v) > 1})
            raise ConfigError(
                f"experiment {self.name}: values must differ; {', '.join(map(str, repeated))} "
                f"{'are' if repeated[1:] else 'is'} given more than once (more runs of a value: "
                "--seeds)"
            )
        if self.parameter == "fish" and not all(float(v).is_integer() for v in self.values):
            raise ConfigError(
                f"experiment {self.name}: fish must be whole numbers, got "
                f"{', '.join(map(str, self.values))}"
            )
        if not isinstance(self.seeds, int) or isinstance(self.seeds, bool) or self.seeds < 1:
            raise ConfigError(
                f"experiment {self.name}: seeds must be a whole number, 1 or more, got "
                f"{as_written(self.seeds)}"
            )
        names = [name for name, _ in self.groups]
        if len(set(names)) < len(names) or "" in names:
            raise ConfigError(f"experiment {self.name}: groups need distinct, non-empty names")
        unmet: list[tuple[str, str, str, Any]] = []
        for group in self.group_names:
            for value in self.values:
                try:
                    scenario = self.scenario_for(value, 0, group)  # each must be valid
                except ConfigError as error:
                    where = f"group {group!r}, " if group else ""
                    raise ConfigError(
                        f"experiment {self.name}: {where}{self.parameter} = {value:g}: {error}"
                    ) from None
                if (condition := unmet_condition(self.parameter, scenario)) is not None:
                    unmet.append((group, *condition, getattr(scenario, condition[0])))
        # A group the sweep leaves alike is a control beside the others (formation-energy's
        # "no rotation"); only a sweep that changes no run at all is refused.
        if unmet and len({group for group, *_ in unmet}) == len(self.group_names):
            group, setting, needed, actual = unmet[0]
            whose = f"group {group!r}'s" if group else "its"
            every = "every group's values" if self.groups else "every value"
            raise ConfigError(
                f"experiment {self.name}: {self.parameter} applies only with {setting} "
                f"{needed}, and {whose} {setting} is {setting_text(actual)}: {every} would "
                f"run alike{applies_anyway(self.parameter)}"
            )

    @property
    def own_setting_swept(self) -> str | None:
        """The behaviour's own setting the experiment sweeps (``parameter`` names it, or
        ``behavior_settings.NAME``); None when it sweeps a scenario setting."""
        name = self.parameter.removeprefix(OWN_SETTING_PREFIX)
        if name != self.parameter or self.parameter not in SWEEPABLE:
            return name
        return None

    @property
    def group_names(self) -> tuple[str, ...]:
        """The groups compared, in order (one unnamed group, ``""``, when there are none)."""
        return tuple(name for name, _ in self.groups) or ("",)

    @property
    def orbiting(self) -> bool:
        """Whether the fish orbit (orbit, milling, waltz) rather than aggregate or disperse."""
        return self.scenario.behavior in ORBIT_BEHAVIORS

    @property
    def spread_text(self) -> str:
        """How the table and the figures summarise the seeds of each value, in words."""
        if self.seeds == 1:
            return "one seed per value (one run each: no spread)"
        return f"{self.seeds} seeds per value; mean ± s.d. over seeds"

    @property
    def forming(self) -> bool:
        """Whether the fish take places in a formation."""
        return self.scenario.behavior == "formation"

    @property
    def forming_locally(self) -> bool:
        """Whether the fish make a local shape (judged with their nearest neighbours: no
        map of slots, so no study fitness)."""
        return self.forming and self.scenario.formation in LOCAL_SHAPES

    @property
    def _study_mean_distance(self) -> bool:
        return (
            "mean-distance" in self.scenario.study_switches
            and not self.forming
            and not self.orbiting
        )

    def study_code_warnings(self) -> list[str]:
        """What the study code's ``mean-distance`` switch cannot give in this experiment,
        said before it runs (the table would otherwise list the switch, or show NaN)."""
        if "mean-distance" not in self.scenario.study_switches:
            return []
        if self.forming or self.orbiting:
            if "mean-distance" not in self.scenario.study_code:
                return []  # on by --profile study-code, with every other switch
            return [
                f"the study code's mean distance (mean-distance) is not measured for "
                f"{self.scenario.behavior} fish, only for aggregating and dispersing ones: "
                "the switch changes nothing here"
            ]
        if self.scenario.ticks < 3:
            period = self.scenario.control_period
            return [
                "the study code's mean distance (mean-distance) compares the third sample "
                f"with the last, and {self.scenario.duration:g} s give "
                f"{self.scenario.ticks + 1}: its column will say nothing (give --duration "
                f"{3 * period:g} or more)"
            ]
        return []

    @property
    def metric_names(self) -> tuple[str, ...]:
        """The columns of each run's metric series."""
        if self.forming:
            return (*self._formation_metric_names, "effort_spread")
        if self.orbiting:
            return ORBIT_METRIC_NAMES
        return (*METRICS, "linked_centroid_distance") if self._study_mean_distance else METRICS

    @property
    def _formation_metric_names(self) -> tuple[str, ...]:
        """A formation's metrics; a local shape has no study fitness (no map for D)."""
        if self.forming_locally:
            return tuple(name for name in FORMATION_METRIC_NAMES if name != "fitness")
        return FORMATION_METRIC_NAMES

    @property
    def summaries(self) -> tuple[Summary, ...]:
        """The columns of the experiment's table."""
        if self.forming:
            if self.forming_locally:
                return FORMATION_SUMMARIES
            return (*FORMATION_SUMMARIES, *STUDY_FITNESS_SUMMARIES)
        if self.orbiting:
            return ORBIT_SUMMARIES
        if self._study_mean_distance:
            return (STUDY_MEAN_DISTANCE, *SWARM_SUMMARIES)
        return SWARM_SUMMARIES

    def metrics_of(
        self,
        scenario: Scenario,
        position: FloatArray,
        seen: NDArray[np.int64],
        effort: FloatArray | None = None,
        times: FloatArray | None = None,
    ) -> FloatArray:
        """(T, M) the metric series of one run from its positions (T, N, 3), the
        neighbours each fish saw (T, N), each fish's effort so far (T, N; formations) and
        the snapshots' times (T,), s (default: one a control period from 0; a formation
        is measured against the shape its scenario has switched to by then)."""
        if self.forming:
            targets = FormationTargets.of(scenario)
            assert targets is not None  # a formation scenario always has them
            spent = np.zeros(position.shape[:2]) if effort is None else effort
            at = np.arange(position.shape[0]) * scenario.control_period if times is None else times
            rows = []
            for p, e, t in zip(position, spent, at, strict=True):
                target = targets.told(None, float(t))
                metrics = target.metrics(p)
                rows.append(
                    [*(metrics[name] for name in self._formation_metric_names), effort_spread(e)]
                )
            return np.array(rows)
        if self.orbiting:
            orbit = orbit_target_of(scenario)
            assert orbit is not None  # an orbiting scenario always has one
            return orbit_metrics(
                position,
                centre=orbit.centre,
                period=scenario.control_period,
                contact=BODY_LENGTH,
            )
        series = np.array(
            [
                [swarm_metrics(p, s)[name] for name in METRICS]
                for p, s in zip(position, seen, strict=True)
            ]
        )
        if not self._study_mean_distance:
            return series
        manhattan = "manhattan" in scenario.study_switches
        study = [
            linked_centroid_distance(p, link_range=scenario.visual_range, manhattan=manhattan)
            for p in position
        ]
        return np.column_stack([series, study])

    def scenario_for(self, value: float, seed: int, group: str = "") -> Scenario:
        """The scenario of one run: the group's settings, then the study's own settings
        under its ``side-settings`` switch; the swept parameter always as given.

        Raises:
            ConfigError: no such group, or a setting is wrong.
        """
        base = self.scenario
        if group:
            settings = dict(self.groups).get(group)
            if settings is None:
                raise ConfigError(
                    f"experiment {self.name}: no group {group!r}; groups: "
                    f"{', '.join(self.group_names)}"
                )
            base = base.with_settings(settings, controller_chosen=self._controller_chosen)
        if "side-settings" in base.study_switches:
            base = base.with_settings(
                self.study_settings, controller_chosen=self._controller_chosen
            )
        swept: dict[str, Any]
        own = self.own_setting_swept
        if own is None:
            swept = {self.parameter: int(value) if self.parameter == "fish" else float(value)}
        else:  # one of the behaviour's own settings, the others as the scenario has them
            default = behavior_named(base.behavior).settings.get(own)
            kind = int if isinstance(default, int) else float
            swept = {"behavior_settings": {**dict(base.behavior_settings), own: kind(value)}}
        return base.replace(**swept, seed=seed).check_duration()

    @property
    def _controller_chosen(self) -> bool | None:
        # Named in the file: chosen; otherwise a group may have chosen one: guessed.
        return True if self.controller_named else None

    def runs(self) -> list[RunKey]:
        """Every (group, value, seed), group by group, then value by value."""
        return [
            (group, value, seed)
            for group in self.group_names
            for value in self.values
            for seed in range(self.seeds)
        ]

    def with_changes(
        self,
        *,
        seeds: int | None = None,
        duration: float | None = None,
        values: tuple[float, ...] | None = None,
        study_code: tuple[str, ...] | None = None,
        profile: str | None = None,
    ) -> Experiment:
        """A copy with fewer seeds, a shorter duration, other values, some of the study
        code's ways or another profile (None: unchanged)."""
        return dataclasses.replace(
            self,
            values=self.values if values is None else values,
            seeds=self.seeds if seeds is None else seeds,
            scenario=self.scenario.replace(
                duration=duration, study_code=study_code, profile=profile
            ),
        )

    @classmethod
    def from_toml(cls, path: Path) -> Experiment:
        """Load an experiment file.

        Raises:
            ConfigError: the file is missing, not TOML, or a setting is wrong (with which).
        """
        data = read_toml(path, "experiment")
        table = data.get("experiment")
        if not isinstance(table, dict):
            raise ConfigError(f"{path}: needs an [experiment] table (name, parameter, values)")
        stray = sorted(set(data) - {"experiment", "scenario", "study_code"})
        if stray:
            raise ConfigError(
                f"{path}: {', '.join(stray)} would be ignored: an experiment file holds the "
                "tables [experiment], [scenario] and [study_code] only"
            )
        known = {"name", "title", "parameter", "label", "values", "seeds", "groups"}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ConfigError(
                f"{path}: unknown [experiment] setting(s) {', '.join(unknown)}; known: "
                f"{', '.join(sorted(known))}"
            )
        missing = sorted({"name", "parameter", "values"} - set(table))
        if missing:
            raise ConfigError(f"{path}: [experiment] needs {', '.join(missing)}")
        values = table["values"]
        if not isinstance(values, list) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in values
        ):
            raise ConfigError(f"{path}: values must be a list of numbers, got {as_written(values)}")
        scenario_table = data.get("scenario", {})
        if not isinstance(scenario_table, Mapping):
            raise ConfigError(f"{path}: [scenario] must be a table")
        scenario = Scenario.from_mapping(scenario_table, source=str(path))
        study_settings = data.get("study_code", {})
        if not isinstance(study_settings, Mapping):
            raise ConfigError(f"{path}: [study_code] must be a table of scenario settings")
        try:
            scenario.replace(**study_settings)
        except (ConfigError, TypeError) as error:
            raise ConfigError(f"{path}: [study_code]: {error}") from None
        groups = table.get("groups", {})
        if not isinstance(groups, Mapping) or not all(
            isinstance(settings, Mapping) for settings in groups.values()
        ):
            raise ConfigError(
                f"{path}: [experiment.groups] must name tables of scenario settings, e.g. "
                '"no flags" = { flags = false }'
            )
        for group, settings in groups.items():
            try:
                scenario.replace(**settings)
            except (ConfigError, TypeError) as error:
                raise ConfigError(f"{path}: group {group!r}: {error}") from None
        name = str(table["name"])
        try:
            return cls(
                name,
                str(table.get("title", name)),
                str(table["parameter"]),
                str(table.get("label", table["parameter"])),
                tuple(float(v) for v in values),
                table.get("seeds", 5),
                scenario,
                dict(study_settings),
                tuple((str(group), dict(settings)) for group, settings in groups.items()),
                controller_named="controller" in scenario_table,
            )
        except ConfigError as error:
            raise ConfigError(f"{path}: {error}") from None


def find(name_or_path: str) -> Experiment:
    """An experiment by name (``experiments/<name>.toml``) or by the path of its file.

    Raises:
        ConfigError: no such experiment, with the names there are.
    """
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        return Experiment.from_toml(path)
    candidate = EXPERIMENTS_FOLDER / f"{name_or_path}.toml"
    if not candidate.is_file():
        names = ", ".join(available()) or "(none found)"
        raise ConfigError(
            f"no experiment named {name_or_path!r}: choose one of {names}, or give the path "
            "of an experiment TOML file"
        )
    return Experiment.from_toml(candidate)


@dataclass(frozen=True)
class RunOutcome:
    """The result of one run.

    Attributes:
        value: the parameter's value.
        seed: the seed.
        group: the group it ran in (``""``: the experiment has none).
        t: (T,) times, s.
        metrics: (T, M) the experiment's metric series (:attr:`Experiment.metric_names`).
        position: (T, N, 3) every fish's position, m.
        wall_time: how long the run took, s.
    """

    value: float
    seed: int
    t: FloatArray
    metrics: FloatArray
    position: FloatArray
    wall_time: float
    group: str = ""
