"""A learning run from start to outputs: generations, checkpoints, resume, results.

Everything a run writes goes to one folder:

- ``checkpoint.npz``: the whole state, every few generations; ``--resume`` continues from it
  exactly where it stopped (same results as a run that never stopped).
- ``history.csv``: best and mean fitness of both populations per generation.
- ``best_replica.npz``: the kept replica (``weights``: with a hall of fame, the winner of a
  tournament of the last generations' champions; without, the fittest model of the last
  generation), with the run's settings (``settings`` as JSON);
  :func:`fishswarm.learning.replica_file.load_replica` reads it back.
- ``radii.md``: the learned radii, mean and s.d. over the final classifier population (the
  study's Table I).
- ``summary.json``: settings, final fitness, spacing and speed over time of ideal vs best
  replica (means over 20 fresh trials), the target's judgement.
- ``fitness.png``, ``spacing_speed.png`` (the study's Figures 10–11) and
  ``trajectories.png`` (Figures 12–13), when matplotlib is installed.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.arena import (
    SPREADS,
    Arena,
    ideal_velocity,
    initial_positions,
    replica_velocity,
    simulate,
    spacing_and_speed,
)
from fishswarm.learning.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from fishswarm.learning.coevolution import Coevolution, LearningSettings
from fishswarm.protocols.jsontext import json_text

FloatArray = NDArray[np.float64]
CHECKPOINT = "checkpoint.npz"


class LearningError(RuntimeError):
    """A learning run cannot start or go on (e.g. nothing to resume); the message says why."""


@dataclass(frozen=True)
class Evaluation:
    """Ideal fish against a replica over several fresh trials.

    Attributes:
        spacing: (2, T + 1) mean neighbour distance over time, ideal then replica.
        speed: (2, T) mean speed over time, ideal then replica.
        tracks: (2, T + 1, N, 2) one trial of each, for pictures.
    """

    spacing: FloatArray
    speed: FloatArray
    tracks: FloatArray


def evaluate(
    settings: LearningSettings, weights: FloatArray, *, trials: int = 20, seed: int = 2**20
) -> Evaluation:
    """Run ``trials`` fresh trials of the ideal fish and of the replica from the same starts."""
    arena = settings.arena
    rng = np.random.default_rng(seed)
    spread = SPREADS[settings.behavior]
    spacing, speed, first = [], [], None
    for _ in range(trials):
        start = initial_positions(rng, arena=arena, spread=spread, models=1)
        ideal = simulate(lambda p: ideal_velocity(p, arena=arena), start, arena=arena)
        replica = simulate(
            lambda p: replica_velocity(p, weights[None], arena=arena), start, arena=arena
        )
        tracks = np.concatenate([ideal, replica])
        trial_spacing, trial_speed = spacing_and_speed(tracks, arena=arena)
        spacing.append(trial_spacing)
        speed.append(trial_speed)
        first = tracks if first is None else first
    assert first is not None
    return Evaluation(np.mean(spacing, axis=0), np.mean(speed, axis=0), first)


SPACING_TOLERANCE = 0.15
"""The target (issue 13): the replica's mean neighbour distance within this share of the
ideal fish's at every second from 5 s to 15 s of a trial."""
SPEED_TOLERANCE = 0.5
"""The target: the replica's final mean speed within this many units/s of the ideal's."""
JUDGED_FROM, JUDGED_UNTIL = 5.0, 15.0
"""The seconds of a trial over which the spacing is judged."""


def target_report(evaluation: Evaluation, arena: Arena) -> dict[str, Any]:
    """How close a replica comes to the ideal fish, by the target's two measures: the
    largest relative spacing error over whole seconds 5–15 s and the final speed difference,
    and whether both are within their tolerances."""
    steps = np.arange(evaluation.spacing.shape[1])
    seconds = steps * arena.period
    judged = (
        (seconds >= JUDGED_FROM)
        & (seconds <= JUDGED_UNTIL)
        & np.isclose(seconds, np.round(seconds))
    )
    ideal, replica = evaluation.spacing[0, judged], evaluation.spacing[1, judged]
    spacing_error = float(np.max(np.abs(replica - ideal) / ideal))
    speed_difference = float(abs(evaluation.speed[1, -1] - evaluation.speed[0, -1]))
    return {
        "spacing_error": spacing_error,
        "speed_difference": speed_difference,
        "met": spacing_error <= SPACING_TOLERANCE and speed_difference <= SPEED_TOLERANCE,
    }


