"""Pictures of any recording: an observer's too, and into folders that do not exist yet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fishswarm.cli import main
from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Snapshot
from fishswarm.study.metrics import swarm_metrics
from fishswarm.study.recording import open_recorder


def _observed(path: Path) -> Path:
    """A recording as ``fishswarm observe --record`` writes it: no scenario settings."""
    rng = np.random.default_rng(0)
    with open_recorder(path, {"observed": True}) as recorder:
        position = rng.uniform(0.2, 1.5, (3, 3))
        for tick in range(4):
            position = position + rng.normal(0, 0.05, (3, 3))
            snapshot = Snapshot(
                tick, float(tick), np.arange(3), position, np.zeros((3, 3)), np.zeros(3),
                np.full(3, 2), np.zeros(3, dtype=np.int64),
            )  # fmt: skip
            recorder.snapshot(float(tick), encode(snapshot))
            recorder.metrics(float(tick), swarm_metrics(position, snapshot.neighbors_seen))
    return path


def test_plot_draws_an_observers_recording_into_a_new_folder(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    recording = _observed(tmp_path / "observed.mcap")
    out = tmp_path / "new" / "folder" / "tracks.png"
    assert main(["plot", str(recording), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_animate_draws_an_observers_recording_into_a_new_folder(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    recording = _observed(tmp_path / "observed.mcap")
    out = tmp_path / "made" / "here" / "fish.gif"
    assert main(["animate", str(recording), "--out", str(out), "--fps", "4", "--quiet"]) == 0
    assert out.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
