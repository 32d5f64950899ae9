"""A normal (non-editable) install carries everything a user runs: the study's experiment
files are package data, found wherever fishswarm is installed."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import install_wheel_of

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.integration


def test_an_installed_wheel_finds_the_studys_experiments(tmp_path: Path) -> None:
    site = install_wheel_of(ROOT, tmp_path, "fishswarm-*.whl")
    program = (
        f"import sys; sys.path.insert(0, {str(site)!r})\n"
        "import fishswarm.study.experiment as e\n"
        f"assert e.__file__.startswith({str(site)!r}), e.__file__\n"
        "print(','.join(e.available()), e.find('milling').scenario.behavior)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", program],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    names, behavior = result.stdout.split()
    assert set(names.split(",")) >= {"blindspot", "blockingsphere", "orbit", "milling", "waltz"}
    assert behavior == "milling"
