"""The benchmark and documentation scripts still import, and their ``--help`` explains every
option: nothing else runs them between the sessions that write their results."""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted(
    path
    for path in [*ROOT.glob("bench/*.py"), *ROOT.glob("docs/*.py")]
    if 'if __name__ == "__main__":' in path.read_text()
)


def _load(path: Path, monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    # bench_swarm imports bench_bridge as its neighbour, as when run from its folder.
    monkeypatch.syspath_prepend(str(path.parent))
    spec = importlib.util.spec_from_file_location(f"script_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _help_of(module: ModuleType, monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setattr(sys, "argv", [f"{module.__name__}.py", "--help"])
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as stopped:
        module.main()
    assert stopped.value.code == 0
    return out.getvalue()


def test_there_are_scripts_to_check() -> None:
    names = {path.name for path in SCRIPTS}
    assert {"bench_swarm.py", "bench_engine.py", "bench_camera.py", "view_picture.py"} <= names


@pytest.mark.parametrize("path", SCRIPTS, ids=[f"{p.parent.name}/{p.name}" for p in SCRIPTS])
def test_a_script_imports_and_its_help_explains_every_option(
    path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    module = _load(path, monkeypatch)
    assert module.__doc__, f"{path.name} says nothing about what it does"
    parsers: list[argparse.ArgumentParser] = []
    real_parse = argparse.ArgumentParser.parse_args

    def spy(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> object:
        parsers.append(self)
        return real_parse(self, *args, **kwargs)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", spy)
    text = _help_of(module, monkeypatch)
    assert text.startswith("usage:"), text
    (parser,) = parsers
    unexplained = [
        action.option_strings[0]
        for action in parser._actions
        if action.option_strings and action.help in (None, "")
    ]
    assert unexplained == [], f"{path.name}: options without help: {unexplained}"
    # The description says the docstring's whole first sentence, not its first line.
    description = parser.description or ""
    assert description.rstrip().endswith((".", ")")), f"{path.name}: {description!r}"


def test_the_swarm_benchmark_times_the_batch_engines_steps(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    module = _load(ROOT / "bench" / "bench_swarm.py", monkeypatch)
    monkeypatch.setitem(module.BATCH_DURATION, 5, 4.0)
    phases = module.batch_phases(5)
    assert set(phases) == {"physics", "vision"}
    assert all(0.0 < seconds < 1.0 for seconds in phases.values())


def test_the_swarm_benchmark_reports_the_round_of_the_median_ratio_and_the_range(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    module = _load(ROOT / "bench" / "bench_swarm.py", monkeypatch)
    # Three rounds of (batch tick, actor tick), s: actors / batch 2.0, 1.5 and 3.0.
    rounds = [(0.002, {"tick": 0.004}), (0.002, {"tick": 0.003}), (0.001, {"tick": 0.003})]
    batch, row, spread = module.median_round(rounds, 0.0005)
    assert (batch, row["tick"]) == (0.002, 0.004)  # the median of 1.5, 2.0, 3.0
    assert spread["batch"] == (1.5, 3.0)
    assert spread["echo"] == pytest.approx((0.003 / 0.0025, 0.003 / 0.0015))
    assert spread["share"] == pytest.approx((1 / 3, 2 / 3))
    # Of two rounds, the lower: actors / batch 1.5 before 2.0.
    batch, row, _ = module.median_round(rounds[:2], 0.0005)
    assert row["tick"] == 0.003
    assert module._with_range(1.5, (1.5, 1.5)) == "1.50"
    assert module._with_range(2.0, (1.5, 3.0)) == "2.00 (1.50–3.00)"


def test_the_learning_pictures_name_a_folder_learn_did_not_write(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    module = _load(ROOT / "docs" / "learning_pictures.py", monkeypatch)
    monkeypatch.setattr(sys, "argv", ["learning_pictures.py", str(tmp_path / "nope")])
    with pytest.raises(SystemExit) as stopped:
        module.main()
    assert stopped.value.code == 2
    assert "nope holds no summary.json: give folders that fishswarm learn wrote" in (
        capsys.readouterr().err
    )