OUTPUTS = (
    CHECKPOINT,
    "history.csv",
    "best_replica.npz",
    "radii.md",
    "summary.json",
    "fitness.png",
    "spacing_speed.png",
    "trajectories.png",
)
"""Every file a learning run writes into its folder."""


def learn(
    settings: LearningSettings | None,
    *,
    generations: int,
    out: Path,
    checkpoint_every: int = 10,
    resume: bool = False,
    given: Mapping[str, Any] | None = None,
    on_start: Callable[[Coevolution, bool], None] | None = None,
    on_generation: Callable[[Coevolution, dict[str, float], float], None] | None = None,
) -> dict[str, Any]:
    """Run (or resume) co-evolution up to ``generations`` and write the outputs to ``out``.

    Args:
        settings: the run's settings (None only when resuming: the checkpoint's rule).
        generations: total number of generations, counting those already done.
        out: output folder.
        checkpoint_every: write a checkpoint every this many generations (and at the end).
        resume: continue from ``out/checkpoint.npz``.
        given: the settings the user asked for by name (e.g. ``{"behavior": "dispersion"}``);
            resuming a run learned with other values of them is refused, not ignored.
        on_start: called once the run is set up, with the run and whether it was resumed.
        on_generation: called after each generation with the run, its record and the wall
            time of the generation, s.

    Returns:
        The summary also written to ``out/summary.json``.

    Raises:
        LearningError: nothing to resume, an unreadable checkpoint, or settings that differ
            from the resumed run's.
    """
    for name, value in (("generations", generations), ("checkpoint interval", checkpoint_every)):
        if value < 1:
            raise LearningError(f"{name} must be at least 1, got {value}")
    checkpoint = out / CHECKPOINT
    if resume:
        if not checkpoint.exists():
            raise LearningError(f"nothing to resume: {checkpoint} does not exist")
        try:
            run = load_checkpoint(checkpoint)
        except CheckpointError as error:
            raise LearningError(str(error)) from None
        _check_same(run.settings, given or {}, checkpoint)
    elif settings is None:
        raise LearningError("a new run needs its settings (None is for resuming only)")
    else:
        run = Coevolution(settings)
        # A new run replaces an earlier one in ``out`` whole: interrupted, it must not
        # leave that run's replica and summary beside its own checkpoint.
        for name in OUTPUTS:
            (out / name).unlink(missing_ok=True)
    if on_start is not None:
        on_start(run, resume)
    while run.generation < generations:
        started = time.perf_counter()
        record = run.step()
        if on_generation is not None:
            on_generation(run, record, time.perf_counter() - started)
        if run.generation % checkpoint_every == 0 or run.generation == generations:
            save_checkpoint(run, checkpoint, target=generations)
    return write_results(run, out)


def _check_same(saved: LearningSettings, given: Mapping[str, Any], checkpoint: Path) -> None:
    """Refuse to resume a run learned with other settings than those asked for."""
    for name, value in given.items():
        old = getattr(saved, name)
        if old != value:
            flag = "--" + name.replace("_", "-")
            raise LearningError(
                f"{checkpoint} holds a run learned with {name} {_shown(old)}, but this command "
                f"asks for {_shown(value)}: drop {flag} to go on with that run, or start a new "
                "one in another --out folder"
            )


def _shown(value: Any) -> str:
    return ",".join(value) if isinstance(value, tuple) else str(value)


