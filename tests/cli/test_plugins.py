"""Another package's behaviour, installed beside fishswarm, in real processes: listed by
``--help``, run by the launcher and its worker processes; a broken one said and left out."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.behaviors.example_plugin import EXAMPLE, NEAREST_ENTRY_POINT, installed
from tests.conftest import free_port, install_wheel_of

pytestmark = pytest.mark.integration

FISHSWARM = [sys.executable, "-m", "fishswarm"]


def _fishswarm(
    *args: str, path: list[Path], cwd: Path, timeout: float = 120.0
) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(str(p) for p in path)}
    return subprocess.run(
        [*FISHSWARM, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        cwd=cwd,
        env=env,
    )


def _run_nearest(site: Path, path: list[Path], tmp_path: Path) -> dict[str, object]:
    summary = tmp_path / "run.json"
    done = _fishswarm(
        "run", "--behavior", "nearest", "--fish", "4", "--duration", "3", "--procs", "1",
        "--quiet", "--behavior-setting", "distance=0.3", "--summary", str(summary),
        "--record", str(tmp_path / "run.mcap"), "--listen", f"tcp/127.0.0.1:{free_port()}",
        path=path, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "warning" not in done.stderr, done.stderr
    assert done.stderr.startswith("fishswarm: 4 fish, nearest (distance 0.3), 3 s at 1 Hz")
    result: dict[str, object] = json.loads(summary.read_text())
    return result


def test_another_packages_behaviour_runs_in_the_launcher_and_its_workers(tmp_path: Path) -> None:
    site = tmp_path / "site"
    installed(site, "fishswarm-nearest", NEAREST_ENTRY_POINT)
    help_text = _fishswarm("run", "--help", path=[site, EXAMPLE], cwd=tmp_path).stdout
    assert "replica, formation, nearest (default dispersion)" in " ".join(help_text.split())
    summary = _run_nearest(site, [site, EXAMPLE], tmp_path)
    assert summary["status"] == "finished"
    scenario = summary["scenario"]
    assert isinstance(scenario, dict)
    assert (scenario["behavior"], scenario["behavior_settings"]) == ("nearest", {"distance": 0.3})
    counts = summary["counts"]
    assert isinstance(counts, dict) and counts["lost_fish"] == 0


def test_the_behaviours_are_listed_with_their_packages_and_own_settings(tmp_path: Path) -> None:
    site = tmp_path / "site"
    installed(site, "fishswarm-nearest", NEAREST_ENTRY_POINT)
    installed(site, "fishswarm-broken", "[fishswarm.behaviors]\ngone = no_such_module_here:GONE\n")
    done = _fishswarm("behaviors", path=[site, EXAMPLE], cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split()[0] for line in lines[:7]] == [
        "dispersion", "aggregation", "orbit", "milling", "waltz", "replica", "formation",
    ]  # fmt: skip
    assert lines[0] == (
        "dispersion   Lennard-Jones with the target distance at the tank diagonal: spread out"
    )
    assert lines[7:] == [
        "nearest      keep the nearest visible neighbour at a distance (an example package's)"
        "  [fishswarm_nearest:NEAREST in fishswarm-nearest 0.1.0]",
        "             its settings (--behavior-setting NAME=VALUE): distance = 0.26, cruise = 0.52",
        "left out: the behaviour 'gone' (no_such_module_here:GONE in fishswarm-broken 0.1.0) is "
        "left out: loading it raised ModuleNotFoundError: No module named 'no_such_module_here'",
    ]
    assert done.stderr == ""  # the list says it, once


def test_an_experiment_sweeps_a_behaviours_own_setting(tmp_path: Path) -> None:
    site = tmp_path / "site"
    installed(site, "fishswarm-nearest", NEAREST_ENTRY_POINT)
    experiment = tmp_path / "spacing.toml"
    experiment.write_text(
        '[experiment]\nname = "spacing"\nparameter = "distance"\nlabel = "kept distance (m)"\n'
        "values = [0.2, 0.6]\nseeds = 1\n"
        '[scenario]\nbehavior = "nearest"\nfish = 5\nduration = 20\n'
        "behavior_settings = { cruise = 0.3 }\n"
    )
    out = tmp_path / "out"
    done = _fishswarm(
        "experiment", str(experiment), "--engine", "batch", "--jobs", "1", "--quiet",
        "--out", str(out), path=[site, EXAMPLE], cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    rows = (out / "table.csv").read_text().splitlines()
    header = rows[0].split(",")
    assert header[0] == "distance", header
    values = [dict(zip(header, row.split(","), strict=True)) for row in rows[1:]]
    assert [row["distance"] for row in values] == ["0.2", "0.6"]
    # Fish that keep their nearest neighbour farther off spread farther from it.
    grew = [float(row["nearest_neighbor_distance_change_percent_mean"]) for row in values]
    assert grew[1] > grew[0] + 30, grew


def test_a_broken_behaviour_package_is_said_and_left_out(tmp_path: Path) -> None:
    site = tmp_path / "site"
    installed(site, "fishswarm-broken", "[fishswarm.behaviors]\ngone = no_such_module_here:GONE\n")
    done = _fishswarm(
        "run", "--behavior", "gone", "--fish", "2", "--duration", "1",
        path=[site], cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 2
    lines = done.stderr.splitlines()
    assert lines[0] == (
        "fishswarm run: warning: the behaviour 'gone' (no_such_module_here:GONE in "
        "fishswarm-broken 0.1.0) is left out: loading it raised ModuleNotFoundError: No "
        "module named 'no_such_module_here'"
    )
    assert lines[-1].startswith("fishswarm run: error: behavior must be one of dispersion,")
    assert lines[-1].endswith(
        "formation, got 'gone': the behaviour 'gone' (no_such_module_here:GONE in "
        "fishswarm-broken 0.1.0) is left out: loading it raised ModuleNotFoundError: No module "
        "named 'no_such_module_here'"
    )
    # --help, which exits before any warning, names it too.
    listed = _fishswarm("run", "--help", path=[site], cwd=tmp_path).stdout
    assert "formation (gone left out: 'fishswarm behaviors' says why)" in " ".join(listed.split())


@pytest.mark.slow
def test_the_example_package_builds_installs_and_runs(tmp_path: Path) -> None:
    """The example's own pyproject.toml, built into a wheel and installed as pip would on a
    base station or a robot (without its dependencies: fishswarm is there already)."""

    source = shutil.copytree(EXAMPLE, tmp_path / "source")  # built there: the tree stays clean
    site = install_wheel_of(source, tmp_path, "fishswarm_nearest-0.1.0-*.whl")
    summary = _run_nearest(site, [site], tmp_path)
    assert summary["status"] == "finished"
