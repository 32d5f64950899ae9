"""Experiment definitions, their TOML files and the tables made from runs."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fishswarm.sim.scenario import ConfigError, Scenario
from fishswarm.study.catalog import available
from fishswarm.study.experiment import (
    METRICS,
    Experiment,
    RunOutcome,
    change_from_third_percent,
    change_percent,
    find,
)
from fishswarm.study.report import markdown_table, table_rows, write_report


def test_the_studys_experiments_are_defined_as_in_spec() -> None:
    assert {"blindspot", "blockingsphere", "orbit", "milling", "waltz"} <= set(available())
    blindspot = find("blindspot")
    assert blindspot.parameter == "blind_width"
    assert blindspot.values == (0.0, 0.05, 0.25, 2.517)
    assert blindspot.seeds == 5
    assert blindspot.scenario.behavior == "dispersion"
    assert blindspot.scenario.resolved_spawn_radius() == pytest.approx(0.26)
    sphere = find("blockingsphere")
    assert sphere.values == (0.0, 0.065, 0.13, 0.195, 0.39, 0.52, 1.04)
    assert sphere.scenario.behavior == "aggregation"
    assert sphere.scenario.resolved_spawn_radius() == pytest.approx(1.3)
    assert sphere.scenario_for(0.39, 3).sphere_radius == 0.39
    assert sphere.scenario_for(0.39, 3).seed == 3


def test_the_study_codes_side_settings_and_mean_distance_in_the_two_experiments() -> None:
    blindspot, sphere = find("blindspot"), find("blockingsphere")
    # The paper's set-up by default; the study code's other vision setting when switched.
    assert blindspot.scenario_for(0.25, 0).sphere_radius == 0.065
    assert sphere.scenario_for(0.39, 0).blind_width == 0.05
    side = blindspot.with_changes(study_code=("side-settings",))
    assert side.scenario_for(0.25, 0).sphere_radius == 0.05
    assert side.scenario_for(0.25, 0).blind_width == 0.25  # the swept value wins
    profiled = sphere.with_changes(profile="study-code")
    assert profiled.scenario_for(0.39, 1).blind_width == 0.05
    assert profiled.scenario_for(0.39, 1).sphere_radius == 0.39
    # The mean-distance switch adds the study's own measure as the table's first column.
    assert blindspot.summaries[0].key == "centroid_distance_change_percent"
    counted = blindspot.with_changes(study_code=("mean-distance",))
    assert counted.summaries[0].key == "study_mean_distance_change_percent"
    assert counted.metric_names[-1] == "linked_centroid_distance"
    assert find("orbit").with_changes(profile="study-code").summaries == find("orbit").summaries
    # Third sample vs last: the study's fish moved from the third sample on.
    assert change_from_third_percent(np.array([9.0, 7.0, 2.0, 3.0, 5.0])) == pytest.approx(150.0)
    assert np.isnan(change_from_third_percent(np.array([1.0, 2.0])))


def test_an_experiments_study_code_table_is_checked(tmp_path: Path) -> None:
    path = tmp_path / "x.toml"
    path.write_text(
        '[experiment]\nname = "x"\nparameter = "blind_width"\nvalues = [0.1]\n'
        "[study_code]\nsphere_radius = -1\n"
    )
    with pytest.raises(
        ConfigError, match=r"\[study_code\]: vision sphere_radius must be a finite non-negative"
    ):
        Experiment.from_toml(path)


def test_unknown_experiment_lists_the_known_ones() -> None:
    with pytest.raises(ConfigError, match=r"no experiment named 'blindpsot': choose one of .*"):
        find("blindpsot")


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("[scenario]\nfish = 3\n", r"needs an \[experiment\] table"),
        ('[experiment]\nname = "x"\nparameter = "colour"\nvalues = [1]\n', "parameter must be"),
        ('[experiment]\nname = "x"\nparameter = "blind_width"\nvalues = []\n', "must not be empty"),
        (
            '[experiment]\nname = "x"\nparameter = "blind_width"\nvalues = ["a"]\n',
            "list of numbers",
        ),
        ('[experiment]\nname = "x"\nparameter = "blind_width"\n', "needs values"),
        (
            # The file, the experiment and the value, before what is wrong with it.
            '[experiment]\nname = "x"\nparameter = "blind_width"\nvalues = [0.1, -1]\n',
            r"bad.toml: experiment x: blind_width = -1: vision blind_width must be a finite "
            "non-negative number, got -1.0",
        ),
        ('[experiment]\nname = "x"\nparameter = "fish"\nvalues = [2]\nspeed = 3\n', "unknown"),
        (
            '[experiment]\nname = "x"\nparameter = "fish"\nvalues = [2]\nseeds = 0\n',
            "bad.toml: experiment x: seeds must be a whole number, 1 or more, got 0",
        ),
        (
            '[experiment]\nname = "x"\nparameter = "fish"\nvalues = [2]\nseeds = "five"\n',
            'bad.toml: experiment x: seeds must be a whole number, 1 or more, got "five"',
        ),
        (
            '[experiment]\nname = "x"\nparameter = "fish"\nvalues = [2.5, 3]\n',
            "experiment x: fish must be whole numbers, got 2.5, 3",
        ),
        (
            '[experiment]\nname = "x"\nparameter = "blind_width"\nvalues = [0.1, 0.2, 0.1]\n',
            r"experiment x: values must differ; 0.1 is given more than once \(more runs of a "
            r"value: --seeds\)",
        ),
        (
            '[experiment]\nname = "x"\nparameter = "spacing"\nvalues = [0.3, 0.4]\n'
            '[scenario]\nbehavior = "aggregation"\n',
            "experiment x: spacing applies only with behavior formation, and its behavior is "
            "aggregation: every value would run alike",
        ),
        (
            '[experiment]\nname = "x"\nparameter = "effort_margin"\nvalues = [1, 2]\n'
            '[scenario]\nbehavior = "formation"\n',
            "experiment x: effort_margin applies only with rotate_effort true, and its "
            "rotate_effort is false: every value would run alike",
        ),
        (
            '[experiment]\nname = "x"\nparameter = "effort_margin"\nvalues = [1, 2]\n'
            "[experiment.groups]\na = { flags = false }\nb = { spacing = 0.3 }\n"
            '[scenario]\nbehavior = "formation"\n',
            "experiment x: effort_margin applies only with rotate_effort true, and group 'a''s "
            "rotate_effort is false: every group's values would run alike",
        ),
        (
            '[experiment]\nname = "x"\nparameter = "blind_width"\nvalues = [0, 2.5]\n'
            '[scenario]\nvision_model = "camera"\n',
            "experiment x: blind_width applies only with vision_model geometric, and its "
            "vision_model is camera: every value would run alike; with cameras, vision "
            "settings still count where a landmark",
        ),
        ("[experiment\n", "not valid TOML"),
        (
            '[experiment]\nname = "x"\nparameter = "fish"\nvalues = [2]\n[scenairo]\nfish = 3\n',
            r"scenairo would be ignored: an experiment file holds the tables \[experiment\]",
        ),
    ],
)
def test_bad_experiment_files_are_explained(tmp_path: Path, text: str, reason: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=reason):
        Experiment.from_toml(path)


def _outcome(value: float, seed: int, first: float, last: float) -> RunOutcome:
    metrics = np.array([[first, first, first, 4.0], [last, last, last, 2.0]])
    return RunOutcome(value, seed, np.array([0.0, 1.0]), metrics, np.zeros((2, 1, 3)), 1.0)


def test_table_gives_mean_and_sd_of_the_change_over_seeds() -> None:
    experiment = find("blindspot").with_changes(values=(0.0, 0.05), seeds=2)
    outcomes = [
        _outcome(0.0, 0, 1.0, 1.5),  # +50 %
        _outcome(0.0, 1, 2.0, 2.2),  # +10 %
        _outcome(0.05, 0, 1.0, 0.5),  # −50 %
        _outcome(0.05, 1, 1.0, 0.5),
    ]
    rows = table_rows(experiment, outcomes)
    assert [row["blind_width"] for row in rows] == [0.0, 0.05]
    assert rows[0]["pairwise_distance_change_percent_mean"] == pytest.approx(30.0)
    # Sample standard deviation of 50 and 10: √((20² + 20²) / 1) ≈ 28.28.
    assert rows[0]["pairwise_distance_change_percent_sd"] == pytest.approx(28.2842712)
    assert rows[1]["centroid_distance_change_percent_mean"] == pytest.approx(-50.0)
    assert rows[1]["centroid_distance_change_percent_sd"] == 0.0
    assert rows[0]["neighbors_seen_final_mean"] == 2.0
    assert rows[0]["neighbors_seen_initial_mean"] == 4.0
    table = markdown_table(experiment, rows)
    assert "| 0 | 30.0 ± 28.3 | 30.0 ± 28.3 | 30.0 ± 28.3 | 4.0 ± 0.0 | 2.0 ± 0.0 |" in table
    assert len(METRICS) == 4


def test_change_percent_of_a_series() -> None:
    assert change_percent(np.array([2.0, 5.0, 3.0])) == pytest.approx(50.0)
    assert np.isnan(change_percent(np.array([0.0, 1.0])))


def test_orbit_experiments_summarise_radius_revolutions_speed_and_collisions() -> None:
    for name, fish in (("orbit", 1), ("milling", 25), ("waltz", 2)):
        experiment = find(name)
        assert experiment.orbiting and experiment.scenario.fish == fish
        assert experiment.metric_names == ("radius", "revolutions", "speed", "collisions")
    orbit = find("orbit").with_changes(values=(0.45,), seeds=1)
    t = np.arange(5.0)
    metrics = np.array(
        [
            [0.9, 0, 0, 0],
            [0.5, 0.1, 0.2, 1],
            [0.44, 0.2, 0.1, 0],
            [0.46, 0.3, 0.1, 2],
            [0.45, 0.4, 0.1, 0],
        ]
    )
    rows = table_rows(orbit, [RunOutcome(0.45, 0, t, metrics, np.zeros((5, 1, 3)), 1.0)])
    # The second half is ticks 2–4: radius mean 0.45, speed 0.1; revolutions at the end 0.4;
    # collisions summed over the run 3.
    assert rows[0]["radius_mean"] == pytest.approx(0.45)
    assert rows[0]["radius_wobble_mean"] == pytest.approx(np.std([0.44, 0.46, 0.45]))
    assert rows[0]["revolutions_mean"] == pytest.approx(0.4)
    assert rows[0]["speed_mean"] == pytest.approx(0.1)
    assert rows[0]["collisions_mean"] == 3.0


def test_ctrl_c_in_a_sweep_returns_the_runs_that_finished(tmp_path: Path) -> None:
    import json

    from fishswarm.study.sweep import SweepInterrupted, simulate_on_batch_engine, sweep_experiment

    experiment = find("blindspot").with_changes(seeds=2, duration=2.0)
    calls = []

    def interrupted_at_the_third_run(scenario: Scenario) -> tuple[np.ndarray, ...]:
        calls.append(scenario.seed)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return simulate_on_batch_engine(scenario)

    with pytest.raises(SweepInterrupted) as stop:
        sweep_experiment(experiment, engine=interrupted_at_the_third_run, jobs=1)  # type: ignore[arg-type]
    assert [(o.group, o.value, o.seed) for o in stop.value.outcomes] == experiment.runs()[:2]
    assert stop.value.total == len(experiment.runs()) == 2 * len(experiment.values)
    # What finished is reported, marked incomplete.
    first = experiment.with_changes(values=experiment.values[:1])
    write_report(first, stop.value.outcomes, tmp_path, engine="batch", wall_time=1.0,
                 runs_total=stop.value.total)  # fmt: skip
    assert "**Incomplete**: interrupted after 2 of 8 runs" in (tmp_path / "table.md").read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (summary["complete"], summary["runs_done"], summary["runs_total"]) == (False, 2, 8)
    assert [row["runs"] for row in summary["rows"]] == [2]


def failing_first_seed(scenario: Scenario) -> tuple[np.ndarray, ...]:
    """A sweep's engine (in a spawned process) whose runs of seed 0 fail at once, and whose
    others take two seconds before they run."""
    import time

    from fishswarm.study.sweep import simulate_on_batch_engine

    if scenario.seed == 0:
        raise RuntimeError(f"run with seed 0 ended degraded (blind width {scenario.blind_width:g})")
    time.sleep(2.0)
    return simulate_on_batch_engine(scenario)


@pytest.mark.slow
@pytest.mark.parametrize("jobs", [1, 2])
def test_a_failed_run_stops_the_sweep_and_returns_the_runs_that_finished(jobs: int) -> None:
    from fishswarm.study.sweep import SweepFailed, sweep_experiment

    experiment = find("blindspot").with_changes(seeds=2, duration=2.0)
    # Runs go value by value, seeds 0 and 1: the first run fails.
    with pytest.raises(SweepFailed, match="RuntimeError: run with seed 0 ended degraded") as stop:
        sweep_experiment(experiment, engine=failing_first_seed, jobs=jobs)  # type: ignore[arg-type]
    assert stop.value.total == len(experiment.runs()) == 8
    # Nothing ran after the failure in this process. In two processes, the runs already
    # handed to them finish (the executor keeps one more queued than it has processes, and
    # the process whose run failed takes the next): at most three; the others of the eight
    # are cancelled, not run to the end.
    assert len(stop.value.outcomes) <= (0 if jobs == 1 else 3)
    assert all(outcome.seed == 1 for outcome in stop.value.outcomes)


def slow_runs(scenario: Scenario) -> tuple[np.ndarray, ...]:
    """A sweep's engine (in a spawned process) whose runs take three seconds each, and say
    when they start with a file in the folder $FISHSWARM_TEST_STARTS."""
    import os
    import time
    from pathlib import Path

    from fishswarm.study.sweep import simulate_on_batch_engine

    Path(os.environ["FISHSWARM_TEST_STARTS"], f"{scenario.blind_width:g}-{scenario.seed}").touch()
    time.sleep(3.0)
    return simulate_on_batch_engine(scenario)


@pytest.mark.slow
@pytest.mark.parametrize("presses", [1, 2])
def test_ctrl_c_in_a_sweep_over_processes_keeps_the_runs_handed_over_unless_pressed_again(
    presses: int,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Ctrl-C once the two processes run their first runs: the runs not handed to them are
    cancelled; the two under way and the one queued finish and are kept. A second Ctrl-C
    drops them at once. Either way no process of the sweep is left (one once hung for
    ever, blocked writing its result)."""
    import multiprocessing
    import os
    import signal
    import threading
    import time

    from fishswarm.study.sweep import SweepInterrupted, sweep_experiment

    monkeypatch.setenv("FISHSWARM_TEST_STARTS", str(tmp_path))
    experiment = find("blindspot").with_changes(seeds=2, duration=2.0)

    presses_at: list[float] = []

    def press_ctrl_c() -> None:
        deadline = time.monotonic() + 60.0
        while len(list(tmp_path.iterdir())) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        for _ in range(presses):
            time.sleep(0.5)
            presses_at.append(time.monotonic())
            os.kill(os.getpid(), signal.SIGINT)

    presser = threading.Thread(target=press_ctrl_c)
    with caplog.at_level("WARNING", logger="fishswarm.study.sweep"):
        presser.start()
        with pytest.raises(SweepInterrupted) as stop:
            sweep_experiment(experiment, engine=slow_runs, jobs=2)  # type: ignore[arg-type]
        returned = time.monotonic()
    presser.join(timeout=10.0)
    # Gone from the system (a process object may still say "started": when two threads
    # wait for one process, the one that did not reap it never learns its exit code).
    left = [p.pid for p in multiprocessing.active_children() if Path(f"/proc/{p.pid}").exists()]
    assert left == []
    assert sorted(path.name for path in tmp_path.iterdir())[:2] == ["0-0", "0-1"]
    said = [record.getMessage() for record in caplog.records]
    assert said[0] == (
        "stopping: waiting for the 3 run(s) handed to its processes to finish (Ctrl-C drops them)"
    )
    assert stop.value.total == 8
    if presses == 1:
        kept = [(o.value, o.seed) for o in stop.value.outcomes]
        assert kept == [(0.0, 0), (0.0, 1), (0.05, 0)] and len(said) == 1
    else:
        assert stop.value.outcomes == []
        assert said[1] == "stopping: dropped the run(s) handed to its processes"
        # The runs under way had 2 s or more to go: the processes were ended at once.
        assert returned - presses_at[-1] < 1.5


