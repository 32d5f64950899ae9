"""Pictures of runs and experiments: tracks from above and from the side, metrics over time,
metrics against a swept parameter (matplotlib, the ``viz`` extra)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.study.experiment import METRIC_LABELS
from fishswarm.study.metrics import FormationTarget, OrbitTarget, orbit_target_of
from fishswarm.study.scene import ROLE_RGB, role_names

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
            overhead.plot(*start[:2], "o", color=colors[fish], markersize=3)
            overhead.plot(*end[:2], marker=_arrowhead(track), color=colors[fish], markersize=6)
            side.plot(start[0], start[2], "o", color=colors[fish], markersize=3)
    if count:
        key = [
            _key_entry("o", "start", markersize=4),
            _key_entry((3, 0, -90), "end, pointing where it swam", markersize=7),
        ]
        overhead.legend(handles=key, fontsize=7, loc="upper right", framealpha=0.8)
    # Seen from above, the tank frame (z down, right-handed) has y pointing down the page.
    overhead.set(xlim=(0, tank[0]), ylim=(tank[1], 0), aspect="equal", xlabel="x (m)")
    overhead.set_ylabel("y (m)")
    overhead.set_title(title, fontsize=9)
    side.set(xlim=(0, tank[0]), ylim=(tank[2], 0), aspect="equal", xlabel="x (m)")
    side.set_ylabel("depth (m)")


def _arrowhead(track: FloatArray) -> tuple[int, int, float]:
    """A triangle marker pointing along a track's last move seen from above (matplotlib's
    (sides, style, angle): a triangle at angle 0 points up the page, angles turn it
    anticlockwise on the page; the view from above has y down the page, so a heading
    turned towards +y turns the marker clockwise)."""
    present = track[~np.isnan(track[:, 0])]
    step = present[-1, :2] - present[-2, :2] if present.shape[0] > 1 else np.array([1.0, 0.0])
    heading_deg = float(np.degrees(np.arctan2(step[1], step[0])))
    return (3, 0, -heading_deg - 90.0)


def _key_entry(marker: Any, label: str, *, markersize: float) -> Any:
    """A legend entry for a marker drawn in every fish's colour (shown in grey)."""
    from matplotlib.lines import Line2D

    return Line2D(
        [], [], marker=marker, linestyle="none", color="dimgrey", markersize=markersize, label=label
    )


def _colors(count: int) -> list[Any]:
    plt = _pyplot()
    cmap = plt.get_cmap("viridis")
    return [cmap(n / max(count - 1, 1)) for n in range(count)]


def _first_last(track: FloatArray) -> tuple[FloatArray | None, FloatArray | None]:
    present = np.flatnonzero(~np.isnan(track[:, 0]))
    if present.size == 0:
        return None, None
    return track[present[0]], track[present[-1]]


def figure_of_run(
    t: FloatArray,
    position: FloatArray,
    metrics: dict[str, FloatArray],
    tank: Sequence[float],
    *,
    title: str,
    orbit: OrbitTarget | None = None,
    formation: FormationTarget | None = None,
    switches: Sequence[tuple[float, str]] = (),
) -> Figure:
    """One run: tracks from above and from the side, and every metric over time (for
    circling fish, given ``orbit``: the post and R drawn, radius, revolutions and speed;
    for a formation, given ``formation``: the fish at the end coloured by role and joined
    state, the target laid onto them, shape error, joined fraction and collisions, each
    switch of shape — (time s, the new shape) in ``switches`` — marked over time)."""
    plt = _pyplot()
    figure = plt.figure(figsize=(12, 7), layout="constrained")
    if orbit is not None or formation is not None:
        if orbit is not None:
            _orbit_panels(figure, t, position, metrics, tank, orbit)
        elif formation is not None:
            _formation_panels(figure, t, position, metrics, tank, formation, switches)
        figure.suptitle(title)
        special: Figure = figure
        return special
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


