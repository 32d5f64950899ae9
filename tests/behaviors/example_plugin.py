"""The example package's behaviour (``examples/behavior_plugin``), for the tests: importable
without installing it, and registered in this process when a test asks."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from fishswarm.behaviors.core import Behavior
from fishswarm.behaviors.registry import BEHAVIORS, register

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "behavior_plugin"
"""The example package's folder (its pyproject.toml and its module)."""


def nearest() -> Behavior:
    """The example's behaviour, imported from its folder."""
    if str(EXAMPLE) not in sys.path:
        sys.path.append(str(EXAMPLE))
    family: Behavior = importlib.import_module("fishswarm_nearest").NEAREST
    return family


def registered() -> Behavior:
    """The example's behaviour, registered (once) in this process."""
    family = nearest()
    if BEHAVIORS.get(family.name) is not family:
        register(family)
    return family


def installed(site: Path, name: str, entry_points: str) -> None:
    """A distribution's metadata in ``site``, as pip leaves it: what Python's
    importlib.metadata reads the entry points from (the module itself comes from elsewhere
    on the path, e.g. :data:`EXAMPLE`)."""
    info = site / f"{name.replace('-', '_')}-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text(entry_points)


NEAREST_ENTRY_POINT = "[fishswarm.behaviors]\nnearest = fishswarm_nearest:NEAREST\n"
"""The example's entry point, as its pyproject.toml names it."""
