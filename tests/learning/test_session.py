"""A whole learning run: outputs on disk, the replica loads back, the command works."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fishswarm.learning.arena import Arena
from fishswarm.learning.coevolution import LearningSettings
from fishswarm.learning.replica_file import ReplicaFileError, load_replica
from fishswarm.learning.session import OUTPUTS, LearningError, learn


def test_learn_writes_every_output(tmp_path: Path) -> None:
    settings = LearningSettings(models=6, classifiers=6, seed=2, inputs=("speed", "neighbors2"))
    summary = learn(settings, generations=3, out=tmp_path, checkpoint_every=2)
    # Exactly the outputs a new run clears first (OUTPUTS).
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted(OUTPUTS)
    assert summary["generations"] == 3
    assert len(summary["radii"]["mean"]) == 2
    assert (tmp_path / "history.csv").read_text().count("\n") == 4
    weights, saved = load_replica(tmp_path / "best_replica.npz")
    assert weights.shape == (21,)
    assert saved["inputs"] == ["speed", "neighbors2"]
    written = json.loads((tmp_path / "summary.json").read_text())
    assert written["settings"]["seed"] == 2
    assert written["settings"]["arena"]["replica_input_scale"] == 40.0
    # The curves: 16 spacings (start and 15 steps) and 15 speeds, from the same starts;
    # the ideal fish end near their spacing of about 35 (sigma 40).
    for who in ("ideal", "replica"):
        assert len(written[who]["spacing"]) == 16 and len(written[who]["speed"]) == 15
        assert written[who]["spacing"][-1] == written[who]["final_spacing"]
    assert written["ideal"]["spacing"][0] == written["replica"]["spacing"][0]
    assert 30 < written["ideal"]["final_spacing"] < 40


def test_resuming_with_other_settings_is_refused_and_with_the_same_allowed(
    tmp_path: Path,
) -> None:
    settings = LearningSettings(models=4, classifiers=4, seed=1, inputs=("speed",))
    learn(settings, generations=1, out=tmp_path)
    for given in (
        {"inputs": ("speed", "neighbors")},
        {"radii": "unbounded"},
        {"seed": 2},
        {"replica": "reciprocal"},
    ):
        with pytest.raises(LearningError, match="holds a run learned with"):
            learn(settings, generations=2, out=tmp_path, resume=True, given=given)
    resumed: list[tuple[int, bool]] = []
    summary = learn(
        LearningSettings(),  # not named: the checkpoint's settings rule
        generations=2,
        out=tmp_path,
        resume=True,
        given={"seed": 1, "inputs": ("speed",)},
        on_start=lambda run, again: resumed.append((run.generation, again)),
    )
    assert resumed == [(1, True)]
    assert summary["generations"] == 2 and summary["settings"]["models"] == 4


def test_a_reciprocal_replica_run_resumes_as_one(tmp_path: Path) -> None:
    arena = dataclasses.replace(Arena(), replica="reciprocal")
    settings = LearningSettings(models=4, classifiers=4, seed=1, inputs=("speed",), arena=arena)
    learn(settings, generations=1, out=tmp_path)
    with pytest.raises(LearningError, match="drop --replica to go on with that run"):
        learn(
            LearningSettings(), generations=2, out=tmp_path, resume=True, given={"replica": "study"}
        )
    summary = learn(
        LearningSettings(),
        generations=2,
        out=tmp_path,
        resume=True,
        given={"replica": "reciprocal"},
    )
    assert summary["settings"]["arena"]["replica"] == "reciprocal"


def test_resume_needs_a_checkpoint(tmp_path: Path) -> None:
    with pytest.raises(LearningError, match="nothing to resume"):
        learn(LearningSettings(), generations=2, out=tmp_path, resume=True)
    with pytest.raises(ReplicaFileError, match="is not a learned replica"):
        load_replica(tmp_path / "missing.npz")


@pytest.mark.slow
def test_learn_command_resumes_to_the_same_result(tmp_path: Path) -> None:
    base = [
        sys.executable,
        "-m",
        "fishswarm",
        "learn",
        "--models",
        "6",
        "--classifiers",
        "6",
        "--seed",
        "5",
        "--checkpoint-every",
        "1",
    ]
    straight = subprocess.run(
        [*base, "--generations", "4", "--out", str(tmp_path / "a")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert straight.returncode == 0, straight.stderr
    assert "generation 4/4" in straight.stderr
    (radii,) = [line for line in straight.stderr.splitlines() if line.startswith("  learned radii")]
    # The default inputs count within fixed radii: nothing learned to report.
    assert radii == "  learned radii  none (the classifiers did not count neighbours)"
    # Four generations of six replicas do not learn to aggregate: the target is missed, and
    # the line says by how much, as summary.json does.
    target = json.loads((tmp_path / "a" / "summary.json").read_text())["target"]
    assert not target["met"]
    assert (
        f"target missed: spacing at most {100 * target['spacing_error']:.0f} % off the ideal's"
        in straight.stderr
    )
    first = subprocess.run(
        [*base, "--generations", "2", "--out", str(tmp_path / "b")],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    second = subprocess.run(
        [*base, "--generations", "4", "--out", str(tmp_path / "b"), "--resume"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert first.returncode == 0 and second.returncode == 0, second.stderr
    header = (
        "fishswarm learn: aggregation ideal fish; classifier inputs speed,counts, no learned "
        "radii; 6 replicas × 6 classifiers, seed 5, hall of fame 10, soft weight 1, "
        "virulence 0.75, 1 start(s) a generation, isotropic replicas; up to generation 2"
    )
    assert header in first.stderr.splitlines()[0]
    assert "resumed from generation" not in first.stderr
    assert f"resumed from generation 2 ({tmp_path / 'b' / 'checkpoint.npz'})" in second.stderr
    history = (tmp_path / "b" / "history.csv").read_text().splitlines()
    assert [line.split(",")[0] for line in history] == ["generation", "1", "2", "3", "4"]
    # Resuming with another setting named stops and says which; the run is left as it was.
    before = (tmp_path / "b" / "checkpoint.npz").read_bytes()
    again = [*base, "--generations", "6", "--out", str(tmp_path / "b"), "--resume"]
    changed = subprocess.run(
        [*again, "--behavior", "dispersion"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert changed.returncode == 2
    assert "holds a run learned with behavior aggregation, but this command asks for " in (
        changed.stderr
    )
    assert "drop --behavior to go on with that run" in changed.stderr
    assert (tmp_path / "b" / "checkpoint.npz").read_bytes() == before
    a = np.load(tmp_path / "a" / "best_replica.npz")["weights"]
    b = np.load(tmp_path / "b" / "best_replica.npz")["weights"]
    np.testing.assert_array_equal(a, b)
    assert (tmp_path / "a" / "history.csv").read_text() == (
        tmp_path / "b" / "history.csv"
    ).read_text()


def test_learn_names_where_learned_radii_start_and_where_they_ended(tmp_path: Path) -> None:
    command = [sys.executable, "-m", "fishswarm", "learn", "--models", "4", "--classifiers"]
    command += ["4", "--generations", "1", "--inputs", "speed,neighbors", "--radius-start"]
    done = subprocess.run(
        [*command, "30", "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert "classifier inputs speed,neighbors, radii bounded from 30 units; 4 replicas" in lines[0]
    (radii,) = [line for line in lines if line.startswith("  learned radii")]
    assert radii.startswith("  learned radii  r1 ") and radii.endswith(" units")


def test_learned_radii_print_as_mean_and_spread_with_their_unit() -> None:
    from fishswarm.cli.learn import radii_text

    assert radii_text({"mean": [45.25, 80.0], "sd": [3.14, 5.4]}) == (
        "r1 45.2 ± 3.1, r2 80.0 ± 5.4 units"
    )
    assert radii_text({"mean": [], "sd": []}).startswith("none")


def test_the_target_judges_spacing_at_whole_seconds_5_to_15_and_the_final_speed() -> None:
    from fishswarm.learning.arena import Arena
    from fishswarm.learning.session import Evaluation, target_report

    arena = Arena()  # one step a second
    ideal = np.full(16, 35.0)
    replica = ideal.copy()
    replica[3] = 100.0  # before 5 s: not judged
    replica[7] = 35.0 * 1.15  # exactly 15 % off: within
    speed = np.array([np.full(15, 0.2), np.full(15, 0.6)])  # 0.4 apart at the end
    tracks = np.zeros((2, 16, 1, 2))
    report = target_report(Evaluation(np.stack([ideal, replica]), speed, tracks), arena)
    assert report["spacing_error"] == pytest.approx(0.15)
    assert report["speed_difference"] == pytest.approx(0.4)
    assert report["met"]
    replica[10] = 41.0  # 17 % off at 10 s
    missed = target_report(Evaluation(np.stack([ideal, replica]), speed, tracks), arena)
    assert missed["spacing_error"] == pytest.approx(6 / 35) and not missed["met"]
    speed[1, -1] = 0.8  # 0.6 apart at the end
    slow = target_report(Evaluation(np.stack([ideal, ideal]), speed, tracks), arena)
    assert slow["spacing_error"] == 0.0 and slow["speed_difference"] == pytest.approx(0.6)
    assert not slow["met"]


@pytest.mark.slow
def test_an_unbounded_run_resumes_with_the_radius_start_it_was_learned_with(
    tmp_path: Path,
) -> None:
    command = [
        sys.executable, "-m", "fishswarm", "learn", "--models", "4", "--classifiers", "4",
        "--inputs", "speed,neighbors", "--radii", "unbounded", "--radius-start", "-20",
        "--out", str(tmp_path), "--quiet",
    ]  # fmt: skip
    for generations, extra in (("2", []), ("3", ["--resume"])):
        done = subprocess.run(
            [*command, "--generations", generations, *extra],
            capture_output=True, text=True, timeout=120, check=False,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
    assert "resumed from generation 2" in done.stderr
    assert json.loads((tmp_path / "summary.json").read_text())["generations"] == 3


@pytest.mark.slow
def test_learning_again_into_a_finished_run_needs_resume_or_force(tmp_path: Path) -> None:
    command = [
        sys.executable, "-m", "fishswarm", "learn", "--models", "4", "--classifiers", "4",
        "--generations", "1", "--out", str(tmp_path), "--quiet",
    ]  # fmt: skip

    def learn(*extra: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [*command, *extra], capture_output=True, text=True, timeout=120, check=False
        )

    assert learn().returncode == 0
    kept = (tmp_path / "checkpoint.npz").read_bytes()
    again = learn("--seed", "5")
    assert again.returncode == 2
    assert (
        "holds a learning run (checkpoint.npz, history.csv, best_replica.npz, radii.md, "
        "summary.json" in again.stderr
    )
    assert "): --resume continues it, --force starts over" in again.stderr
    assert (tmp_path / "checkpoint.npz").read_bytes() == kept  # nothing lost
    # Without its checkpoint the run cannot be resumed, but its results are still there.
    (tmp_path / "checkpoint.npz").rename(tmp_path / "kept.npz")
    results = learn("--seed", "5")
    assert results.returncode == 2
    assert "holds a learning run (history.csv, best_replica.npz" in results.stderr
    assert "--resume" not in results.stderr and "--force starts over" in results.stderr
    (tmp_path / "kept.npz").rename(tmp_path / "checkpoint.npz")
    assert learn("--seed", "5", "--force").returncode == 0
    assert (tmp_path / "checkpoint.npz").read_bytes() != kept


class _Stop(Exception):
    """Stands for Ctrl-C in the middle of a run."""


def _stop_at(generation: int) -> Any:
    def on_generation(run: Any, record: dict[str, float], seconds: float) -> None:
        if run.generation == generation:
            raise _Stop

    return on_generation


def test_a_new_run_clears_an_earlier_runs_outputs_before_it_starts(tmp_path: Path) -> None:
    # --force over a finished run, interrupted before its first checkpoint: the folder held
    # the old run's replica and summary beside nothing of the new one's, and 'run --model'
    # took the old replica for the new.
    for name in OUTPUTS:
        (tmp_path / name).write_text("the earlier run's")
    settings = LearningSettings(models=4, classifiers=4, seed=3)
    with pytest.raises(_Stop):
        learn(settings, generations=5, out=tmp_path, checkpoint_every=2, on_generation=_stop_at(1))
    assert list(tmp_path.iterdir()) == []


def test_a_resumed_run_goes_on_to_the_generation_it_was_started_for(tmp_path: Path) -> None:
    # Started for 4 generations and stopped after 2: '--resume' without '--generations'
    # carried on to the default 500 instead.
    from fishswarm.cli import main
    from fishswarm.learning.checkpoint import checkpoint_target

    settings = LearningSettings(models=4, classifiers=4, seed=3)
    with pytest.raises(_Stop):
        learn(settings, generations=4, out=tmp_path, checkpoint_every=1, on_generation=_stop_at(3))
    assert checkpoint_target(tmp_path / "checkpoint.npz") == 4
    assert main(["learn", "--out", str(tmp_path), "--resume", "--quiet"]) == 0
    assert json.loads((tmp_path / "summary.json").read_text())["generations"] == 4
    # Told otherwise, it goes on further, and says so for the next resume.
    assert main(["learn", "--out", str(tmp_path), "--resume", "--generations", "5", "--quiet"]) == 0
    assert checkpoint_target(tmp_path / "checkpoint.npz") == 5
    assert checkpoint_target(tmp_path / "missing.npz") is None


def test_resuming_to_fewer_generations_than_done_is_refused_with_what_to_give(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Done 2 of 4: asked to resume to 1, it said 'up to generation 1', then 'done: 2'.
    from fishswarm.cli import main
    from fishswarm.learning.checkpoint import checkpoint_generation

    settings = LearningSettings(models=4, classifiers=4, seed=3)
    with pytest.raises(_Stop):
        learn(settings, generations=4, out=tmp_path, checkpoint_every=1, on_generation=_stop_at(3))
    assert checkpoint_generation(tmp_path / "checkpoint.npz") == 2
    with pytest.raises(SystemExit) as exited:
        main(["learn", "--out", str(tmp_path), "--resume", "--generations", "1", "--quiet"])
    assert exited.value.code == 2
    assert (
        f"--out {tmp_path} has done 2 generations, more than --generations 1: give more to "
        "go on, or leave --generations out to go on to 4"
    ) in capsys.readouterr().err
    assert checkpoint_generation(tmp_path / "checkpoint.npz") == 2  # nothing changed


@pytest.mark.parametrize("stopped_at", [1, 3])
def test_ctrl_c_says_what_a_learning_run_kept_and_how_to_go_on(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    stopped_at: int,
) -> None:
    # It said only 'fishswarm: interrupted', and left an empty folder before the first
    # checkpoint.
    from fishswarm.cli import main
    from fishswarm.learning import session

    real = session.learn

    def interrupted(*args: Any, on_generation: Any, **kwargs: Any) -> Any:
        def progress(run: Any, record: dict[str, float], seconds: float) -> None:
            on_generation(run, record, seconds)
            if run.generation == stopped_at:
                raise KeyboardInterrupt

        return real(*args, on_generation=progress, **kwargs)

    monkeypatch.setattr(session, "learn", interrupted)
    out = tmp_path / "learned"
    command = ["learn", "--models", "4", "--classifiers", "4", "--seed", "3", "--generations",
               "6", "--checkpoint-every", "2", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(command) == 130
    said = capsys.readouterr().err.strip().splitlines()[-1]
    if stopped_at == 1:
        assert said == (
            "fishswarm: interrupted; nothing kept: interrupted before the first checkpoint "
            "(every 2 generations)"
        )
        assert not out.exists()
    else:
        assert said == (
            f"fishswarm: interrupted; {out / 'checkpoint.npz'} holds generation 2 (checkpoints "
            f"every 2): fishswarm learn --out {out} --resume goes on from there"
        )
        monkeypatch.setattr(session, "learn", real)
        assert main(["learn", "--out", str(out), "--resume", "--quiet"]) == 0  # as it says