def _orbit_panels(
    figure: Figure,
    t: FloatArray,
    position: FloatArray,
    metrics: dict[str, FloatArray],
    tank: Sequence[float],
    orbit: OrbitTarget,
) -> None:
    grid = figure.add_gridspec(3, 2, width_ratios=(1.3, 1))
    overhead = figure.add_subplot(grid[0:2, 0])
    side = figure.add_subplot(grid[2, 0])
    draw_tracks(overhead, side, position, tank, title="from above")
    side.set_title("from the side", fontsize=9)
    reference = orbit.expected_radius
    if orbit.centre is not None:
        from matplotlib.patches import Circle

        x, y, z = orbit.centre
        overhead.plot(x, y, "+", color="red", markersize=10, label="post")
        overhead.add_patch(
            Circle((x, y), reference, fill=False, linestyle="--", color="red", linewidth=0.8)
        )
        side.plot(x, z, "+", color="red", markersize=10)
    radius = figure.add_subplot(grid[0, 1])
    radius.plot(t, metrics["radius"], color="tab:blue", label="measured")
    radius.axhline(reference, color="red", linestyle="--", linewidth=0.8, label=orbit.label)
    radius.set(xlabel="time (s)", ylabel=METRIC_LABELS["radius"])
    radius.legend(fontsize=8, loc="best")
    turns = figure.add_subplot(grid[1, 1])
    turns.plot(t, metrics["revolutions"], color="tab:green")
    turns.set(xlabel="time (s)", ylabel=METRIC_LABELS["revolutions"])
    speed = figure.add_subplot(grid[2, 1])
    speed.plot(t, metrics["speed"], color="tab:orange")
    speed.set(xlabel="time (s)", ylabel=METRIC_LABELS["speed"])


ROLE_COLOURS: dict[str, tuple[float, float, float]] = {
    role: (ROLE_RGB[role][0] / 255, ROLE_RGB[role][1] / 255, ROLE_RGB[role][2] / 255)
    for role in ("joined", "seeking", "leader")
}
"""How fish in a formation are coloured: in their place, still seeking one, the leader (the
live view's colours, :data:`~fishswarm.study.scene.ROLE_RGB`)."""


def role_colours(
    joined: NDArray[np.bool_], leader: NDArray[np.bool_]
) -> list[tuple[float, float, float]]:
    """Each fish's colour by its role in a formation (:data:`ROLE_COLOURS`)."""
    return [ROLE_COLOURS[role] for role in role_names(joined, leader)]


def role_key(*, leader: bool = True) -> list[Any]:
    """Legend entries of the role colours (without the leader's for a local shape)."""
    from matplotlib.lines import Line2D

    return [
        Line2D([], [], marker="o", linestyle="none", color=colour, label=role)
        for role, colour in ROLE_COLOURS.items()
        if leader or role != "leader"
    ]


def draw_formation(
    overhead: Axes, side: Axes, position: FloatArray, formation: FormationTarget
) -> list[Any]:
    """The fish of one moment (N, 3) coloured by role, and the target's slots laid onto
    them (hollow circles), from above and from the side; returns the artists drawn."""
    here = position[~np.isnan(position[:, 0])]
    roles = formation.roles(here)
    colours = role_colours(roles.joined, roles.leader)
    drawn: list[Any] = []
    if roles.slots is not None:
        for ax, (a, b) in ((overhead, (0, 1)), (side, (0, 2))):
            drawn.append(
                ax.scatter(
                    roles.slots[:, a], roles.slots[:, b], s=60, facecolors="none",
                    edgecolors="black", linewidths=0.8, zorder=3,
                )
            )  # fmt: skip
    for ax, (a, b) in ((overhead, (0, 1)), (side, (0, 2))):
        drawn.extend(draw_edges(ax, here, roles.edges, (a, b)))
        drawn.append(ax.scatter(here[:, a], here[:, b], s=22, c=colours, zorder=4))
    return drawn


def draw_edges(
    ax: Axes, position: FloatArray, edges: NDArray[np.intp], axes: tuple[int, int]
) -> list[Any]:
    """The edges of completed local shapes (pairs of fish, (E, 2)) as thin lines between
    the fish (N, 3), in the plane of two coordinates; returns the artists drawn."""
    if edges.shape[0] == 0:
        return []
    from matplotlib.collections import LineCollection

    segments = position[edges][:, :, list(axes)]
    lines = LineCollection(list(segments), colors=ROLE_COLOURS["joined"], linewidths=0.8, zorder=3)
    ax.add_collection(lines)
    return [lines]


