"""Learning checkpoints as plain data: a NumPy archive that cannot run code when read.

A checkpoint holds the run's settings, its history, the scores each optimiser was told at
every generation, the champions and the last populations — arrays and JSON, read with
``allow_pickle=False``. CMA-ES's own state is not stored: it is rebuilt by replaying the
run's ask/tell sequence with the stored scores (the optimisers draw from seeded streams of
their own, so the replay asks for the same solutions and ends in the same state, bit for
bit). Replaying 500 generations takes about a second; nothing is simulated again.
"""

from __future__ import annotations

import dataclasses
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from fishswarm.learning.arena import arena_from
from fishswarm.learning.coevolution import Coevolution, Fitness, LearningSettings
from fishswarm.learning.features import radii_count

FORMAT = "fishswarm-learning-checkpoint/1"

# What a run was learned with before each of these settings existed: a checkpoint written
# then lacks the field, and must resume as it ran, not with today's default.
_BEFORE_THE_SETTING: dict[str, Any] = {
    "hall_of_fame": 0,
    "virulence": 1.0,
    "trials": 1,
    "radius_start": None,
}


class CheckpointError(ValueError):
    """A file is not a readable learning checkpoint; the message says why."""


def save_checkpoint(run: Coevolution, path: Path, *, target: int | None = None) -> None:
    """Write ``run`` to ``path`` atomically (a crash never leaves half a file), with the
    generation it is to reach (``target``; None: not said), which a resumed run goes on to."""
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "format": FORMAT,
        "settings": _settings_data(run.settings),
        "generation": run.generation,
        "history": run.history,
        **({} if target is None else {"target": target}),
    }
    arrays: dict[str, np.ndarray] = {
        "meta": np.array(json.dumps(meta)),
        "told_models": _rows(run.told_models),
        "told_classifiers": _rows(run.told_classifiers),
        "model_champions": _rows(run.model_champions),
        "classifier_champions": _rows(run.classifier_champions),
        "population": run.population,
        "classifier_population": run.classifier_population,
    }
    if run.last_fitness is not None:
        for field in dataclasses.fields(Fitness):
            arrays[f"fitness_{field.name}"] = getattr(run.last_fitness, field.name)
    partial = path.with_name(path.name + ".partial")
    with partial.open("wb") as stream:
        np.savez(stream, **arrays)  # type: ignore[arg-type]
    partial.replace(path)


def load_checkpoint(path: Path) -> Coevolution:
    """Read a checkpoint written by :func:`save_checkpoint`.

    Raises:
        CheckpointError: missing, truncated, or not a fishswarm learning checkpoint.
    """
    try:
        # Opened here, so that a file numpy refuses is still closed.
        with path.open("rb") as stream, np.load(stream, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
        meta = json.loads(str(arrays["meta"]))
    except FileNotFoundError:
        raise CheckpointError(f"{path} does not exist") from None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as error:
        raise CheckpointError(
            f"{path} is not a readable learning checkpoint (truncated or another kind of "
            f"file: {type(error).__name__}); start afresh with --force instead of --resume "
            "(it replaces the folder's run), or keep the folder and use a new --out"
        ) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not a fishswarm learning checkpoint ({FORMAT})")
    try:
        run = Coevolution(_settings_from(meta["settings"]))
        told_models, told_classifiers = arrays["told_models"], arrays["told_classifiers"]
        generations = int(meta["generation"])
        if told_models.shape[0] != generations or told_classifiers.shape[0] != generations:
            raise ValueError("the told scores do not cover every generation")
        run.replay(told_models, told_classifiers)
        # One record a generation, in order: numbered from 1 again (checkpoints written
        # before history.csv counted from 1 hold 0, 1, 2, ...).
        run.history = [
            {**dict(record), "generation": number}
            for number, record in enumerate(meta["history"], start=1)
        ]
        run.model_champions = list(arrays["model_champions"])
        run.classifier_champions = list(arrays["classifier_champions"])
        run.population = arrays["population"]
        run.classifier_population = arrays["classifier_population"]
        if "fitness_models" in arrays:
            run.last_fitness = Fitness(
                *(arrays[f"fitness_{field.name}"] for field in dataclasses.fields(Fitness))
            )
    except (KeyError, TypeError, ValueError) as error:
        raise CheckpointError(f"{path} is a damaged learning checkpoint: {error}") from None
    return run


def checkpoint_progress(path: Path) -> tuple[int | None, int | None]:
    """How far the run in the checkpoint at ``path`` is: the generations it has done, and
    the generation it was to reach (each None where the file does not say — a target was
    not written before checkpoints did — or cannot be read, which :func:`load_checkpoint`
    then explains); one read of the file for both."""
    try:
        with path.open("rb") as stream, np.load(stream, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None, None
    if not isinstance(meta, dict):
        return None, None
    done, target = (meta.get(name) for name in ("generation", "target"))
    return _whole(done), _whole(target)


def checkpoint_target(path: Path) -> int | None:
    """The generation the run in the checkpoint at ``path`` was to reach (see
    :func:`checkpoint_progress`)."""
    return checkpoint_progress(path)[1]


def checkpoint_generation(path: Path) -> int | None:
    """The generations the run in the checkpoint at ``path`` has done (see
    :func:`checkpoint_progress`)."""
    return checkpoint_progress(path)[0]


def _whole(value: object) -> int | None:
    """``value`` if it is a whole number (JSON's true and false are not), else None."""
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _rows(rows: list[np.ndarray]) -> np.ndarray:
    """A list of equal rows as one 2-D array (an empty list: shape (0, 0))."""
    return np.stack(rows) if rows else np.zeros((0, 0))


def _settings_data(settings: LearningSettings) -> dict[str, Any]:
    data = dataclasses.asdict(settings)
    data["inputs"] = list(settings.inputs)
    return data


def _settings_from(data: dict[str, Any]) -> LearningSettings:
    values = {**_BEFORE_THE_SETTING, **data}
    values["inputs"] = tuple(values["inputs"])
    if radii_count(values["inputs"]) == 0:
        # Saved by a version that took a start for radii these inputs never learn: it
        # meant nothing then either.
        values["radius_start"] = None
    values["arena"] = arena_from(values["arena"])
    return LearningSettings(**values)
