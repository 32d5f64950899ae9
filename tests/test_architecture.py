"""The package's shape: imports flow one way (DESIGN §1), with no circles, lazy ones included.

The layers, lowest first: ``protocols`` ← ``bluebot`` ← ``learning`` ← ``formations`` ←
``behaviors`` ← ``sim`` ← ``study`` ← ``actors`` ← ``cli``. A module may import its own
package and the layers below, never above; nothing below ``actors`` imports trio or zenoh.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "fishswarm"
LAYERS = ("protocols", "bluebot", "learning", "formations", "behaviors", "sim", "study", "actors")
RANK = {name: rank for rank, name in enumerate((*LAYERS, "cli"))}
PLUMBING = ("trio", "zenoh")


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _imports(path: Path) -> set[str]:
    """Every module ``path`` imports, at the top or inside a function (lazy)."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            # ``from fishswarm.sim import engine`` imports the module fishswarm.sim.engine.
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {
        name: {target for target in _imports(path) if target in modules and target != name}
        for name, path in modules.items()
    }


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in RANK else None


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A circle of imports, or None."""
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                return [*path[path.index(target) :], target]
            if target not in state and (found := visit(target)) is not None:
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)) is not None:
            return found
    return None


def test_the_import_graph_has_no_circle() -> None:
    graph = _graph()
    assert len(graph) > 40  # the whole package was read
    assert _cycle(graph) is None, " → ".join(_cycle(graph) or [])


def test_the_cycle_finder_finds_a_drawn_circle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_imports_flow_from_the_wire_up_to_the_command_line() -> None:
    against = []
    for module, targets in _graph().items():
        mine = _layer(module)
        for target in targets:
            theirs = _layer(target)
            if mine is not None and theirs is not None and RANK[theirs] > RANK[mine]:
                against.append(f"{module} imports {target}")
    assert not against, "\n".join(sorted(against))


@pytest.mark.parametrize("layer", [layer for layer in LAYERS if layer != "actors"])
def test_pure_layers_import_no_plumbing(layer: str) -> None:
    for module, path in _modules().items():
        if _layer(module) != layer:
            continue
        bad = {n for n in _imports(path) if n.split(".")[0] in PLUMBING}
        assert not bad, f"{module} imports {sorted(bad)}"


def test_only_the_entry_points_live_at_the_top_level() -> None:
    loose = sorted(p.name for p in PACKAGE.iterdir() if p.suffix == ".py")
    assert loose == ["__init__.py", "__main__.py"]
    packages = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    assert packages <= set(RANK), f"packages without a layer: {packages - set(RANK)}"