def write_results(run: Coevolution, out: Path) -> dict[str, Any]:
    """Write every output of a run that has done at least one generation."""
    out.mkdir(parents=True, exist_ok=True)
    settings = run.settings
    best = run.tournament_model()
    settings_json = json.dumps(_settings_dict(settings))
    np.savez(out / "best_replica.npz", weights=best, settings=np.array(settings_json))
    with (out / "history.csv").open("w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(run.history[0]))
        writer.writeheader()
        # Generations are counts (checkpoints of older versions stored them as floats).
        writer.writerows({**row, "generation": int(row["generation"])} for row in run.history)
    radii = run.final_radii()
    table = ["| radius | mean | s.d. |", "|---|---:|---:|"]
    for index in range(radii.shape[1]):
        table.append(
            f"| r{index + 1} | {radii[:, index].mean():.1f} | {radii[:, index].std(ddof=1):.1f} |"
        )
    if radii.shape[1] == 0:
        table.append("| (no radius: the classifiers did not count neighbours) | | |")
    (out / "radii.md").write_text(
        f"Learned radii over the final {len(radii)} classifiers "
        f"({settings.behavior}, radii {settings.radii}, inputs {', '.join(settings.inputs)}, "
        f"generation {run.generation}).\n\n" + "\n".join(table) + "\n",
        encoding="utf-8",
    )
    evaluation = evaluate(settings, best)
    final = run.history[-1]
    summary: dict[str, Any] = {
        "settings": _settings_dict(settings),
        "generations": run.generation,
        "final_fitness": final,
        "radii": {"mean": radii.mean(axis=0).tolist(), "sd": radii.std(axis=0, ddof=1).tolist()},
        "model_restarts": run.model_restarts,
        **{
            who: {
                "final_spacing": float(evaluation.spacing[row, -1]),
                "final_speed": float(evaluation.speed[row, -1]),
                "spacing": evaluation.spacing[row].tolist(),
                "speed": evaluation.speed[row].tolist(),
            }
            for row, who in enumerate(("ideal", "replica"))
        },
        "target": target_report(evaluation, settings.arena),
    }
    (out / "summary.json").write_text(json_text(summary, indent=2) + "\n", encoding="utf-8")
    _pictures(run, evaluation, out)
    return summary


def _settings_dict(settings: LearningSettings) -> dict[str, Any]:
    data = dataclasses.asdict(settings)
    data["inputs"] = list(settings.inputs)
    return data


def _pictures(run: Coevolution, evaluation: Evaluation, out: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    for name, figure in (
        ("fitness.png", fitness_figure(run)),
        ("spacing_speed.png", spacing_speed_figure(run.settings.arena, evaluation)),
        ("trajectories.png", trajectories_figure(evaluation)),
    ):
        figure.savefig(out / name, dpi=120)
        plt.close(figure)


def fitness_figure(run: Coevolution) -> Any:
    """Best and mean fitness of both populations per generation (the study's Figure 10)."""
    import matplotlib.pyplot as plt

    history = run.history
    generation = [h["generation"] for h in history]
    figure, axis = plt.subplots(figsize=(8, 4), layout="constrained")
    axis.plot(generation, [h["model_mean"] for h in history], label="models, mean")
    axis.plot(generation, [h["model_best"] for h in history], label="models, best", alpha=0.6)
    axis.plot(generation, [h["classifier_mean"] for h in history], label="classifiers, mean")
    axis.plot(
        generation, [h["classifier_best"] for h in history], label="classifiers, best", alpha=0.6
    )
    axis.set(
        xlabel="generation",
        ylabel="fitness (fraction judged right)",
        ylim=(0, 1),
        title=f"Turing learning, {run.settings.behavior}",
    )
    figure.legend(loc="outside right upper", fontsize=8)  # beside the curves, not on them
    return figure


def spacing_speed_figure(arena: Arena, evaluation: Evaluation) -> Any:
    """Spacing and speed over time, ideal fish against the best replica (Figure 11)."""
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    for row, label in ((0, "ideal fish"), (1, "best replica")):
        left.plot(
            np.arange(evaluation.spacing.shape[1]) * arena.period,
            evaluation.spacing[row],
            label=label,
        )
        right.plot(
            (np.arange(evaluation.speed.shape[1]) + 1) * arena.period,
            evaluation.speed[row],
            label=label,
        )
    left.axhline(arena.spacing, color="grey", linestyle=":", label="σ, the ideal spacing")
    # The study's arena has its own length unit ("units", 300 to a side).
    left.set(xlabel="time (s)", ylabel="mean neighbour distance (units)", title="spacing")
    right.set(xlabel="time (s)", ylabel="mean speed (units/s)", title="speed")
    figure.legend(*left.get_legend_handles_labels(), loc="outside right upper", fontsize=8)
    return figure


def trajectories_figure(evaluation: Evaluation) -> Any:
    """One trial of the ideal fish and one of the best replica, from above (Figures
    12–13); a dot where each fish ended."""
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(
        1, 2, figsize=(10, 5), sharex=True, sharey=True, layout="constrained"
    )
    for axis, row, label in ((axes[0], 0, "ideal fish"), (axes[1], 1, "best replica")):
        tracks = evaluation.tracks[row]
        for fish in range(tracks.shape[1]):
            axis.plot(tracks[:, fish, 0], tracks[:, fish, 1], linewidth=0.8)
            axis.plot(tracks[-1, fish, 0], tracks[-1, fish, 1], "k.", markersize=4)
        axis.set(title=label, aspect="equal", xlabel="x (units)")
    axes[0].set_ylabel("y (units)")
    return figure
