"""An experiment's report: tables (Markdown, CSV), per-run data, a JSON summary, pictures."""

from __future__ import annotations

import csv
import itertools
import logging
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fishswarm.protocols.jsontext import json_text
from fishswarm.sim.scenario import Scenario, behavior_text
from fishswarm.study.experiment import Experiment, RunOutcome
from fishswarm.study.figures import FiguresUnavailable, experiment_figures

log = logging.getLogger(__name__)


def table_rows(experiment: Experiment, outcomes: list[RunOutcome]) -> list[dict[str, Any]]:
    """One row per group and value that has runs: each of the experiment's summaries, mean
    and s.d. over seeds (a ``group`` column first when the experiment compares groups)."""
    rows = []
    for group, value in itertools.product(experiment.group_names, experiment.values):
        mine = [o for o in outcomes if o.value == value and o.group == group]
        if not mine:
            continue
        row: dict[str, Any] = {"group": group} if experiment.groups else {}
        row |= {experiment.parameter: value, "runs": len(mine)}
        each = [run_values(experiment, outcome) for outcome in mine]
        for summary in experiment.summaries:
            values = np.array([run[summary.key] for run in each])
            row[f"{summary.key}_mean"] = float(values.mean())
            row[f"{summary.key}_sd"] = float(values.std(ddof=1)) if values.size > 1 else 0.0
        row["wall_time_mean"] = float(np.mean([o.wall_time for o in mine]))
        rows.append(row)
    return rows


def run_values(experiment: Experiment, outcome: RunOutcome) -> dict[str, float]:
    """The number each of the experiment's summaries gives for one run (what a table row
    averages over seeds), by the summary's key."""
    return {
        summary.key: float(
            summary.reduce(outcome.metrics[:, experiment.metric_names.index(summary.metric)])
        )
        for summary in experiment.summaries
    }


