"""A robot or a fresh machine installs the core only (no cma, no matplotlib, no gpiozero):
the swarm must still run, every command's --help must work, and a command that needs an
extra says which to install (exit 1, no traceback)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import free_port

pytestmark = pytest.mark.integration

# Blocks the extras as if they were not installed: importing them raises ImportError.
WITHOUT_EXTRAS = (
    "import sys\n"
    "for name in ('cma', 'matplotlib', 'imageio_ffmpeg', 'hypothesis', 'rerun', 'gpiozero'):\n"
    "    sys.modules[name] = None\n"
    "from fishswarm.cli import main\n"
    "sys.exit(main(sys.argv[1:]))\n"
)


def _core(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", WITHOUT_EXTRAS, *args],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def test_a_swarm_runs_with_the_core_dependencies_only(tmp_path: Path) -> None:
    listen = f"tcp/127.0.0.1:{free_port()}"
    record, summary = str(tmp_path / "r.mcap"), str(tmp_path / "s.json")
    result = _core(
        "run",
        "--fish",
        "3",
        "--duration",
        "2",
        "--quiet",
        "--listen",
        listen,
        "--record",
        record,
        "--summary",
        summary,
    )
    assert result.returncode == 0, result.stderr
    assert "status: finished" in result.stderr
    directory = _core("run", "--record", str(tmp_path), "--listen", listen)
    assert directory.returncode == 2
    assert "--record must name a file" in directory.stderr


@pytest.mark.parametrize(
    "command",
    ["run", "fish", "world", "observe", "view", "experiment", "plot", "animate", "learn"],
)
def test_every_help_works_with_the_core_dependencies_only(command: str) -> None:
    result = _core(command, "--help")
    assert result.returncode == 0, result.stderr
    assert "usage: fishswarm" in result.stdout


def test_pictures_without_matplotlib_say_how_to_get_it(tmp_path: Path) -> None:
    listen = f"tcp/127.0.0.1:{free_port()}"
    record = tmp_path / "r.mcap"
    made = _core(
        "run",
        "--fish",
        "2",
        "--duration",
        "1",
        "--quiet",
        "--listen",
        listen,
        "--record",
        str(record),
        "--summary",
        str(tmp_path / "s.json"),
    )
    assert made.returncode == 0, made.stderr
    result = _core("plot", str(record))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "pictures need matplotlib: pip install -e '.[viz]'" in result.stderr
    result = _core("animate", str(record), "--out", str(tmp_path / "r.gif"))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "animations need matplotlib: pip install -e '.[viz]'" in result.stderr


def test_learning_without_pycma_says_how_to_get_it(tmp_path: Path) -> None:
    result = _core("learn", "--generations", "1", "--out", str(tmp_path / "learned"))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "Turing learning needs pycma: pip install -e '.[learn]'" in result.stderr


def test_a_mock_robot_without_gpiozero_says_how_to_get_it() -> None:
    # Its pins are gpiozero's mock pins: it fails before it looks for the router.
    result = _core(
        "robot", "--id", "3", "--hardware", "mock", "--connect", f"tcp/127.0.0.1:{free_port()}"
    )
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert "a mock robot runs on gpiozero's mock pins: pip install -e '.[robot]'" in (result.stderr)


def test_an_experiment_without_matplotlib_writes_its_tables(tmp_path: Path) -> None:
    out = tmp_path / "blindspot"
    result = _core(
        "experiment",
        "blindspot",
        "--seeds",
        "1",
        "--duration",
        "1",
        "--engine",
        "batch",
        "--jobs",
        "1",
        "--out",
        str(out),
        "--quiet",
    )
    assert result.returncode == 0, result.stderr
    assert (out / "table.md").exists() and not (out / "tracks.png").exists()
    assert "tables written, no pictures: pictures need matplotlib" in result.stderr


def test_a_view_without_the_rerun_sdk_says_how_to_get_it(tmp_path: Path) -> None:
    ran = _core(
        "run", "--fish", "2", "--duration", "1", "--quiet", "--view",
        "--listen", f"tcp/127.0.0.1:{free_port()}", "--record", str(tmp_path / "r.mcap"),
    )  # fmt: skip
    assert ran.returncode == 1 and "Traceback" not in ran.stderr
    assert (
        "the view (of a live swarm or of a recording) needs the rerun SDK: pip install -e "
        "'.[view]'" in ran.stderr
    )
