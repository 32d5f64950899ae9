"""Animations of recorded runs: the fish as arrows in the tank, and what one fish sees.

The study's BlueAnimat, redone: four views — from above and from the side (flat), a camera
circling the tank (3-D), and through the eyes of one fish, which shows only the neighbours its
vision model lets it see (range, blind spot, occlusion) at their bearing and elevation.
Recordings hold one snapshot per control period; frames are taken at even steps of
simulated time between them (positions linearly, headings the short way round), one step
being the playing speed times how long a frame is really shown, so that the animation plays
at the speed asked for. GIF through
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
from fishswarm.study.figures import ROLE_COLOURS, draw_edges, role_colours, role_key
from fishswarm.study.metrics import FormationTarget
from fishswarm.study.progress import ids_text

FloatArray = NDArray[np.float64]

FORMATS = (".gif", ".mp4")
ARROW_LENGTH = 0.12
"""Length of a fish's arrow, m (about a body length)."""


class AnimationError(ValueError):
    """An animation cannot be made (format, missing tools, nothing to draw)."""


class AnimationUnavailable(AnimationError):
    """A package the animation needs is not installed (the message says which)."""


class AnimationInterrupted(KeyboardInterrupt):
    """Ctrl-C while the frames were written: the file holds those written (the GIF writer
    and ffmpeg close it as they stop)."""

    def __init__(self, written: int, total: int) -> None:
        super().__init__(f"interrupted after {written} of {total} frames")
        self.written = written
        self.total = total


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


def resample(
    t: FloatArray, position: FloatArray, yaw: FloatArray, ids: NDArray[np.int64], *, step: float
) -> Frames:
    """Frames every ``step`` simulated seconds from the first snapshot to the last:
    positions linearly between snapshots, yaws the short way round.

    Args:
        t: (T,) snapshot times, s, increasing.
        position: (T, N, 3) positions, m (NaN for absent fish stays NaN).
        yaw: (T, N) yaws, rad.
        ids: (N,) fish ids.
        step: simulated time between frames, s (the playing speed × a frame's duration).
    """
    if not step > 0:
        raise AnimationError(f"the time between frames must be positive, got {step}")
    if t.size < 2:
        return Frames(t, position, yaw, ids)
    count = math.floor((t[-1] - t[0]) / step + 1e-9) + 1
    times = t[0] + np.arange(count) * step
    before = np.clip(np.searchsorted(t, times, side="right") - 1, 0, t.size - 2)
    fraction = (times - t[before]) / (t[before + 1] - t[before])
    moved = position[before] + (position[before + 1] - position[before]) * fraction[:, None, None]
    turn = np.angle(np.exp(1j * (yaw[before + 1] - yaw[before])))
    return Frames(times, moved, yaw[before] + turn * fraction[:, None], ids)