def _formation_panels(
    figure: Figure,
    t: FloatArray,
    position: FloatArray,
    metrics: dict[str, FloatArray],
    tank: Sequence[float],
    formation: FormationTarget,
    switches: Sequence[tuple[float, str]],
) -> None:
    from matplotlib.lines import Line2D

    grid = figure.add_gridspec(3, 2, width_ratios=(1.3, 1))
    overhead = figure.add_subplot(grid[0:2, 0])
    side = figure.add_subplot(grid[2, 0])
    draw_tracks(overhead, side, position, tank, title="from above; the fish at the end")
    side.set_title("from the side", fontsize=9)
    draw_formation(overhead, side, position[-1], formation)
    key = [
        _key_entry("o", "start", markersize=4),
        *role_key(leader=formation.slots is not None),
    ]
    if formation.slots is not None:
        key.append(
            Line2D([], [], marker="o", linestyle="none", markerfacecolor="none",
                   markeredgecolor="black", label="target, best fit")
        )  # fmt: skip
    else:
        key.append(Line2D([], [], color=ROLE_COLOURS["joined"], label="shape completed"))
    overhead.legend(handles=key, fontsize=7, loc="best", framealpha=0.8)
    error = figure.add_subplot(grid[0, 1])
    error.plot(t, metrics["shape_error"], color="tab:blue")
    error.axhline(formation.tolerance, color="red", linestyle="--", linewidth=0.8,
                  label="tolerance")  # fmt: skip
    error.set(xlabel="time (s)", ylabel=METRIC_LABELS["shape_error"])
    error.legend(fontsize=8)
    joined = figure.add_subplot(grid[1, 1])
    joined.plot(t, 100 * metrics["joined_fraction"], color="tab:green")
    joined.axhline(90, color="grey", linestyle=":", linewidth=0.8)
    joined.set(xlabel="time (s)", ylabel="in their places (%)", ylim=(-2, 102))
    crowded = figure.add_subplot(grid[2, 1])
    crowded.plot(t, metrics["collisions"], color="tab:red")
    crowded.set(xlabel="time (s)", ylabel=METRIC_LABELS["collisions"])
    # The metrics jump where the fish were told another shape: mark where, and which.
    for time, shape in switches:
        for over_time in (error, joined, crowded):
            over_time.axvline(time, color="dimgrey", linestyle="-.", linewidth=0.8)
        error.annotate(
            f"→ {shape}", (time, 1.0), xycoords=("data", "axes fraction"),
            xytext=(3, -3), textcoords="offset points", va="top", fontsize=8, color="dimgrey",
            bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85, "pad": 1},
        )  # fmt: skip


CROWDED_GAPS = 10.0
"""Swept values whose widest gap is this many times their narrowest or more are drawn on a
scale linear near zero and logarithmic beyond (the study's blind spots, 0, 0.05, 0.25 and
2.517 m: on a linear axis 0 and 0.05 wrote their labels over each other)."""


