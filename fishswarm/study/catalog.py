"""The study's experiments that ship with fishswarm: where their files are, their names, and
the engines a sweep can run them on.

Kept apart from :mod:`fishswarm.study.experiment` (which needs scipy for its metrics) so that
building the ``fishswarm`` command's help imports nothing a robot lacks: a BlueBot's Pi runs
``fishswarm robot`` without scipy (DESIGN §7).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

EXPERIMENTS_FOLDER = Path(__file__).resolve().parent / "experiments"
"""The experiment files shipped with the package (``experiments/`` in a checkout links here)."""

ENGINES = ("actors", "batch")
"""How an experiment's runs go: through the actor system, or the in-process batch engine."""


def available() -> list[str]:
    """Names of the experiments shipped with fishswarm (``fishswarm/study/experiments/``)."""
    if not EXPERIMENTS_FOLDER.is_dir():
        return []
    return sorted(
        path.stem
        for path in EXPERIMENTS_FOLDER.glob("*.toml")
        if "experiment" in tomllib.loads(path.read_text(encoding="utf-8"))
    )
