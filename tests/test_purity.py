"""Imports flow one way: the pure packages never import trio or zenoh (nor actors)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "fishswarm"
PLUMBING = {"actors", "cli.py", "__init__.py", "__pycache__"}
# Every other part of the package is pure: new packages are covered as soon as they exist.
PURE = sorted(p.name for p in PACKAGE.iterdir() if p.name not in PLUMBING)
FORBIDDEN = ("trio", "zenoh", "fishswarm.actors")


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
    return names


@pytest.mark.parametrize("part", PURE)
def test_pure_modules_import_no_plumbing(part: str) -> None:
    assert {"protocols", "bluebot", "behaviors", "simulation.py"} <= set(PURE)
    root = PACKAGE / part
    files = [root] if root.suffix == ".py" else sorted(root.rglob("*.py"))
    assert files
    for path in files:
        bad = {n for n in _imports(path) if n.split(".")[0] in FORBIDDEN or n.startswith(FORBIDDEN)}
        assert not bad, f"{path.relative_to(PACKAGE)} imports {sorted(bad)}"


def test_protocols_import_nothing_else_of_fishswarm() -> None:
    for path in (PACKAGE / "protocols").rglob("*.py"):
        others = {
            n
            for n in _imports(path)
            if n.startswith("fishswarm.") and not n.startswith("fishswarm.protocols")
        }
        assert not others, f"{path.name} imports {sorted(others)}"