def parameter_axis(ax: Any, values: Sequence[float]) -> None:
    """Lay out an axis of swept ``values``: each value a tick labelled with it, drawn where
    it is; values bunched near zero spread out on a symmetric-log scale, linear up to the
    smallest value other than zero; many labels turned so that they do not overlap."""
    ordered = sorted(set(values))
    gaps = np.diff(ordered)
    nonzero = [abs(v) for v in ordered if v != 0]
    if len(ordered) > 2 and gaps.min() > 0 and gaps.max() >= CROWDED_GAPS * gaps.min() and nonzero:
        ax.set_xscale("symlog", linthresh=min(nonzero), linscale=0.5)
        ax.minorticks_off()
    turned = len(ordered) > 3
    ax.set_xticks(
        ordered, [f"{v:g}" for v in ordered], rotation=40 if turned else 0,
        ha="right" if turned else "center",
    )  # fmt: skip


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
    names = experiment.metric_names
    spread = experiment.seeds > 1
    # The radius each value should give (orbit experiments), drawn as a reference.
    orbits = [orbit_target_of(experiment.scenario_for(value, 0)) for value in values]
    known = [orbit for orbit in orbits if orbit is not None]
    expected = [o.expected_radius for o in known] if len(known) == len(values) else None
    if expected is None:
        reference = ""
    elif len(set(expected)) == 1:
        reference = known[0].label
    else:
        reference = "target radius R" + ("" if known[0].centre is not None else "/2")
    paths = []

    summaries = experiment.summaries
    figure, axes = _panels(len(summaries), width=3.4)
    groups = experiment.group_names
    for ax, summary in zip(axes, summaries, strict=True):
        for group in groups:
            group_rows = [row for row in rows if row.get("group", "") == group]
            means = [row[f"{summary.key}_mean"] for row in group_rows]
            errors = [row[f"{summary.key}_sd"] for row in group_rows] if spread else None
            # At the values themselves: unevenly spaced values are drawn unevenly spaced.
            ax.errorbar(
                [row[experiment.parameter] for row in group_rows], means, yerr=errors, fmt="o-",
                capsize=4, label=group or "measured",
            )  # fmt: skip
        if summary.key == "radius" and expected is not None:
            ax.plot(values, expected, "--", color="red", linewidth=0.8, label=reference)
        if (summary.key == "radius" and expected is not None) or len(groups) > 1:
            ax.legend(fontsize=7)
        parameter_axis(ax, values)
        ax.set_xlabel(experiment.label)
        ax.set_title(summary.label, fontsize=9)
        ax.grid(alpha=0.3)
    figure.suptitle(f"{experiment.title}: {experiment.spread_text}")
    paths.append(_save(figure, folder / "metrics_vs_parameter.png"))

    figure, axes = _panels(len(names), width=3.8)
    colors = _colors(len(values))
    styles = ("-", "--", ":", "-.")
    for ax, (column, name) in zip(axes, enumerate(names), strict=True):
        for (style, group), (color, value) in itertools.product(
            zip(itertools.cycle(styles), groups), zip(colors, values, strict=True)
        ):
            mine = [o for o in outcomes if o.value == value and o.group == group]
            if not mine:
                continue
            stacked = np.array([o.metrics[:, column] for o in mine])
            mean, sd = stacked.mean(axis=0), stacked.std(axis=0)
            label = f"{group}, {value:g}" if group else f"{value:g}"
            ax.plot(mine[0].t, mean, color=color, linestyle=style, label=label)
            if spread:
                ax.fill_between(mine[0].t, mean - sd, mean + sd, color=color, alpha=0.15)
        if name == "radius" and expected is not None:
            for color, radius in zip(colors, expected, strict=True):
                ax.axhline(radius, color=color, linestyle="--", linewidth=0.8)
            ax.plot([], [], "--", color="grey", linewidth=0.8, label=reference)
        ax.set(xlabel="time (s)")
        ax.set_title(METRIC_LABELS[name], fontsize=9)
    # Beside the panels, not over the data.
    figure.legend(
        *axes[0].get_legend_handles_labels(),
        loc="outside right upper",
        title=experiment.label,
        fontsize=7,
        title_fontsize=7,
    )
    band = ", band ± s.d. over seeds" if spread else ", one seed per value"
    figure.suptitle(f"{experiment.title}: metrics over time (mean{band})")
    paths.append(_save(figure, folder / "metrics_over_time.png"))

    tank = experiment.scenario.tank
    shown = [
        (group, value)
        for group, value in itertools.product(groups, values)
        if any(o.value == value and o.group == group for o in outcomes)
    ]
    figure, axes = plt.subplots(
        2, len(shown), figsize=(3.2 * len(shown), 5.2), layout="constrained", squeeze=False
    )
    for column, (group, value) in enumerate(shown):
        first = min(
            (o for o in outcomes if o.value == value and o.group == group), key=lambda o: o.seed
        )
        title = f"{experiment.label.split(' (')[0]} = {value:g}, seed {first.seed}"
        draw_tracks(
            axes[0, column],
            axes[1, column],
            first.position,
            tank,
            title=f"{group}: {title}" if group else title,
        )
        for landmark in experiment.scenario_for(value, first.seed, group).landmarks():
            axes[0, column].plot(landmark[0], landmark[1], "+", color="red", markersize=8)
            axes[1, column].plot(landmark[0], landmark[2], "+", color="red", markersize=8)
    figure.suptitle(f"{experiment.title}: tracks from above and from the side")
    paths.append(_save(figure, folder / "tracks.png"))
    return paths


PANELS_PER_ROW = 5
"""More panels than this wrap onto further rows (a formation's table has ten columns)."""


def _panels(count: int, *, width: float) -> tuple[Figure, list[Any]]:
    """A figure of ``count`` panels, each ``width`` inches wide, in rows of at most
    :data:`PANELS_PER_ROW`; the unused places of the last row left empty."""
    plt = _pyplot()
    columns = min(count, PANELS_PER_ROW)
    rows = -(-count // columns)
    figure, axes = plt.subplots(
        rows, columns, figsize=(width * columns, 3.6 * rows), layout="constrained",
        squeeze=False,
    )  # fmt: skip
    places = list(axes.flat)
    for empty in places[count:]:
        empty.set_visible(False)
    return figure, places[:count]


def _save(figure: Figure, path: Path) -> Path:
    plt = _pyplot()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
