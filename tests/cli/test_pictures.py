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
from fishswarm.study.recording import Recorder, open_recorder


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


def test_a_plots_title_counts_the_fish_recorded_not_those_configured(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A run configured for 2 fish, which fish 10 (a robot, say) joins at tick 2: the
    # recording holds 3 fish, and the title says so.
    pytest.importorskip("matplotlib")
    from fishswarm.study import figures

    path = tmp_path / "joined.mcap"
    with open_recorder(path, {"fish": 2, "behavior": "dispersion", "seed": 7}) as recorder:
        for tick in range(4):
            ids = np.array([0, 1, 10] if tick >= 2 else [0, 1])
            position = np.full((ids.size, 3), 0.5) + 0.1 * np.arange(ids.size)[:, None]
            count = ids.size
            snapshot = Snapshot(
                tick, float(tick), ids, position, np.zeros((count, 3)), np.zeros(count),
                np.full(count, count - 1), np.zeros(count, dtype=np.int64),
            )  # fmt: skip
            recorder.snapshot(float(tick), encode(snapshot))
            recorder.metrics(float(tick), swarm_metrics(position, snapshot.neighbors_seen))
    titles: list[str] = []
    drawn = figures.figure_of_run

    def figure_of_run(*args: Any, title: str, **kwargs: Any) -> Any:
        titles.append(title)
        return drawn(*args, title=title, **kwargs)

    monkeypatch.setattr(figures, "figure_of_run", figure_of_run)
    assert main(["plot", str(path), "--out", str(tmp_path / "tracks.png")]) == 0
    assert titles == ["3 fish, dispersion, seed 7 (joined.mcap)"]


@pytest.mark.slow
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


def test_outputs_that_cannot_be_written_are_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recording = _observed(tmp_path / "observed.mcap")
    folder = tmp_path / "a folder"
    folder.mkdir()
    for args, message in (
        (["export", str(recording), "--npz", str(tmp_path / "arrays")],
         "--npz must name a .npz file, e.g. --npz runs/latest.npz; got arrays"),
        (["export", str(recording), "--npz", str(folder)], f"{str(folder)!r} is a folder"),
        (["export", str(recording), "--csv", str(folder)], "--csv must name a file"),
        (["plot", str(recording), "--out", "/proc/none/x.png"],
         "--out /proc/none/x.png: its folder /proc/none: cannot write there"),
        (["animate", str(recording), "--out", str(folder / "sub" / "x.gif"), "--fps", "4"],
         None),
        (["observe", "--connect", "tcp/127.0.0.1:1", "--record", str(folder)],
         "--record must name a file, e.g. --record runs/observed.mcap"),
    ):  # fmt: skip
        code: int | str | None
        try:
            code = main(args)
        except SystemExit as usage:  # a usage error ends as argparse's do
            code = usage.code
        err = capsys.readouterr().err
        if message is None:  # a folder that does not exist yet is made
            assert code == 0 and (folder / "sub" / "x.gif").exists(), err
            continue
        assert code == 2 and message in err and "Traceback" not in err, (args, err)
    assert not (tmp_path / "arrays.npz").exists()


def test_a_recording_without_snapshots_has_nothing_to_export(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # As an earlier fishswarm wrote one for an observer that saw nothing (a recorder now
    # makes no file until the first snapshot): the header and the settings only.
    recording = tmp_path / "nothing.mcap"
    with recording.open("wb") as stream:
        Recorder(stream, {"observed": True}).finish()
    assert main(["export", str(recording), "--npz", str(tmp_path / "x.npz")]) == 1
    assert "holds no snapshots: nothing to export" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()


def test_the_fish_eye_view_sees_with_the_recorded_runs_vision_model() -> None:
    from fishswarm.bluebot.vision import Vision
    from fishswarm.cli.study import _vision_of
    from fishswarm.sim.scenario import Scenario

    ran = Scenario(profile="study-code", blind_width=0.25, vision_noise=0.1)
    vision = _vision_of(ran.to_dict())
    # The study code's range is Manhattan; the noise is left out (the view draws where
    # neighbours are); the blind spot is the run's.
    assert vision == Vision(3.0, 0.25, 0.065, 0.0, manhattan=True)
    assert _vision_of({"observed": True}) == Vision()  # an observer's: a BlueBot's


def test_ctrl_c_while_animating_says_what_the_file_holds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("matplotlib")
    from fishswarm.study import animation

    recording = _observed(tmp_path / "observed.mcap", ticks=20)
    out = tmp_path / "fish.gif"
    drawn = animation.animate

    def interrupted_at_frame_six(*args: Any, on_frame: Any, **kwargs: Any) -> Any:
        def count(done: int, total: int) -> None:
            on_frame(done, total)
            if done == 5:
                raise KeyboardInterrupt

        return drawn(*args, on_frame=count, **kwargs)

    monkeypatch.setattr(animation, "animate", interrupted_at_frame_six)
    assert main(["animate", str(recording), "--out", str(out), "--quiet"]) == 130
    said = capsys.readouterr().err.strip().splitlines()
    assert said[-1] == (f"fishswarm: interrupted at frame 5 of 96; {out} holds its first 5 frames")
    assert out.read_bytes()[:6] in (b"GIF87a", b"GIF89a")


def test_animating_says_how_long_is_left(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A long run at the default speed drew thousands of frames, half an hour, saying only
    # 'frame 10/9091'.
    import re

    from fishswarm.cli.study import _duration_text

    pytest.importorskip("matplotlib")
    recording = _observed(tmp_path / "observed.mcap")
    assert main(["animate", str(recording), "--out", str(tmp_path / "fish.gif")]) == 0
    lines = capsys.readouterr().err.splitlines()
    assert re.fullmatch(r"\[#+\.*\] frame 10/16  ~\d+ s left", lines[0]), lines
    assert re.fullmatch(r"\[#{20}\] frame 16/16  ~0 s left", lines[-2]), lines
    assert [_duration_text(s) for s in (42.4, 210.0, 7200.0)] == ["42 s", "3.5 min", "2.0 h"]
