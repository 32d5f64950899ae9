"""Pictures of any recording: an observer's too, and into folders that do not exist yet."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fishswarm.cli import main
from fishswarm.protocols.codec import encode
from fishswarm.protocols.messages import Snapshot
from fishswarm.study.metrics import swarm_metrics
from fishswarm.study.recording import open_recorder


def _observed(path: Path, ticks: int = 4) -> Path:
    """A recording as ``fishswarm observe --record`` writes it: no scenario settings."""
    rng = np.random.default_rng(0)
    with open_recorder(path, {"observed": True}) as recorder:
        position = rng.uniform(0.2, 1.5, (3, 3))
        for tick in range(ticks):
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


def test_an_animation_plays_at_the_speed_asked_for(tmp_path: Path) -> None:
    # 12 s of run at 6× should play for 2 s (and one frame more, the last). At 15 fps a GIF
    # shows each frame 0.06 s, not 1/15 s: spaced by 1/15 s of play, the run played 10 %
    # fast.
    pytest.importorskip("matplotlib")
    from PIL import Image

    recording = _observed(tmp_path / "observed.mcap", ticks=13)
    out = tmp_path / "fish.gif"
    command = ["animate", str(recording), "--out", str(out), "--speed", "6", "--fps", "15"]
    assert main([*command, "--quiet"]) == 0
    gif: Any
    with Image.open(out) as gif:
        shown = []
        for frame in range(gif.n_frames):
            gif.seek(frame)
            shown.append(gif.info["duration"] / 1000)
    played = sum(shown) - shown[-1]  # until the last frame appears
    assert played == pytest.approx(12 / 6, rel=0.05)