def write_report(
    experiment: Experiment,
    outcomes: list[RunOutcome],
    folder: Path,
    *,
    engine: str,
    wall_time: float,
    runs_total: int | None = None,
) -> list[Path]:
    """Write the experiment's tables, per-run data and pictures into ``folder``.

    Files: ``table.md`` and ``table.csv`` (mean ± s.d. per value), ``runs.csv`` (one row
    per run: each metric's first and last value, and the run's number behind each of the
    table's columns), ``summary.json`` (settings, rows, timing, whether complete) and, with
    matplotlib, the pictures of :func:`fishswarm.study.figures.experiment_figures`.

    Args:
        runs_total: the runs the sweep had, when it was interrupted before all of them
            finished (``outcomes`` then holds those that did, ``experiment`` their values):
            the table and summary say so.

    Returns:
        The paths written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    rows = table_rows(experiment, outcomes)
    paths = [folder / "table.md", folder / "table.csv", folder / "runs.csv"]
    missing = 0 if runs_total is None else runs_total - len(outcomes)
    text = markdown_table(experiment, rows)
    if missing:
        text += (
            f"\n**Incomplete**: interrupted after {len(outcomes)} of {runs_total} runs; each "
            f"row holds the runs of its value that finished (`runs` in table.csv).\n"
        )
    paths[0].write_text(text, encoding="utf-8")
    with paths[1].open("w", newline="", encoding="utf-8") as stream:
        table = csv.DictWriter(stream, fieldnames=list(rows[0]))
        table.writeheader()
        table.writerows(rows)
    with paths[2].open("w", newline="", encoding="utf-8") as stream:
        writer = csv.writer(stream)
        grouped = bool(experiment.groups)
        ends = [f"{m}_initial" for m in experiment.metric_names] + [
            f"{m}_final" for m in experiment.metric_names
        ]
        # A summary that is a metric's first or last value is there already, as that.
        summaries = [s.key for s in experiment.summaries if s.key not in ends]
        writer.writerow(
            [
                *(["group"] if grouped else []),
                experiment.parameter,
                "seed",
                *ends,
                *summaries,
                "wall_time",
            ]
        )
        for outcome in outcomes:
            values = run_values(experiment, outcome)
            writer.writerow(
                [
                    *([outcome.group] if grouped else []),
                    int(outcome.value) if experiment.parameter == "fish" else outcome.value,
                    outcome.seed,
                    *outcome.metrics[0].tolist(),
                    *outcome.metrics[-1].tolist(),
                    *(values[key] for key in summaries),
                    round(outcome.wall_time, 3),
                ]
            )
    summary = {
        "experiment": experiment.name,
        "title": experiment.title,
        "parameter": experiment.parameter,
        "values": list(experiment.values),
        "groups": {name: dict(settings) for name, settings in experiment.groups},
        "seeds": experiment.seeds,
        "engine": engine,
        "scenario": experiment.scenario.to_dict(),
        "rows": rows,
        "wall_time": wall_time,
        "complete": missing == 0,
        "runs_done": len(outcomes),
        "runs_total": len(outcomes) + missing,
    }
    summary_path = folder / "summary.json"
    summary_path.write_text(json_text(summary, indent=2), encoding="utf-8")
    paths.append(summary_path)
    try:
        paths += experiment_figures(experiment, outcomes, rows, folder)
    except FiguresUnavailable as error:
        log.warning("tables written, no pictures: %s", error)
    return paths


def markdown_table(experiment: Experiment, rows: list[dict[str, Any]]) -> str:
    """The table of an experiment in Markdown, mean ± s.d. over seeds."""
    scenario = experiment.scenario
    if experiment.forming_locally:
        explain = (
            "Shape error: the RMS distance of each fish's group (it and the nearest "
            "neighbours it makes the shape with) from the ideal shape after the best rigid "
            "alignment, averaged over fish; in their slots: every fish of the group within "
            "the tolerance of its place; lattice energy: mean squared relative deviation of "
            "neighbour distances from the spacing; collisions: pairs closer than one body "
            "length, summed over snapshots."
        )
    elif experiment.forming:
        explain = (
            "Shape error: RMS distance of the fish from the target map after the best rigid "
            "alignment and assignment; in their slots: within the tolerance of their slot; "
            "lattice energy: mean squared relative deviation of neighbour distances from the "
            "spacing; collisions: pairs closer than one body length, summed over snapshots; "
            "the study's fitness: ΣF over the fish, F = C + min D (C: the tolerance for each "
            "other fish within an eighth of the spacing; D: the distance to the nearest slot "
            "no other fish is within the tolerance of, or the tolerance when none is free), "
            "against the aligned map; lower is better."
        )
    elif experiment.orbiting:
        explain = (
            "Radius, speed: means over the second half of each run; revolutions: at the end; "
            "collisions: pairs closer than one body length, summed over ticks."
        )
    else:
        explain = "Changes are from the first to the last tick, per cent of the first."
    group_label = ["group"] if experiment.groups else []
    if experiment.groups:
        explain += (
            " Groups: "
            + "; ".join(
                f"{name}: {_settings_text(settings)}" for name, settings in experiment.groups
            )
            + "."
        )
    lines = [
        f"# {experiment.title}",
        "",
        f"{_fish_text(experiment)} fish, "
        f"{behavior_text(scenario.behavior, scenario.behavior_settings)}, "
        f"{scenario.duration:g} s at "
        f"{1 / scenario.control_period:g} Hz; {experiment.spread_text}. {explain}"
        + _following_text(scenario),
        "",
        "| "
        + " | ".join([*group_label, experiment.label, *(s.label for s in experiment.summaries)])
        + " |",
        "|" + ":---|" * len(group_label) + "---:|" * (1 + len(experiment.summaries)),
    ]
    undefined = False
    for row in rows:
        cells = [row["group"]] if group_label else []
        cells.append(f"{row[experiment.parameter]:g}")
        for summary in experiment.summaries:
            mean, sd = row[f"{summary.key}_mean"], row[f"{summary.key}_sd"]
            if not math.isfinite(mean):
                undefined = True
                cells.append("—")
                continue
            # A row of one run (an interrupted sweep's) has no spread to show.
            spread = f" ± {sd:.{summary.digits}f}" if row.get("runs", 0) > 1 else ""
            # + 0.0: a mean that rounds to zero from below is shown 0.00, not -0.00.
            cells.append(f"{round(mean, summary.digits) + 0.0:.{summary.digits}f}{spread}")
        lines.append("| " + " | ".join(cells) + " |")
    if experiment.seeds > 1 and any(row.get("runs", 0) < experiment.seeds for row in rows):
        lines += [
            "",
            "Rows of fewer runs than seeds (an interrupted sweep's) average the runs done; a "
            "row of one run shows no spread.",
        ]
    if undefined:
        lines += [
            "",
            "—: not defined for these runs (e.g. a distance between fish, or a change from "
            "a first value of 0, with one fish; runs.csv and table.csv hold it as nan).",
        ]
    return "\n".join(lines) + "\n"


def _fish_text(experiment: Experiment) -> str:
    """How many fish the runs have: the scenario's, or the values swept."""
    if experiment.parameter == "fish":
        return ", ".join(f"{value:g}" for value in experiment.values)
    return str(experiment.scenario.fish)


def _settings_text(settings: Mapping[str, Any]) -> str:
    """A group's settings as TOML would write them."""
    return ", ".join(
        f"{key} = {str(value).lower() if isinstance(value, bool) else value}"
        for key, value in settings.items()
    )


def _following_text(scenario: Scenario) -> str:
    """Where the runs follow the study's code instead of the paper, as a sentence."""
    if scenario.profile == "study-code":
        return " Profile study-code: every difference of the study's code (docs/fidelity.md)."
    if scenario.study_code:
        return (
            f" Following the study's code in: {', '.join(scenario.study_code)} (docs/fidelity.md)."
        )
    return ""
