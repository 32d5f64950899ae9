"""Animations of recorded runs: the fish as arrows in the tank, and what one fish sees.

The study's BlueAnimat, redone: four views side by side — from above, from the side, a camera
circling the tank, and through the eyes of one fish, which shows only the neighbours its
vision model lets it see (range, blind spot, occlusion) at their bearing and elevation.
Recordings hold one snapshot per control period; frames in between are interpolated
(positions linearly, headings the short way round) so that motion looks smooth. GIF through
Pillow, MP4 through the ffmpeg that imageio-ffmpeg ships (both in the ``viz`` extra).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.vision import Vision, perceive
from fishswarm.study.progress import ids_text

FloatArray = NDArray[np.float64]

FORMATS = (".gif", ".mp4")
ARROW_LENGTH = 0.12
"""Length of a fish's arrow, m (about a body length)."""


class AnimationError(ValueError):
    """An animation cannot be made (format, missing tools, nothing to draw)."""


@dataclass(frozen=True)
class Frames:
    """The run resampled for animation.

    Attributes:
        t: (F,) frame times, s.
        position: (F, N, 3) positions, m.
        yaw: (F, N) headings, rad.
        ids: (N,) fish ids.
    """

    t: FloatArray
    position: FloatArray
    yaw: FloatArray
    ids: NDArray[np.int64]


def interpolate(
    t: FloatArray, position: FloatArray, yaw: FloatArray, ids: NDArray[np.int64], *, per_step: int
) -> Frames:
    """``per_step`` frames per recorded step: positions linearly, yaws the short way round.

    Args:
        t: (T,) snapshot times, s.
        position: (T, N, 3) positions, m (NaN for absent fish stays NaN).
        yaw: (T, N) yaws, rad.
        ids: (N,) fish ids.
        per_step: frames per snapshot interval (1: the snapshots only).
    """
    if per_step < 1:
        raise AnimationError(f"frames per step must be at least 1, got {per_step}")
    if t.size < 2 or per_step == 1:
        return Frames(t, position, yaw, ids)
    fraction = np.arange(per_step) / per_step
    turn = np.angle(np.exp(1j * (yaw[1:] - yaw[:-1])))
    times = (t[:-1, None] + (t[1:] - t[:-1])[:, None] * fraction).reshape(-1)
    moved = (
        position[:-1, None]
        + (position[1:] - position[:-1])[:, None] * fraction[None, :, None, None]
    )
    turned = yaw[:-1, None] + turn[:, None] * fraction[None, :, None]
    return Frames(
        np.append(times, t[-1]),
        np.concatenate([moved.reshape(-1, *position.shape[1:]), position[-1:]]),
        np.concatenate([turned.reshape(-1, yaw.shape[1]), yaw[-1:]]),
        ids,
    )


