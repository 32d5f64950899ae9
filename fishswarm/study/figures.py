"""Pictures of runs and experiments: tracks from above and from the side, metrics over time,
metrics against a swept parameter (matplotlib, the ``viz`` extra)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.study.experiment import METRIC_LABELS

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from fishswarm.study.experiment import Experiment, RunOutcome

FloatArray = NDArray[np.float64]


class FiguresUnavailable(RuntimeError):
    """matplotlib is not installed."""


def _pyplot() -> Any:
    try:
        import matplotlib
    except ImportError:
        raise FiguresUnavailable("pictures need matplotlib: pip install -e '.[viz]'") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_tracks(
    overhead: Axes, side: Axes, position: FloatArray, tank: Sequence[float], *, title: str = ""
) -> None:
    """Tracks of every fish seen from above (x, y) and from the side (x, depth).

    Args:
        overhead: axes for the view from above.
        side: axes for the side view (depth increases downwards, as in the tank).
        position: (T, N, 3) positions, m; NaN where a fish is absent.
        tank: tank size (x, y, z), m.
        title: title of the overhead view.
    """
    count = position.shape[1]
    colors = _colors(count)
    for fish in range(count):
        track = position[:, fish]
        overhead.plot(track[:, 0], track[:, 1], color=colors[fish], linewidth=0.8)
        side.plot(track[:, 0], track[:, 2], color=colors[fish], linewidth=0.8)
        start, end = _first_last(track)
        if start is not None and end is not None:
            overhead.plot(*start[:2], "o", color=colors[fish], markersize=2)
            overhead.plot(*end[:2], ">", color=colors[fish], markersize=3)
            side.plot(start[0], start[2], "o", color=colors[fish], markersize=2)
    overhead.set(xlim=(0, tank[0]), ylim=(0, tank[1]), aspect="equal", xlabel="x (m)")
    overhead.set_ylabel("y (m)")
    overhead.set_title(title, fontsize=9)
    side.set(xlim=(0, tank[0]), ylim=(tank[2], 0), aspect="equal", xlabel="x (m)")
    side.set_ylabel("depth (m)")


def _colors(count: int) -> list[Any]:
    plt = _pyplot()
    cmap = plt.get_cmap("viridis")
    return [cmap(n / max(count - 1, 1)) for n in range(count)]


def _first_last(track: FloatArray) -> tuple[FloatArray | None, FloatArray | None]:
    present = np.flatnonzero(~np.isnan(track[:, 0]))
    if present.size == 0:
        return None, None
    return track[present[0]], track[present[-1]]


def run_figure(
    t: FloatArray,
    position: FloatArray,
    metrics: dict[str, FloatArray],
    tank: Sequence[float],
    *,
    title: str,
) -> Figure:
    """One run: tracks from above and from the side, and every metric over time."""
    plt = _pyplot()
    figure = plt.figure(figsize=(12, 7), layout="constrained")
    grid = figure.add_gridspec(2, 2, width_ratios=(1.3, 1))
    overhead = figure.add_subplot(grid[0, 0])
    side = figure.add_subplot(grid[1, 0])
    draw_tracks(overhead, side, position, tank, title="from above")
    side.set_title("from the side", fontsize=9)
    distances = figure.add_subplot(grid[0, 1])
    for name in ("centroid_distance", "pairwise_distance", "nearest_neighbor_distance"):
        distances.plot(t, metrics[name], label=METRIC_LABELS[name])
    distances.set(xlabel="time (s)", ylabel="m")
    distances.legend(fontsize=8)
    seen = figure.add_subplot(grid[1, 1])
    seen.plot(t, metrics["neighbors_seen"], color="tab:purple")
    seen.set(xlabel="time (s)", ylabel=METRIC_LABELS["neighbors_seen"])
    figure.suptitle(title)
    result: Figure = figure
    return result


def experiment_figures(
    experiment: Experiment,
    outcomes: list[RunOutcome],
    rows: list[dict[str, Any]],
    folder: Path,
) -> list[Path]:
    """Write the experiment's pictures into ``folder``; returns their paths.

    - ``metrics_vs_parameter.png``: each column of the experiment's table (``rows``, from
      :func:`fishswarm.study.experiment.table_rows`) against the parameter, mean ± s.d. over seeds.
    - ``metrics_over_time.png``: each metric over time, one line per value (mean, band ± s.d.).
    - ``tracks.png``: the first seed's tracks for every value, from above and from the side.
    """
    plt = _pyplot()
    values = experiment.values
    positions = np.arange(len(values))
    names = experiment.metric_names
    paths = []

    summaries = experiment.summaries
    figure, axes = plt.subplots(
        1, len(summaries), figsize=(3.4 * len(summaries), 3.6), layout="constrained"
    )
    for ax, summary in zip(axes, summaries, strict=True):
        means = [row[f"{summary.key}_mean"] for row in rows]
        errors = [row[f"{summary.key}_sd"] for row in rows]
        ax.errorbar(positions, means, yerr=errors, fmt="o-", capsize=4)
        ax.set_xticks(positions, [f"{v:g}" for v in values])
        ax.set_xlabel(experiment.label)
        ax.set_title(summary.label, fontsize=9)
        ax.grid(alpha=0.3)
    figure.suptitle(f"{experiment.title}: mean ± s.d. over {experiment.seeds} seeds")
    paths.append(_save(figure, folder / "metrics_vs_parameter.png"))

    figure, axes = plt.subplots(
        1, len(names), figsize=(3.8 * len(names), 3.6), layout="constrained"
    )
    colors = _colors(len(values))
    for ax, (column, name) in zip(axes, enumerate(names), strict=True):
        for color, value in zip(colors, values, strict=True):
            mine = [o for o in outcomes if o.value == value]
            stacked = np.array([o.metrics[:, column] for o in mine])
            mean, sd = stacked.mean(axis=0), stacked.std(axis=0)
            ax.plot(mine[0].t, mean, color=color, label=f"{value:g}")
            ax.fill_between(mine[0].t, mean - sd, mean + sd, color=color, alpha=0.15)
        ax.set(xlabel="time (s)")
        ax.set_title(METRIC_LABELS[name], fontsize=9)
    axes[0].legend(title=experiment.label, fontsize=7, title_fontsize=7)
    figure.suptitle(f"{experiment.title}: metrics over time")
    paths.append(_save(figure, folder / "metrics_over_time.png"))

    tank = experiment.scenario.tank
    figure, axes = plt.subplots(
        2, len(values), figsize=(3.2 * len(values), 5.2), layout="constrained", squeeze=False
    )
    for column, value in enumerate(values):
        first = min((o for o in outcomes if o.value == value), key=lambda o: o.seed)
        draw_tracks(
            axes[0, column],
            axes[1, column],
            first.position,
            tank,
            title=f"{experiment.label.split(' (')[0]} = {value:g}, seed {first.seed}",
        )
        for landmark in experiment.scenario_for(value, first.seed).landmarks():
            axes[0, column].plot(landmark[0], landmark[1], "+", color="red", markersize=8)
            axes[1, column].plot(landmark[0], landmark[2], "+", color="red", markersize=8)
    figure.suptitle(f"{experiment.title}: tracks from above and from the side")
    paths.append(_save(figure, folder / "tracks.png"))
    return paths


def _save(figure: Figure, path: Path) -> Path:
    plt = _pyplot()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
