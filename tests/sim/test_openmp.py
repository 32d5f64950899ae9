"""How the OpenMP workers wait (fishswarm.sim.openmp)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from fishswarm.sim.openmp import SPIN_COUNT, openmp_waits, tune_openmp


@pytest.fixture
def clean(monkeypatch: pytest.MonkeyPatch) -> pytest.MonkeyPatch:
    monkeypatch.delenv("GOMP_SPINCOUNT", raising=False)
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    return monkeypatch


def test_the_spin_count_is_set_unless_the_environment_says_how_workers_wait(
    clean: pytest.MonkeyPatch,
) -> None:
    import os

    assert openmp_waits() == "OpenMP waits: libgomp default"
    assert tune_openmp() is True
    assert os.environ["GOMP_SPINCOUNT"] == str(SPIN_COUNT) == "30000"
    assert openmp_waits() == "OpenMP waits: GOMP_SPINCOUNT=30000"
    clean.setenv("GOMP_SPINCOUNT", "5")
    assert tune_openmp() is False and os.environ["GOMP_SPINCOUNT"] == "5"
    clean.delenv("GOMP_SPINCOUNT")
    clean.setenv("OMP_WAIT_POLICY", "passive")
    assert tune_openmp() is False and "GOMP_SPINCOUNT" not in os.environ
    assert openmp_waits() == "OpenMP waits: OMP_WAIT_POLICY=passive"


def test_the_fishswarm_command_sets_it_for_itself_and_the_processes_it_starts(
    clean: pytest.MonkeyPatch,
) -> None:
    # The command's own setting, before numba loads OpenMP, as its worker processes inherit it.
    script = "import os\nfrom fishswarm.cli import main\nmain(['behaviors'])\n"
    shown = subprocess.run(
        [sys.executable, "-c", script + "print(os.environ.get('GOMP_SPINCOUNT'))"],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert shown.stdout.split()[-1] == "30000", shown.stderr