def eye_view(
    position: FloatArray, yaw: FloatArray, viewer: int, vision: Vision
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """What fish ``viewer`` sees: bearing (deg, positive right), elevation (deg, positive
    up) and distance (m) of each visible neighbour.

    Args:
        position: (N, 3) positions of the present fish, m.
        yaw: (N,) their yaws, rad.
        viewer: index of the seeing fish in these arrays.
        vision: the vision model.
    """
    seen = perceive(position, yaw, vision=vision)
    body = seen.neighbors[viewer][seen.mask[viewer]]
    distance = np.linalg.norm(body, axis=1)
    bearing = np.degrees(np.arctan2(body[:, 1], body[:, 0]))
    planar = np.hypot(body[:, 0], body[:, 1])
    elevation = np.degrees(np.arctan2(-body[:, 2], planar))  # z points down
    return bearing, elevation, distance


def animate(
    frames: Frames,
    *,
    tank: Sequence[float],
    vision: Vision,
    viewer: int,
    out: Path,
    fps: int = 10,
    title: str = "",
    on_frame: Callable[[int, int], None] | None = None,
) -> Path:
    """Write an animation of the run to ``out`` (.gif or .mp4).

    Args:
        frames: the run, resampled (see :func:`interpolate`).
        tank: tank size (x, y, z), m.
        vision: the vision model, for the fish's-eye view.
        viewer: id of the fish whose eyes the fourth view shows.
        out: file to write; its suffix picks the format.
        fps: frames per second of the animation.
        title: shown above the views.
        on_frame: called with (frame number, frames in all) as frames are drawn.

    Raises:
        AnimationError: unknown format, the viewer is not in the run, or a tool is missing.
    """
    if out.suffix not in FORMATS:
        raise AnimationError(f"the output must end in {' or '.join(FORMATS)}, got {out.name}")
    ids = frames.ids.tolist()
    if viewer not in ids:
        raise AnimationError(f"fish {viewer} is not in the recording (fish: {ids_text(ids)})")
    plt, animation = _matplotlib()
    writer = _writer(animation, out, fps)
    figure = plt.figure(figsize=(10, 7.5), dpi=80, layout="constrained")
    views = [figure.add_subplot(2, 2, n, projection="3d") for n in (1, 2, 3)]
    angles = (("from above", 90.0, -90.0), ("from the side", 0.0, -90.0), ("circling", 25.0, 0.0))
    for ax, (name, _, _) in zip(views, angles, strict=True):
        _tank_axes(ax, tank)
        ax.set_title(name, fontsize=9)
    eye = figure.add_subplot(2, 2, 4)
    _eye_axes(eye)
    column = ids.index(viewer)
    count = frames.t.size
    drawn: list[Any] = []

    def column_in(present: NDArray[np.bool_]) -> int | None:
        return int(present[:column].sum()) if present[column] else None

    def draw(frame: int) -> None:
        # Only the fish are redrawn; axes, panes and labels stay (redrawing them all was
        # most of the time per frame).
        for artist in drawn:
            artist.remove()
        drawn.clear()
        position, yaw = frames.position[frame], frames.yaw[frame]
        present = ~np.isnan(position[:, 0])
        mine = column_in(present)
        for ax, (_, elevation, azimuth) in zip(views, angles, strict=True):
            drawn.append(_arrows(ax, position[present], yaw[present], highlight=mine))
            turn = -60.0 + 360.0 * frame / max(count, 1) if ax is views[2] else azimuth
            ax.view_init(elev=elevation, azim=turn)
        drawn.extend(_eye(eye, position[present], yaw[present], mine, vision, viewer))
        figure.suptitle(f"{title}   t = {frames.t[frame]:5.1f} s")

    # Lay the views out once, then keep that layout: re-running constrained layout for
    # every frame took more time than drawing it.
    draw(0)
    figure.canvas.draw()
    figure.set_layout_engine("none")
    with writer.saving(figure, str(out), dpi=figure.dpi):
        for frame in range(count):
            draw(frame)
            writer.grab_frame()
            if on_frame is not None:
                on_frame(frame + 1, count)
    plt.close(figure)
    return out


def _tank_axes(ax: Any, tank: Sequence[float]) -> None:
    ax.set(xlim=(0, tank[0]), ylim=(0, tank[1]), zlim=(tank[2], 0))
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.set_zlabel("depth (m)", fontsize=8)
    ax.set_box_aspect(tank)
    ax.tick_params(labelsize=7)


def _arrows(ax: Any, position: FloatArray, yaw: FloatArray, *, highlight: int | None) -> Any:
    colors = ["tab:blue"] * position.shape[0]
    if highlight is not None:
        colors[highlight] = "tab:red"
    return ax.quiver(
        position[:, 0],
        position[:, 1],
        position[:, 2],
        np.cos(yaw),
        np.sin(yaw),
        np.zeros_like(yaw),
        length=ARROW_LENGTH,
        colors=colors,
        linewidth=1.5,
    )


def _eye_axes(ax: Any) -> None:
    ax.set(xlim=(-180, 180), ylim=(-90, 90), xlabel="bearing (deg, right +)")
    ax.set_ylabel("elevation (deg, up +)")
    ax.axvspan(-180, -90, color="0.92")
    ax.axvspan(90, 180, color="0.92")
    ax.axvline(0, color="0.6", linewidth=0.8)


def _eye(
    ax: Any,
    position: FloatArray,
    yaw: FloatArray,
    index: int | None,
    vision: Vision,
    viewer: int,
) -> list[Any]:
    if index is None:
        ax.set_title(f"fish {viewer}'s eyes: not in the tank now", fontsize=9)
        return []
    bearing, elevation, distance = eye_view(position, yaw, index, vision)
    size = 400 * (0.15 / np.maximum(distance, 0.05)) ** 2
    ax.set_title(
        f"through fish {viewer}'s eyes (red arrow): {bearing.size} neighbours seen\n"
        "dot size ~ 1/distance²; shaded: behind",
        fontsize=9,
    )
    return [ax.scatter(bearing, elevation, s=size, color="tab:blue", alpha=0.7)]


def _matplotlib() -> tuple[Any, Any]:
    try:
        import matplotlib
    except ImportError:
        raise AnimationError("animations need matplotlib: pip install -e '.[viz]'") from None
    matplotlib.use("Agg")
    import matplotlib.animation as animation
    import matplotlib.pyplot as plt

    return plt, animation


def _writer(animation: Any, out: Path, fps: int) -> Any:
    if out.suffix == ".gif":
        return animation.PillowWriter(fps=fps)
    try:
        import imageio_ffmpeg
    except ImportError:
        raise AnimationError(
            "MP4 needs ffmpeg: pip install -e '.[viz]' (brings imageio-ffmpeg), or write a .gif"
        ) from None
    import matplotlib

    matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
    return animation.FFMpegWriter(fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"])


def frames_per_step(fps: int, period: float, speed: float) -> int:
    """Frames per recorded step so that the animation plays ``speed`` times real time."""
    return max(1, math.ceil(fps * period / speed))
