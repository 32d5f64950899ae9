"""Measure the tables of docs/fidelity.md: each of the study code's switches alone, and the
whole ``study-code`` profile, on the study's experiments (batch engine, the experiments' own
seeds and settings).

Usage:
    python docs/fidelity_tables.py            # every table, as markdown on stdout
    python docs/fidelity_tables.py --jobs 1   # one run at a time
"""

from __future__ import annotations

import argparse
import time

from fishswarm.sim.scenario import STUDY_CODE_SWITCHES
from fishswarm.study.experiment import Experiment, find
from fishswarm.study.report import table_rows
from fishswarm.study.sweep import simulate_on_batch_engine, sweep_experiment

PAIRWISE = "pairwise_distance_change_percent"
STUDY_MEASURE = "study_mean_distance_change_percent"


def _cells(experiment: Experiment, key: str, jobs: int) -> list[str]:
    rows = table_rows(
        experiment, sweep_experiment(experiment, engine=simulate_on_batch_engine, jobs=jobs)
    )
    return [f"{row[f'{key}_mean']:.1f} ± {row[f'{key}_sd']:.1f}" for row in rows]


def switch_table(name: str, jobs: int) -> str:
    """Rows: the swept values; columns: the paper, each switch alone, the whole profile."""
    base = find(name)
    columns: list[tuple[str, list[str]]] = [("paper", _cells(base, PAIRWISE, jobs))]
    for switch in STUDY_CODE_SWITCHES:
        changed = base.with_changes(study_code=(switch,))
        key = STUDY_MEASURE if switch == "mean-distance" else PAIRWISE
        label = f"`{switch}`" + (" ‡" if switch == "mean-distance" else "")
        columns.append((label, _cells(changed, key, jobs)))
    profile = base.with_changes(profile="study-code")
    columns.append(("study-code", _cells(profile, PAIRWISE, jobs)))
    columns.append(("study-code ‡", _cells(profile, STUDY_MEASURE, jobs)))
    lines = [
        "| " + " | ".join([base.label, *(label for label, _ in columns)]) + " |",
        "|" + "---:|" * (1 + len(columns)),
    ]
    for index, value in enumerate(base.values):
        lines.append(
            "| " + " | ".join([f"{value:g}", *(cells[index] for _, cells in columns)]) + " |"
        )
    return "\n".join(lines)


def orbit_table(jobs: int) -> str:
    """Orbit, milling and waltz under both profiles: their summaries, a row per value."""
    lines: list[str] = []
    for name in ("orbit", "milling", "waltz"):
        for profile in ("paper", "study-code"):
            experiment = find(name).with_changes(profile=profile)
            outcomes = sweep_experiment(experiment, engine=simulate_on_batch_engine, jobs=jobs)
            if not lines:
                labels = [summary.label for summary in experiment.summaries]
                lines += [
                    "| experiment | value (m) | profile | " + " | ".join(labels) + " |",
                    "|---|---:|---|" + "---:|" * len(labels),
                ]
            for value, row in zip(experiment.values, table_rows(experiment, outcomes), strict=True):
                cells = [
                    f"{row[f'{s.key}_mean']:.{s.digits}f} ± {row[f'{s.key}_sd']:.{s.digits}f}"
                    for s in experiment.summaries
                ]
                lines.append(f"| {name} | {value:g} | {profile} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--jobs", type=int, default=2, help="runs at a time (default 2)")
    args = parser.parse_args()
    started = time.perf_counter()
    for name in ("blindspot", "blockingsphere"):
        print(f"## {name} (pairwise distance change, %; ‡ the study's mean distance)\n")
        print(switch_table(name, args.jobs), "\n", flush=True)
    print("## orbit, milling, waltz\n")
    print(orbit_table(args.jobs))
    print(f"\n(measured in {time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
