"""Experiments through the actor system: same trajectories as the batch engine, and every
experiment command end to end at a reduced size."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from fishswarm.actors.runs import simulate_on_actors
from fishswarm.cli import main
from fishswarm.study.experiment import find
from fishswarm.study.report import table_rows
from fishswarm.study.sweep import simulate_on_batch_engine, sweep_experiment

pytestmark = pytest.mark.integration


def test_actor_and_batch_engines_give_the_same_trajectories() -> None:
    experiment = find("blockingsphere").with_changes(values=(0.0, 0.39), seeds=1, duration=4.0)
    through_actors = sweep_experiment(experiment, engine=simulate_on_actors, jobs=2)
    in_batch = sweep_experiment(experiment, engine=simulate_on_batch_engine, jobs=1)
    assert [(o.value, o.seed) for o in through_actors] == [(0.0, 0), (0.39, 0)]
    # Orbiting: the landmark travels in perceptions and perception batches alike.
    orbiting = find("milling").with_changes(values=(0.45,), seeds=1, duration=6.0)
    through_actors += sweep_experiment(orbiting, engine=simulate_on_actors, jobs=1)
    in_batch += sweep_experiment(orbiting, engine=simulate_on_batch_engine, jobs=1)
    # The study code's profile: fish-side switches reach the fish processes too.
    studied = find("blindspot").with_changes(
        values=(0.05,), seeds=1, duration=4.0, profile="study-code"
    )
    through_actors += sweep_experiment(studied, engine=simulate_on_actors, jobs=1)
    in_batch += sweep_experiment(studied, engine=simulate_on_batch_engine, jobs=1)
    for actors, batch in zip(through_actors, in_batch, strict=True):
        assert actors.position.shape[1:] == (25, 3)
        np.testing.assert_array_equal(actors.position, batch.position)
        np.testing.assert_array_equal(actors.metrics, batch.metrics)
    # A bigger blocking sphere hides more: fewer neighbours seen at the start.
    assert in_batch[1].metrics[0, 3] < in_batch[0].metrics[0, 3]
    assert in_batch[2].metrics[-1, 2] > 0  # the milling fish move


@pytest.mark.parametrize(
    "name",
    [
        "blindspot",
        "blockingsphere",
        "orbit",
        "milling",
        "waltz",
        "formation-global",
        "formation-local",
        "formation-flags",
        "formation-energy",
    ],
)
@pytest.mark.slow
def test_experiment_command_end_to_end(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / name
    code = main(["experiment", name, "--seeds", "2", "--duration", "2", "--out", str(out)])
    assert code == 0
    experiment = find(name)
    with (out / "table.csv").open(encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    groups = len(experiment.group_names)
    assert [float(row[experiment.parameter]) for row in rows] == list(experiment.values) * groups
    assert all(row["runs"] == "2" for row in rows)
    with (out / "runs.csv").open(encoding="utf-8") as stream:
        assert len(list(csv.DictReader(stream))) == 2 * len(experiment.values) * groups
    # The numbers are those of the same runs in the batch engine.
    shrunk = experiment.with_changes(seeds=2, duration=2)
    expected = table_rows(shrunk, sweep_experiment(shrunk, engine=simulate_on_batch_engine, jobs=1))
    for row, want in zip(rows, expected, strict=True):
        for summary_spec in experiment.summaries:
            column = f"{summary_spec.key}_mean"
            assert float(row[column]) == pytest.approx(want[column], rel=1e-12, abs=1e-12)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["engine"] == "actors" and summary["seeds"] == 2
    for picture in ("metrics_vs_parameter.png", "metrics_over_time.png", "tracks.png"):
        assert (out / picture).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert printed.startswith(f"# {experiment.title}")


def test_an_experiment_under_the_study_code_profile(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "study"
    arguments = ["experiment", "blindspot", "--engine", "batch", "--profile", "study-code"]
    code = main([*arguments, "--seeds", "2", "--duration", "5", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert "Profile study-code: every difference of the study's code" in printed
    assert "mean distance change, study code (%)" in printed
    with (out / "table.csv").open(encoding="utf-8") as stream:
        rows = list(csv.DictReader(stream))
    studied = find("blindspot").with_changes(seeds=2, duration=5, profile="study-code")
    expected = table_rows(
        studied, sweep_experiment(studied, engine=simulate_on_batch_engine, jobs=1)
    )
    paper = find("blindspot").with_changes(seeds=2, duration=5)
    against = table_rows(paper, sweep_experiment(paper, engine=simulate_on_batch_engine, jobs=1))
    column = "study_mean_distance_change_percent_mean"
    for row, want, other in zip(rows, expected, against, strict=True):
        assert float(row[column]) == pytest.approx(want[column], rel=1e-12)
        assert column not in other
        # The profile changes the runs: not the paper's numbers.
        key = "pairwise_distance_change_percent_mean"
        assert float(row[key]) != pytest.approx(other[key], rel=1e-6)


def test_unknown_experiment_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        main(["experiment", "orbitz"])
    assert stopped.value.code == 2
    assert "no experiment named 'orbitz'" in capsys.readouterr().err
