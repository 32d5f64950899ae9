"""Pictures read back from the figure objects: axis labels with units, keys, the reference
radius, parameter values spaced as they are, and what one seed can and cannot show."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fishswarm.sim.scenario import Scenario
from fishswarm.study.experiment import Experiment
from fishswarm.study.metrics import OrbitTarget
from fishswarm.study.report import markdown_table, table_rows
from fishswarm.study.sweep import sweep_experiment

pytest.importorskip("matplotlib")

from fishswarm.study.figures import experiment_figures, figure_of_run


def _circle(steps: int = 9) -> np.ndarray:
    """A fish going clockwise (seen from above) round (0.9, 0.9) at 0.45 m, 1/8 turn a step."""
    angle = -np.arange(steps) * math.pi / 4
    return np.stack(
        [0.9 + 0.45 * np.cos(angle), 0.9 + 0.45 * np.sin(angle), np.full(steps, 0.5)], -1
    )[:, None]


def _labels(ax: Any) -> tuple[str, str]:
    return ax.get_xlabel(), ax.get_ylabel()


def test_an_orbit_runs_figure_shows_the_post_the_radius_and_the_circling() -> None:
    position = _circle()
    t = np.arange(9.0)
    metrics = {
        "radius": np.full(9, 0.45),
        "revolutions": np.arange(9) / 8,
        "speed": np.full(9, 0.34),
        "neighbors_seen": np.zeros(9),
    }
    target = OrbitTarget(np.array([0.9, 0.9, 0.5]), 0.45)
    figure = figure_of_run(t, position, metrics, (1.78, 1.78, 1.17), title="orbit", orbit=target)
    axes: list[Any] = figure.axes
    above, side, radius, turns, speed = axes
    assert _labels(above) == ("x (m)", "y (m)")
    assert _labels(side) == ("x (m)", "depth (m)")
    assert _labels(radius) == ("time (s)", "radius (m)")
    assert _labels(turns) == ("time (s)", "revolutions")
    assert _labels(speed) == ("time (s)", "speed (m/s)")
    # The reference line at R, in the key.
    reference = [line for line in radius.get_lines() if line.get_label() == "R = 0.45 m"]
    assert len(reference) == 1 and list(reference[0].get_ydata()) == [0.45, 0.45]
    # The post, and a dashed circle of radius R round it.
    (circle,) = above.patches
    assert circle.center == (0.9, 0.9) and circle.radius == 0.45
    # The key of the tracks: a dot where each fish started, an arrowhead where it ended.
    assert [text.get_text() for text in above.get_legend().get_texts()] == [
        "start",
        "end, pointing where it swam",
    ]
    # The last step goes from 45° round the centre to 0°: a chord heading 22.5° − 90° =
    # −67.5° in the tank. Seen from above, y runs down the page, so on the page the chord
    # points 67.5° anticlockwise from the x axis; the triangle (pointing up the page, 90°,
    # unturned) is turned by 67.5° − 90°.
    assert above.yaxis_inverted()
    arrowhead: Any = above.get_lines()[2]
    assert arrowhead.get_marker() == (3, 0, pytest.approx(67.5 - 90.0))


def test_a_swarm_runs_figure_keeps_its_distance_panels() -> None:
    position = np.random.default_rng(1).uniform(0.2, 1.5, (5, 4, 3))
    names = ("centroid_distance", "pairwise_distance", "nearest_neighbor_distance")
    metrics = {name: np.linspace(0.2, 0.5, 5) for name in names}
    metrics["neighbors_seen"] = np.full(5, 3.0)
    figure = figure_of_run(np.arange(5.0), position, metrics, (1.78, 1.78, 1.17), title="run")
    assert [_labels(ax) for ax in figure.axes] == [
        ("x (m)", "y (m)"),
        ("x (m)", "depth (m)"),
        ("time (s)", "m"),
        ("time (s)", "neighbours seen"),
    ]


def test_a_formation_runs_figure_colours_fish_by_role_and_lays_the_target_on_them() -> None:
    import matplotlib.colors

    from fishswarm.formations.maps import target_map
    from fishswarm.study.figures import ROLE_COLOURS
    from fishswarm.study.metrics import FormationTarget

    slots = target_map("pyramid", 6, spacing=0.3)
    target = FormationTarget(slots, 0.3, 0.1)
    end = slots + np.array([1.2, 0.9, 0.5])
    # The last fish is 0.3 m from its slot; the best fit shifts the others by up to 0.075 m
    # (computed), within the tolerance of 0.1 m.
    end[5, 1] += 0.3
    position = np.stack([end + np.array([-0.4, 0.0, 0.0]), end])
    metrics = {
        "shape_error": np.array([0.2, 0.05]),
        "joined_fraction": np.array([0.0, 5 / 6]),
        "collisions": np.array([1.0, 0.0]),
    }
    figure = figure_of_run(
        np.arange(2.0), position, metrics, (1.78, 1.78, 1.17), title="f", formation=target
    )
    axes: list[Any] = figure.axes
    above, side, error, joined, crowded = axes
    assert _labels(error) == ("time (s)", "shape error (m)")
    assert len(side.collections) == 2  # the slots and the fish, seen from the side too
    assert _labels(joined) == ("time (s)", "in their places (%)")
    np.testing.assert_allclose(joined.get_lines()[0].get_ydata(), [0.0, 500 / 6])
    assert _labels(crowded) == ("time (s)", "colliding pairs")
    # The tolerance drawn over the shape error.
    (tolerance,) = [line for line in error.get_lines() if line.get_label() == "tolerance"]
    assert list(tolerance.get_ydata()) == [0.1, 0.1]
    slots_drawn, fish_drawn = above.collections
    # The target's six slots, hollow, laid onto the fish at the end (five of them nearly).
    laid = slots_drawn.get_offsets()
    assert laid.shape == (6, 2) and (slots_drawn.get_facecolors().size == 0)
    near = np.linalg.norm(laid[:, None, :] - end[None, :, :2], axis=2).min(axis=0)
    assert (near[:5] < 0.08).all() and near[5] > 0.2
    # Colours: the apex (furthest along +x) leads, four in their places, one still seeking.
    rgba = matplotlib.colors.to_rgba
    colours = [tuple(c) for c in fish_drawn.get_facecolors()]
    assert colours[0] == rgba(ROLE_COLOURS["leader"])
    assert colours[1:5] == [rgba(ROLE_COLOURS["joined"])] * 4
    assert colours[5] == rgba(ROLE_COLOURS["seeking"])
    assert [text.get_text() for text in above.get_legend().get_texts()] == [
        "start", "joined", "seeking", "leader", "target, best fit",
    ]  # fmt: skip


def _orbit_experiment(values: tuple[float, ...], seeds: int) -> Experiment:
    return Experiment(
        name="orbit-test",
        title="Orbit",
        parameter="orbit_radius",
        label="orbit radius R (m)",
        values=values,
        seeds=seeds,
        scenario=Scenario(fish=1, behavior="orbit", duration=8.0, spawn_radius=0.6),
    )


def test_experiment_figures_space_uneven_values_as_they_are_with_one_seed(
    tmp_path: Path,
) -> None:
    from matplotlib.figure import Figure

    experiment = _orbit_experiment((0.3, 0.35, 0.6), seeds=1)
    outcomes = sweep_experiment(experiment, jobs=1)
    rows = table_rows(experiment, outcomes)
    captured: list[Any] = []
    original = Figure.savefig

    def keep(figure: Any, *args: Any, **kwargs: Any) -> None:
        captured.append(figure)
        original(figure, *args, **kwargs)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(Figure, "savefig", keep)
        experiment_figures(experiment, outcomes, rows, tmp_path)
    versus, over_time, _ = captured
    assert versus.get_suptitle() == "Orbit: one seed per value (one run each: no spread)"
    radius = versus.axes[0]
    (container,) = radius.containers
    assert container.get_label() == "measured"
    measured = container.lines[0]
    assert list(measured.get_xdata()) == [0.3, 0.35, 0.6]  # where they are, not 0, 1, 2
    assert [tick for tick in radius.get_xticks()] == [0.3, 0.35, 0.6]
    assert not radius.collections  # no error bars from a single seed
    target = next(line for line in radius.get_lines() if line.get_label() == "target radius R")
    assert list(target.get_ydata()) == [0.3, 0.35, 0.6]
    # Over time: a dashed line at each value's R, and the key beside the panels.
    panel = over_time.axes[0]
    dashed = [line.get_ydata() for line in panel.get_lines() if line.get_linestyle() == "--"]
    levels = sorted(data[0] for data in dashed if len(data))  # the key's entry has no data
    assert levels == [0.3, 0.35, 0.6]
    assert not panel.collections  # no ± s.d. band from a single seed
    (key,) = over_time.legends
    assert [text.get_text() for text in key.get_texts()][-1] == "target radius R"
    assert "± " not in markdown_table(experiment, rows).split("|---")[1]
    assert "1 seeds" not in markdown_table(experiment, rows)


def test_learning_figures_name_their_units_and_keep_the_key_off_the_data(tmp_path: Path) -> None:
    from fishswarm.learning.coevolution import Coevolution, LearningSettings
    from fishswarm.learning.session import (
        evaluate,
        fitness_figure,
        spacing_speed_figure,
        trajectories_figure,
    )

    settings = LearningSettings(models=4, classifiers=4, seed=1)
    run = Coevolution(settings)
    run.step()
    evaluation = evaluate(settings, run.best_model())
    fitness = fitness_figure(run)
    assert _labels(fitness.axes[0]) == ("generation", "fitness (fraction judged right)")
    assert not fitness.axes[0].get_legend() and len(fitness.legends) == 1
    spacing = spacing_speed_figure(settings.arena, evaluation)
    left, right = spacing.axes
    assert _labels(left) == ("time (s)", "mean neighbour distance (units)")
    assert _labels(right) == ("time (s)", "mean speed (units/s)")
    assert not left.get_legend() and not right.get_legend()
    (key,) = spacing.legends
    assert [t.get_text() for t in key.get_texts()] == [
        "ideal fish",
        "best replica",
        "σ, the ideal spacing",
    ]
    tracks = trajectories_figure(evaluation)
    assert _labels(tracks.axes[0]) == ("x (units)", "y (units)")


def test_a_formation_runs_figure_marks_each_switch_of_shape_over_time() -> None:
    from fishswarm.formations.maps import target_map
    from fishswarm.study.metrics import FormationTarget

    target = FormationTarget(target_map("diamond", 6, spacing=0.3), 0.3, 0.1)
    position = np.zeros((4, 6, 3)) + np.array([0.9, 0.9, 0.5])
    metrics = {
        "shape_error": np.array([0.05, 0.04, 0.3, 0.2]),
        "joined_fraction": np.array([1.0, 1.0, 0.0, 0.5]),
        "collisions": np.zeros(4),
    }

    def marks(switches: list[tuple[float, str]]) -> tuple[list[list[float]], list[str]]:
        figure = figure_of_run(
            np.arange(4.0), position, metrics, (1.78, 1.78, 1.17), title="f",
            formation=target, switches=switches,
        )  # fmt: skip
        _, _, error, joined, crowded = figure.axes
        upright = [
            np.asarray(line.get_xdata(), dtype=float).tolist()
            for axes in (error, joined, crowded)
            for line in axes.get_lines()
            if line.get_linestyle() == "-."
        ]
        return upright, [text.get_text() for text in error.texts]

    # Told a diamond at 2 s: a mark at 2 s on the three panels over time, named once.
    assert marks([(2.0, "diamond")]) == ([[2.0, 2.0]] * 3, ["→ diamond"])
    assert marks([]) == ([], [])


def test_the_switches_of_a_recorded_formation_are_where_the_told_shape_changes() -> None:
    from types import SimpleNamespace

    from fishswarm.cli.study import _switches_of

    def recording(told: list[str | None], **scenario: object) -> Any:
        snapshots = [SimpleNamespace(time=float(n), formation=f) for n, f in enumerate(told)]
        settings = {"behavior": "formation", "fish": 6, **scenario}
        return SimpleNamespace(scenario=settings, snapshots=snapshots)

    # An operator's switches, as the snapshots name them (back to the first shape too); an
    # order for the shape the fish already take is none.
    told = [None, "pyramid", "diamond", "diamond", "pyramid"]
    assert _switches_of(recording(told)) == [(2.0, "diamond"), (4.0, "pyramid")]
    assert _switches_of(recording(told, formation="column")) == [
        (1.0, "pyramid"), (2.0, "diamond"), (4.0, "pyramid"),
    ]  # fmt: skip
    # Recorded before snapshots named the shape: the scenario's own switch.
    scheduled = recording([None] * 4, switch_formation="column", switch_at=1.5)
    assert _switches_of(scheduled) == [(2.0, "column")]
    assert _switches_of(recording([None] * 3)) == []


@pytest.mark.parametrize(
    ("values", "scale"),
    [
        ((0.0, 0.05, 0.25, 2.517), "symlog"),  # the study's blind spots
        ((0.0, 0.1, 0.2, 0.3, 0.4), "linear"),  # evenly spaced: where they are
        ((0.25, 0.5), "linear"),
    ],
)
def test_swept_values_label_their_axis_without_overlapping(
    values: tuple[float, ...], scale: str
) -> None:
    # On a linear axis of 0 to 2.5 m the labels 0 and 0.05 were written over each other.
    import itertools

    import matplotlib.pyplot as plt

    from fishswarm.study.figures import parameter_axis

    figure, ax = plt.subplots(figsize=(3.4, 2.6))
    ax.plot(values, np.ones(len(values)), "o-")
    parameter_axis(ax, values)
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
    labels = [label for label in ax.get_xticklabels() if label.get_text()]
    assert ax.get_xscale() == scale
    assert [label.get_text() for label in labels] == [f"{v:g}" for v in values]
    boxes = [label.get_window_extent(renderer) for label in labels]
    for left, right in itertools.pairwise(boxes):
        assert left.x1 <= right.x0 + 0.5 or not left.overlaps(right), (left, right)
    plt.close(figure)