def frame_duration(suffix: str, fps: int) -> float:
    """How long each frame is shown, s: 1/fps, but a GIF counts whole hundredths of a second
    (after matplotlib's writer truncates to whole milliseconds), so 15 fps plays 0.06 s
    frames there; the frames are spaced in simulated time by what is really shown.

    Raises:
        AnimationError: fps outside 1–50 for a GIF (viewers show shorter frames at 0.1 s).
    """
    if fps < 1:
        raise AnimationError(f"fps must be at least 1, got {fps}")
    if suffix == ".gif":
        if fps > 50:
            raise AnimationError(
                f"a GIF plays at most 50 frames per second (viewers slow shorter frames down "
                f"to 0.1 s), got --fps {fps}; use .mp4 or a lower --fps"
            )
        return (int(1000 / fps) // 10) / 100
    return 1 / fps


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
    formation: FormationTarget | None = None,
    switches: Sequence[tuple[float, FormationTarget]] = (),
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
        formation: the target of a formation run: fish coloured by role and joined state,
            the target laid onto them in the flat views.
        switches: (time, target) of each switch to another shape: from ``time``, s, the
            fish are coloured by, and laid onto, that target.

    Raises:
        AnimationError: unknown format, the viewer is not in the run, or a tool is missing.
        AnimationInterrupted: Ctrl-C while the frames were written.
    """
    if out.suffix not in FORMATS:
        raise AnimationError(f"the output must end in {' or '.join(FORMATS)}, got {out.name}")
    ids = frames.ids.tolist()
    if viewer not in ids:
        raise AnimationError(f"fish {viewer} is not in the recording (fish: {ids_text(ids)})")
    plt, animation = _matplotlib()
    writer = _writer(animation, out, fps)
    figure, draw = animation_figure(
        frames, tank=tank, vision=vision, viewer=viewer, title=title, formation=formation,
        switches=switches,
    )  # fmt: skip
    count = frames.t.size
    written = 0
    interrupted = False
    try:
        with writer.saving(figure, str(out), dpi=figure.dpi):
            try:
                for frame in range(count):
                    draw(frame)
                    writer.grab_frame()
                    written = frame + 1
                    if on_frame is not None:
                        on_frame(written, count)
            except KeyboardInterrupt:
                interrupted = True
                raise
    except KeyboardInterrupt:
        raise AnimationInterrupted(written, count) from None
    except Exception:
        # ffmpeg, in Ctrl-C's process group, has stopped too, and the writer, closing the
        # file, fails on its exit status instead.
        if interrupted:
            raise AnimationInterrupted(written, count) from None
        raise
    finally:
        plt.close(figure)
    return out


def animation_figure(
    frames: Frames,
    *,
    tank: Sequence[float],
    vision: Vision,
    viewer: int,
    title: str = "",
    formation: FormationTarget | None = None,
    switches: Sequence[tuple[float, FormationTarget]] = (),
) -> tuple[Any, Callable[[int], None]]:
    """The animation's figure and a function that draws frame k into it (``formation`` and
    ``switches`` as in :func:`animate`).

    Four views: from above and from the side (flat, so that their axes read like a plan and
    an elevation), a camera circling the tank (3-D), and through the eyes of fish ``viewer``
    (drawn red in the other views). A formation's fish are coloured by role and joined state
    (:data:`fishswarm.study.figures.ROLE_COLOURS`), its target drawn as hollow circles.
    """
    plt, _ = _matplotlib()
    ids = frames.ids.tolist()
    figure = plt.figure(figsize=(12, 9), dpi=80, layout="constrained")
    grid = figure.add_gridspec(2, 2, height_ratios=(tank[1], max(tank[2], 0.6 * tank[1])))
    above = figure.add_subplot(grid[0, 0])
    # Seen from above, the tank frame (z down, right-handed) has y pointing down the page.
    above.set(xlim=(0, tank[0]), ylim=(tank[1], 0), aspect="equal", xlabel="x (m)")
    above.set_ylabel("y (m)")
    above.set_title("from above", fontsize=10)
    side = figure.add_subplot(grid[1, 0])
    side.set(xlim=(0, tank[0]), ylim=(tank[2], 0), aspect="equal", xlabel="x (m)")
    side.set_ylabel("depth (m)")
    side.set_title("from the side", fontsize=10)
    circling = figure.add_subplot(grid[0, 1], projection="3d")
    _tank_axes(circling, tank)
    circling.set_title("circling", fontsize=10)
    eye = figure.add_subplot(grid[1, 1])
    _eye_axes(eye)
    if formation is not None:
        key = role_key(leader=formation.slots is not None)
        if formation.slots is None:
            from matplotlib.lines import Line2D

            key.append(Line2D([], [], color=ROLE_COLOURS["joined"], label="shape completed"))
        above.legend(handles=key, fontsize=7, loc="lower right", framealpha=0.8)
    column = ids.index(viewer)
    count = frames.t.size
    drawn: list[Any] = []

    def draw(frame: int) -> None:
        # Only the fish are redrawn; axes, panes and labels stay (redrawing them all was
        # most of the time per frame).
        for artist in drawn:
            artist.remove()
        drawn.clear()
        position, yaw = frames.position[frame], frames.yaw[frame]
        present = ~np.isnan(position[:, 0])
        mine = int(present[:column].sum()) if present[column] else None
        here, heading = position[present], yaw[present]
        colours: list[Any] = _colours(here.shape[0])
        target = formation
        for since, switched in switches:
            if frames.t[frame] >= since:
                target = switched
        if target is not None:
            roles = target.roles(here)
            colours = role_colours(roles.joined, roles.leader)
            if roles.slots is not None:
                drawn.append(_hollow(above, roles.slots[:, 0], roles.slots[:, 1]))
                drawn.append(_hollow(side, roles.slots[:, 0], roles.slots[:, 2]))
            drawn.extend(draw_edges(above, here, roles.edges, (0, 1)))
            drawn.extend(draw_edges(side, here, roles.edges, (0, 2)))
        if mine is not None:
            colours[mine] = "tab:red"
        drawn.append(_flat_arrows(above, here[:, 0], here[:, 1], heading, colours))
        # From the side (looking along +y) a fish shows how far it swims along x.
        drawn.append(_flat_arrows(side, here[:, 0], here[:, 2], heading, colours, side=True))
        drawn.append(_arrows(circling, here, heading, colours=colours))
        circling.view_init(elev=25.0, azim=-60.0 + 360.0 * frame / max(count, 1))
        drawn.extend(_eye(eye, here, heading, mine, vision, viewer))
        figure.suptitle(f"{title}   t = {frames.t[frame]:5.1f} s")

    # Lay the views out once, then keep that layout: re-running constrained layout for
    # every frame took more time than drawing it.
    draw(0)
    figure.canvas.draw()
    figure.set_layout_engine("none")
    return figure, draw


def _tank_axes(ax: Any, tank: Sequence[float]) -> None:
    # Depth drawn downwards, and y turned with it: a rotation of the tank frame, not a
    # mirror image of it.
    ax.set(xlim=(0, tank[0]), ylim=(tank[1], 0), zlim=(tank[2], 0))
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.set_zlabel("depth (m)", fontsize=8)
    ax.set_box_aspect(tank, zoom=1.15)
    # Three ticks an axis: more pile up on the short depth axis as the camera turns.
    for axis, size in zip((ax.xaxis, ax.yaxis, ax.zaxis), tank, strict=True):
        axis.set_ticks(np.linspace(0, size, 3).round(2))
    ax.tick_params(labelsize=7, pad=0)


def _colours(count: int) -> list[str]:
    return ["tab:blue"] * count


def _flat_arrows(
    ax: Any,
    x: FloatArray,
    y: FloatArray,
    yaw: FloatArray,
    colours: list[str],
    *,
    side: bool = False,
) -> Any:
    """Each fish as an arrow one body length long (in the axes' metres) along its heading
    as this view shows it: from the side, only its x component."""
    u = np.cos(yaw) * ARROW_LENGTH
    v = np.zeros_like(yaw) if side else np.sin(yaw) * ARROW_LENGTH
    return ax.quiver(
        x,
        y,
        u,
        v,
        color=colours,
        angles="xy",
        scale_units="xy",
        scale=1.0,
        width=0.006,
        headwidth=3.5,
        headlength=4.0,
        pivot="middle",
    )


def _hollow(ax: Any, x: FloatArray, y: FloatArray) -> Any:
    """A formation's target slots as hollow circles."""
    return ax.scatter(x, y, s=50, facecolors="none", edgecolors="black", linewidths=0.7)


def _arrows(ax: Any, position: FloatArray, yaw: FloatArray, *, colours: list[str]) -> Any:
    return ax.quiver(
        position[:, 0],
        position[:, 1],
        position[:, 2],
        np.cos(yaw),
        np.sin(yaw),
        np.zeros_like(yaw),
        length=1.5 * ARROW_LENGTH,  # the 3-D view is the smallest: a little longer
        colors=colours,
        linewidth=2.0,
        arrow_length_ratio=0.45,
        normalize=True,
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
        raise AnimationUnavailable("animations need matplotlib: pip install -e '.[viz]'") from None
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
        raise AnimationUnavailable(
            "MP4 needs ffmpeg: pip install -e '.[viz]' (brings imageio-ffmpeg), or write a .gif"
        ) from None
    import matplotlib

    matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
    return animation.FFMpegWriter(fps=fps, codec="libx264", extra_args=["-pix_fmt", "yuv420p"])