@pytest.mark.parametrize(
    ("named", "controller"), [('controller = "homing"\n', "homing"), ("", "pid")]
)
def test_a_controller_the_scenario_names_stays_in_a_group_of_another_behaviour(
    tmp_path: Path, named: str, controller: str
) -> None:
    # The file's dispersion fish steer with homing (its default, named or not); a group
    # of formation fish keeps a named controller and otherwise takes formation's own, pid.
    path = tmp_path / "grouped.toml"
    path.write_text(
        '[experiment]\nname = "grouped"\nparameter = "channel_loss"\nvalues = [0.0]\n'
        'seeds = 1\n[experiment.groups]\n"formed" = { behavior = "formation" }\n'
        f'[scenario]\nfish = 4\nbehavior = "dispersion"\n{named}',
        encoding="utf-8",
    )
    assert find(str(path)).scenario_for(0.0, 0, "formed").controller == controller


def test_groups_compare_the_sweep_under_named_settings(tmp_path: Path) -> None:
    import json

    from fishswarm.study.sweep import sweep_experiment

    folder = tmp_path / "experiments"
    folder.mkdir()
    path = folder / "grouped.toml"
    path.write_text(
        '[experiment]\nname = "grouped"\nparameter = "channel_loss"\nvalues = [0.0, 0.5]\n'
        'seeds = 1\n[experiment.groups]\n"flags" = { flags = true }\n'
        '"no flags" = { flags = false }\n'
        '[scenario]\nfish = 4\nbehavior = "formation"\nformation = "pyramid"\n'
        "duration = 2\ncontrol_period = 0.5\n",
        encoding="utf-8",
    )
    experiment = find(str(path))
    assert experiment.group_names == ("flags", "no flags")
    assert experiment.runs() == [
        ("flags", 0.0, 0), ("flags", 0.5, 0), ("no flags", 0.0, 0), ("no flags", 0.5, 0),
    ]  # fmt: skip
    off = experiment.scenario_for(0.5, 3, "no flags")
    assert (off.flags, off.channel_loss, off.seed) == (False, 0.5, 3)
    assert experiment.scenario_for(0.5, 3, "flags").flags is True
    with pytest.raises(ConfigError, match="no group 'sometimes'; groups: flags, no flags"):
        experiment.scenario_for(0.0, 0, "sometimes")
    outcomes = sweep_experiment(experiment, jobs=1)
    assert [(o.group, o.value) for o in outcomes] == [key[:2] for key in experiment.runs()]
    rows = table_rows(experiment, outcomes)
    assert [(r["group"], r["channel_loss"]) for r in rows] == [key[:2] for key in experiment.runs()]
    # Without flags nothing goes over the channel, so its loss changes nothing.
    no_flags = [r for r in rows if r["group"] == "no flags"]
    assert no_flags[0]["shape_error_mean"] == no_flags[1]["shape_error_mean"]
    # A global map's table carries the study's fitness, summed over the snapshots (five
    # of them in 2 s at 2 Hz) as the study sums it.
    outcome = outcomes[0]
    fitness = outcome.metrics[:, experiment.metric_names.index("fitness")]
    assert fitness.shape == (5,) and (fitness > 0).all()
    assert rows[0]["fitness_total_mean"] == pytest.approx(fitness.sum())
    assert rows[0]["fitness_mean"] == pytest.approx(fitness[-1])
    text = markdown_table(experiment, rows)
    assert "| group | channel_loss |" in text and "| no flags | 0.5 |" in text
    assert "study's fitness ΣF, summed over time (m)" in text
    local = dataclasses.replace(
        experiment, scenario=dataclasses.replace(experiment.scenario, formation="triangle")
    )
    assert "fitness" not in [summary.key for summary in local.summaries]
    assert "fitness" not in local.metric_names and "fitness" in experiment.metric_names
    assert "Groups: flags: flags = true; no flags: flags = false." in text
    write_report(experiment, outcomes, tmp_path / "out", engine="batch", wall_time=1.0)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["groups"] == {"flags": {"flags": True}, "no flags": {"flags": False}}
    runs_csv = (tmp_path / "out" / "runs.csv").read_text().splitlines()
    assert runs_csv[0].startswith("group,channel_loss,seed,") and len(runs_csv) == 5


