"""Animation helpers: resampling between snapshots, frame durations, the views, and the
fish's-eye geometry."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from fishswarm.bluebot.vision import Vision
from fishswarm.study.animation import (
    ARROW_LENGTH,
    AnimationError,
    animation_figure,
    eye_view,
    frame_duration,
    resample,
)


def test_resampling_is_linear_and_turns_the_short_way() -> None:
    t = np.array([0.0, 1.0, 2.0])
    position = np.array([[[0.0, 0.0, 0.5]], [[1.0, 2.0, 0.5]], [[1.0, 2.0, 0.5]]])
    yaw = np.array([[math.radians(170)], [math.radians(-170)], [math.radians(-170)]])
    frames = resample(t, position, yaw, np.array([4]), step=0.25)
    np.testing.assert_allclose(frames.t, np.arange(9) * 0.25)
    np.testing.assert_allclose(frames.position[2, 0], [0.5, 1.0, 0.5])
    np.testing.assert_allclose(frames.position[-1, 0], [1.0, 2.0, 0.5])
    # Halfway from 170° to −170° the short way is 180°, not 0°.
    assert abs(math.cos(frames.yaw[2, 0]) + 1) < 1e-12
    assert frames.position.shape == (9, 1, 3)
    # Steps that do not divide a snapshot interval: 0.6 s apart, across snapshots.
    uneven = resample(t, position, yaw, np.array([4]), step=0.6)
    np.testing.assert_allclose(uneven.t, [0.0, 0.6, 1.2, 1.8])
    np.testing.assert_allclose(uneven.position[1, 0], [0.6, 1.2, 0.5])
    with pytest.raises(AnimationError, match="must be positive"):
        resample(t, position, yaw, np.array([4]), step=0.0)


def test_frames_last_as_long_as_the_format_really_shows_them() -> None:
    assert frame_duration(".mp4", 15) == pytest.approx(1 / 15)
    assert frame_duration(".gif", 10) == pytest.approx(0.1)
    # 1000/15 = 66 ms, kept by a GIF as 6 hundredths of a second.
    assert frame_duration(".gif", 15) == pytest.approx(0.06)
    with pytest.raises(AnimationError, match="at most 50 frames per second"):
        frame_duration(".gif", 60)


def test_the_animation_views_read_like_a_plan_an_elevation_and_a_camera() -> None:
    pytest.importorskip("matplotlib")
    t = np.array([0.0, 1.0])
    # Fish 7 heads +x at (0.5, 0.5, 0.3); fish 9 heads +y at (1.2, 1.0, 0.8).
    position = np.array([[[0.5, 0.5, 0.3], [1.2, 1.0, 0.8]]] * 2)
    yaw = np.array([[0.0, math.pi / 2]] * 2)
    frames = resample(t, position, yaw, np.array([7, 9]), step=0.5)
    figure, draw = animation_figure(
        frames, tank=(1.78, 1.78, 1.17), vision=Vision(), viewer=9, title="test"
    )
    draw(1)
    above, side, circling, eye = figure.axes
    assert (above.get_xlabel(), above.get_ylabel(), above.get_title()) == (
        "x (m)",
        "y (m)",
        "from above",
    )
    assert (side.get_xlabel(), side.get_ylabel()) == ("x (m)", "depth (m)")
    assert side.get_ylim() == (1.17, 0.0)  # depth grows downwards
    assert circling.name == "3d" and len(circling.get_zticks()) == 3
    assert eye.get_xlabel() == "bearing (deg, right +)"
    # From above, each fish is an arrow one body length long along its heading, in metres;
    # the viewer is red.
    (arrows,) = above.collections
    np.testing.assert_allclose(arrows.U, [ARROW_LENGTH, 0.0], atol=1e-12)
    np.testing.assert_allclose(arrows.V, [0.0, ARROW_LENGTH], atol=1e-12)
    assert arrows.scale == 1.0 and arrows.scale_units == "xy"
    red = matplotlib_colors().to_rgba("tab:red")
    assert tuple(arrows.get_facecolors()[1]) == red
    # From the side only the x component shows: fish 9 (heading +y) is end-on.
    (edge_on,) = side.collections
    np.testing.assert_allclose(edge_on.U, [ARROW_LENGTH, 0.0], atol=1e-12)


def test_formation_frames_show_roles_and_the_target() -> None:
    pytest.importorskip("matplotlib")
    from fishswarm.formations.maps import target_map
    from fishswarm.study.figures import ROLE_COLOURS
    from fishswarm.study.metrics import FormationTarget

    slots = target_map("pyramid", 3, spacing=0.3)
    placed = slots + np.array([1.0, 1.0, 0.5])
    position = np.stack([placed, placed])
    frames = resample(
        np.array([0.0, 1.0]), position, np.zeros((2, 3)), np.array([1, 2, 3]), step=1.0
    )
    figure, draw = animation_figure(
        frames, tank=(1.78, 1.78, 1.17), vision=Vision(), viewer=3, title="f",
        formation=FormationTarget(slots, 0.3, 0.05),
    )  # fmt: skip
    draw(1)
    above = figure.axes[0]
    hollow, arrows = above.collections
    np.testing.assert_allclose(
        np.sort(hollow.get_offsets(), axis=0), np.sort(placed[:, :2], axis=0), atol=1e-9
    )
    to_rgba = matplotlib_colors().to_rgba
    # Fish 1 on the apex leads, fish 2 has joined, fish 3 (the viewer) is red.
    assert [tuple(c) for c in arrows.get_facecolors()] == [
        to_rgba(ROLE_COLOURS["leader"]), to_rgba(ROLE_COLOURS["joined"]), to_rgba("tab:red"),
    ]  # fmt: skip
    assert [t.get_text() for t in above.get_legend().get_texts()] == list(ROLE_COLOURS)


def test_after_a_switch_the_frames_show_the_new_target() -> None:
    # The fish hold a column all along; the run starts as a pyramid and switches at 1 s.
    pytest.importorskip("matplotlib")
    from fishswarm.formations.maps import target_map
    from fishswarm.study.metrics import FormationTarget

    column = target_map("column", 3, spacing=0.3)
    placed = column + np.array([1.0, 1.0, 0.5])
    frames = resample(
        np.array([0.0, 2.0]), np.stack([placed, placed]), np.zeros((2, 3)),
        np.array([1, 2, 3]), step=1.0,
    )  # fmt: skip
    pyramid = FormationTarget(target_map("pyramid", 3, spacing=0.3), 0.3, 0.05)
    figure, draw = animation_figure(
        frames, tank=(1.78, 1.78, 1.17), vision=Vision(), viewer=3,
        formation=pyramid, switches=[(1.0, FormationTarget(column, 0.3, 0.05))],
    )  # fmt: skip
    above = figure.axes[0]

    def target_shown(frame: int) -> np.ndarray:
        draw(frame)
        hollow = above.collections[0]
        return np.sort(np.asarray(hollow.get_offsets()), axis=0)

    on_the_fish = np.sort(placed[:, :2], axis=0)
    assert not np.allclose(target_shown(0), on_the_fish, atol=1e-6)  # still the pyramid
    np.testing.assert_allclose(target_shown(1), on_the_fish, atol=1e-9)  # the column, at 1 s
    np.testing.assert_allclose(target_shown(2), on_the_fish, atol=1e-9)


def matplotlib_colors() -> Any:
    import matplotlib.colors

    return matplotlib.colors


def test_eye_view_by_hand() -> None:
    # The viewer at (1, 1, 1) faces +x. One neighbour 1 m ahead and 1 m higher (z down),
    # one 1 m to its right (+y), one 1 m straight behind (in the blind spot).
    position = np.array([[1.0, 1.0, 1.0], [2.0, 1.0, 0.0], [1.0, 2.0, 1.0], [0.0, 1.0, 1.0]])
    yaw = np.zeros(4)
    bearing, elevation, distance = eye_view(position, yaw, 0, Vision(sphere_radius=0.0))
    order = np.argsort(bearing)
    np.testing.assert_allclose(bearing[order], [0.0, 90.0], atol=1e-9)
    np.testing.assert_allclose(elevation[order], [45.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(distance[order], [math.sqrt(2), 1.0])


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_ctrl_c_while_writing_frames_keeps_those_written(tmp_path: Any, suffix: str) -> None:
    """Ctrl-C at the sixth frame: the file holds five, and the interrupt says so. For an
    MP4, Ctrl-C stops ffmpeg too (its process group's signal), and the writer then failed
    on ffmpeg's exit status: the same interrupt, not that error."""
    import signal

    pytest.importorskip("matplotlib")
    if suffix == ".mp4":
        pytest.importorskip("imageio_ffmpeg")
    from matplotlib import animation as mpl_animation

    from fishswarm.study.animation import AnimationInterrupted, animate

    t = np.arange(0.0, 20.0)
    position = np.tile([[[0.5, 0.5, 0.3], [1.2, 1.0, 0.8]]], (t.size, 1, 1))
    frames = resample(t, position, np.zeros((t.size, 2)), np.array([7, 9]), step=1.0)
    out = tmp_path / f"fish{suffix}"
    writers: list[Any] = []
    saving = mpl_animation.AbstractMovieWriter.saving

    def interrupted(done: int, total: int) -> None:
        if done == 5:
            if suffix == ".mp4":  # ffmpeg hears Ctrl-C as the process does
                writers[0]._proc.send_signal(signal.SIGINT)
            raise KeyboardInterrupt

    def recorded(writer: Any, *args: Any, **kwargs: Any) -> Any:
        writers.append(writer)
        return saving(writer, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(mpl_animation.AbstractMovieWriter, "saving", recorded)
        with pytest.raises(AnimationInterrupted, match="interrupted after 5 of 20 frames") as stop:
            animate(frames, tank=(1.78, 1.78, 1.17), vision=Vision(), viewer=7, out=out,
                    on_frame=interrupted)  # fmt: skip
    assert (stop.value.written, stop.value.total) == (5, 20)
    assert out.stat().st_size > 0
    if suffix == ".gif":
        from PIL import Image

        gif: Any
        with Image.open(out) as gif:
            assert gif.n_frames == 5