@pytest.mark.parametrize(
    ("groups", "message"),
    [
        ('"a" = 3', r"must name tables of scenario settings"),
        ('"a" = { flags = "maybe" }', r"group 'a': flags and rotate_effort must be true or false"),
        ('"" = { flags = true }', "experiment bad: groups need distinct, non-empty names"),
    ],
)
def test_bad_groups_are_named(tmp_path: Path, groups: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(
        f'[experiment]\nname = "bad"\nparameter = "fish"\nvalues = [2]\n'
        f"[experiment.groups]\n{groups}\n[scenario]\n",
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match=message):
        find(str(path))


def test_a_formation_experiment_measures_each_snapshot_against_the_scheduled_shape() -> None:
    # Six fish held in the slots of a column for three snapshots; the scenario starts as a
    # pyramid and switches to the column at 1 s: only the first snapshot is off its target.
    from fishswarm.sim.scenario import Scenario
    from fishswarm.study.metrics import FormationTargets

    scenario = Scenario(
        fish=6, behavior="formation", formation="pyramid", switch_formation="column",
        switch_at=1.0, spacing=0.25, duration=2.0,
    )  # fmt: skip
    targets = FormationTargets.of(scenario)
    assert targets is not None
    slots = targets.at("column").slots
    assert slots is not None
    position = np.repeat((slots[:6] + np.array([0.9, 0.9, 0.5]))[None], 3, axis=0)
    experiment = Experiment(
        name="switch-test", title="Switch", parameter="fish", label="fish", values=(6.0,),
        seeds=1, scenario=scenario,
    )  # fmt: skip
    series = experiment.metrics_of(
        scenario, position, np.zeros((3, 6), dtype=np.int64), times=np.array([0.0, 1.0, 2.0])
    )
    shape_error = series[:, experiment.metric_names.index("shape_error")]
    assert shape_error[0] > 0.05
    np.testing.assert_allclose(shape_error[1:], 0.0, atol=1e-9)


def test_the_experiment_command_writes_what_finished_when_a_run_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    from fishswarm.cli import main
    from fishswarm.cli import study as study_command

    def fails_at_the_second_run(scenario: Scenario) -> tuple[np.ndarray, ...]:
        from fishswarm.study.sweep import simulate_on_batch_engine

        if scenario.seed == 1:
            raise RuntimeError("run with seed 1 ended degraded")
        return simulate_on_batch_engine(scenario)

    monkeypatch.setattr(study_command, "engine_named", lambda name: fails_at_the_second_run)
    out = tmp_path / "out"
    code = main(
        ["experiment", "blindspot", "--seeds", "2", "--duration", "2", "--jobs", "1",
         "--out", str(out), "--quiet"]
    )  # fmt: skip
    assert code == 1
    said = capsys.readouterr().err
    assert "a run failed (RuntimeError: run with seed 1 ended degraded) after 1 of 8 runs" in said
    summary = json.loads((out / "summary.json").read_text())
    assert (summary["complete"], summary["runs_done"], summary["runs_total"]) == (False, 1, 8)


def test_a_sweep_reports_each_run_as_it_finishes_with_how_many_are_done() -> None:
    from fishswarm.study.sweep import sweep_experiment

    experiment = find("blindspot").with_changes(seeds=1, duration=1.0)
    total = len(experiment.runs())
    reports: list[tuple[int, int, float, int]] = []
    outcomes = sweep_experiment(
        experiment,
        jobs=1,
        on_run=lambda done, runs, o: reports.append((done, runs, o.value, o.seed)),
    )
    assert reports == [
        (done, total, value, seed) for done, (_, value, seed) in enumerate(experiment.runs(), 1)
    ]
    assert all(outcome.wall_time > 0.0 for outcome in outcomes)


def test_the_batch_engine_gives_a_runs_times_positions_sightings_and_effort() -> None:
    from fishswarm.sim.engine import simulate_batch
    from fishswarm.study.sweep import simulate_on_batch_engine

    scenario = Scenario(fish=3, duration=2.0)
    t, position, seen, effort = simulate_on_batch_engine(scenario)
    trajectory = simulate_batch(scenario)
    np.testing.assert_array_equal(t, trajectory.t)
    np.testing.assert_array_equal(position, trajectory.position)
    np.testing.assert_array_equal(seen, trajectory.neighbors_seen)
    np.testing.assert_array_equal(effort, trajectory.effort)
    assert t.tolist() == [0.0, 1.0, 2.0] and (effort[-1] > 0.0).all()  # the fins beat


def test_the_study_codes_mean_distance_is_warned_of_where_it_cannot_be_measured() -> None:
    # Named for orbiting fish, the switch changed nothing while the table listed it; with
    # fewer than four samples its column said NaN (or 0) without a word.
    orbit = find("orbit").with_changes(study_code=("mean-distance",), duration=5)
    (said,) = orbit.study_code_warnings()
    assert "not measured for orbit fish" in said
    assert find("orbit").with_changes(profile="study-code").study_code_warnings() == []
    short = find("blockingsphere").with_changes(profile="study-code", duration=2)
    (said,) = short.study_code_warnings()
    assert "compares the third sample with the last, and 2 s give 3" in said
    assert "give --duration 3 or more" in said
    assert (
        find("blockingsphere").with_changes(profile="study-code", duration=3).study_code_warnings()
        == []
    )
    assert find("blockingsphere").with_changes(duration=1).study_code_warnings() == []


def test_runs_csv_holds_each_runs_number_behind_every_table_column(tmp_path: Path) -> None:
    # The study code's mean distance compares a run's third sample with its last: runs.csv
    # must hold that per-run number, as it holds the others, so that the table's mean and
    # s.d. can be checked from it.

    experiment = find("blindspot").with_changes(study_code=("mean-distance",))
    names = experiment.metric_names
    outcomes = []
    for seed, scale in ((0, 1.0), (1, 2.0)):
        series = np.ones((5, len(names)))
        # Linked centroid distance 9, 7, 2, 3, 5 (× scale): +150 % from the third sample.
        series[:, names.index("linked_centroid_distance")] = np.array([9, 7, 2, 3, 5]) * scale
        # Centroid distance 4 → 5 and 4 → 6: +25 % and +50 % from the first.
        series[:, names.index("centroid_distance")] = [4, 4, 4, 4, 4 + scale]
        outcomes.append(RunOutcome(0.25, seed, np.arange(5.0), series, np.zeros((5, 2, 3)), 1.0))
    write_report(experiment, outcomes, tmp_path, engine="batch", wall_time=2.0)
    with (tmp_path / "runs.csv").open(encoding="utf-8") as stream:
        header = next(csv.reader(stream))
        stream.seek(0)
        runs = list(csv.DictReader(stream))
    # Each column once (the neighbours seen at the start and end were there twice).
    assert len(header) == len(set(header)) and "neighbors_seen_final" in header
    assert [float(run["study_mean_distance_change_percent"]) for run in runs] == [150.0, 150.0]
    assert [float(run["centroid_distance_change_percent"]) for run in runs] == [25.0, 50.0]
    assert [float(run["linked_centroid_distance_initial"]) for run in runs] == [9.0, 18.0]
    with (tmp_path / "table.csv").open(encoding="utf-8") as stream:
        (row,) = list(csv.DictReader(stream))
    assert float(row["centroid_distance_change_percent_mean"]) == pytest.approx(37.5)
    assert float(row["centroid_distance_change_percent_sd"]) == pytest.approx(
        np.std([25.0, 50.0], ddof=1)
    )


def test_a_sweep_of_fish_says_the_counts_it_runs(tmp_path: Path) -> None:
    path = tmp_path / "fish.toml"
    path.write_text(
        '[experiment]\nname = "x"\nparameter = "fish"\nvalues = [2, 3]\n'
        '[scenario]\nbehavior = "aggregation"\nduration = 2\n',
        encoding="utf-8",
    )
    experiment = Experiment.from_toml(path)
    outcomes = [
        RunOutcome(value, 0, np.arange(3.0), np.ones((3, len(experiment.metric_names))),
                   np.zeros((3, int(value), 3)), 1.0)
        for value in (2.0, 3.0)
    ]  # fmt: skip
    write_report(experiment, outcomes, tmp_path / "out", engine="batch", wall_time=1.0)
    assert "\n2, 3 fish, aggregation, 2 s at 1 Hz" in (tmp_path / "out" / "table.md").read_text()
    with (tmp_path / "out" / "runs.csv").open(encoding="utf-8") as stream:
        assert [run["fish"] for run in csv.DictReader(stream)] == ["2", "3"]


def test_a_mean_that_rounds_to_zero_from_below_is_shown_as_zero() -> None:
    experiment = find("orbit")
    row: dict[str, object] = {experiment.parameter: experiment.values[0], "runs": 2}
    for summary in experiment.summaries:
        row[f"{summary.key}_mean"], row[f"{summary.key}_sd"] = -0.001, 0.002
    row["runs"] = experiment.seeds
    (line,) = [line for line in markdown_table(experiment, [row]).splitlines() if line[:3] == "| 0"]
    cells = [cell.strip() for cell in line.split("|")]
    # Radius, wobble and speed have three decimals, revolutions two, collisions one.
    assert cells[2:-1] == ["-0.001 ± 0.002"] * 2 + ["0.00 ± 0.00", "-0.001 ± 0.002", "0.0 ± 0.0"]


def test_a_number_one_fish_leaves_undefined_is_a_dash_in_the_table(tmp_path: Path) -> None:
    # One fish has no distance to another fish: the table said "nan ± nan".
    from fishswarm.study.sweep import sweep_experiment

    path = tmp_path / "fish.toml"
    path.write_text(
        '[experiment]\nname = "x"\nparameter = "fish"\nvalues = [1, 3]\nseeds = 2\n'
        '[scenario]\nbehavior = "aggregation"\nduration = 3\n',
        encoding="utf-8",
    )
    experiment = Experiment.from_toml(path)
    outcomes = sweep_experiment(experiment, jobs=1)
    write_report(experiment, outcomes, tmp_path / "out", engine="batch", wall_time=1.0)
    table = (tmp_path / "out" / "table.md").read_text(encoding="utf-8")
    one, three = (line for line in table.splitlines() if line.startswith(("| 1 |", "| 3 |")))
    assert "nan ±" not in table and "| nan" not in table
    # Aggregating fish: centroid, pairwise and nearest-neighbour changes, neighbours seen at
    # the start and the end. One fish sees none; its distances to others are not defined,
    # and its distance to the school's centre is 0 throughout, so has no change in per cent.
    assert one == "| 1 | — | — | — | 0.0 ± 0.0 | 0.0 ± 0.0 |"
    assert "—" not in three
    assert table.rstrip().endswith("runs.csv and table.csv hold it as nan).")


def test_a_group_the_sweep_leaves_alike_is_a_control_beside_one_it_changes(
    tmp_path: Path,
) -> None:
    # formation-energy's "no rotation" group: the margin changes nothing there, by design.
    path = tmp_path / "control.toml"
    path.write_text(
        '[experiment]\nname = "x"\nparameter = "effort_margin"\nvalues = [1, 2]\n'
        "[experiment.groups]\non = { rotate_effort = true }\noff = { rotate_effort = false }\n"
        '[scenario]\nbehavior = "formation"\n',
        encoding="utf-8",
    )
    assert Experiment.from_toml(path).group_names == ("on", "off")
    assert find("formation-energy").group_names == ("rotation", "no rotation")


def test_a_row_of_one_run_in_an_interrupted_sweep_shows_no_spread() -> None:
    # One of five seeds done: "223.3 ± 0.0" read as a spread measured over seeds.
    experiment = find("blindspot").with_changes(values=(0.0, 0.05), seeds=5)
    outcomes = [_outcome(0.0, seed, 1.0, 1.5 + 0.1 * seed) for seed in range(5)]
    rows = table_rows(experiment, [*outcomes, _outcome(0.05, 0, 1.0, 0.5)])
    table = markdown_table(experiment, rows)
    (done, one) = [line for line in table.splitlines() if line.startswith(("| 0 |", "| 0.05 |"))]
    assert "±" in done and "±" not in one
    assert one.startswith("| 0.05 | -50.0 | -50.0 | -50.0 |")
    assert "Rows of fewer runs than seeds (an interrupted sweep's) average the runs done" in table
    assert "fewer runs" not in markdown_table(experiment, table_rows(experiment, outcomes))


def test_an_experiment_sweeps_a_behaviours_own_setting_by_name_or_by_its_table() -> None:
    import dataclasses

    from fishswarm.behaviors.registry import BEHAVIORS, register
    from tests.behaviors.signal_behavior import SIGNAL

    spaced = dataclasses.replace(SIGNAL, name="test-spaced", settings={"spacing": 0.3, "n": 2})
    if spaced.name not in BEHAVIORS:
        register(spaced)
    scenario = Scenario(behavior="test-spaced", fish=3, duration=2.0)

    def sweep(parameter: str, values: tuple[float, ...] = (0.2, 0.4)) -> Experiment:
        return Experiment("x", "x", parameter, "x", values, 1, scenario)

    # A name a scenario setting has too: the table's name says which.
    with pytest.raises(ConfigError, match=r'write parameter = "behavior_settings\.spacing"'):
        sweep("spacing")
    run = sweep("behavior_settings.spacing").scenario_for(0.4, 0)
    assert run.behavior_settings == (("spacing", 0.4),) and run.spacing is None
    # A whole-number setting takes whole numbers, as an int.
    assert sweep("n", (1, 3)).scenario_for(3, 0).behavior_settings == (("n", 3),)
    with pytest.raises(ConfigError, match=r"n must be whole numbers, got 1\.5"):
        sweep("n", (1.5, 3))
    with pytest.raises(ConfigError, match=r"or a number of test-spaced's own settings: spacing, n"):
        sweep("behavior_settings.gap")
