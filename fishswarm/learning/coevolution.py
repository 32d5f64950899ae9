"""Turing learning: replica models and classifiers co-evolved with CMA-ES (pycma ask/tell).

Each generation runs one trial of the ideal fish (its N tracks are the genuine samples) and
one trial per model (N counterfeit samples each), all from the same start (common random
numbers). Every classifier judges every sample. A model's fitness is the fraction of
judgements it fooled; a classifier's is ½(sensitivity + specificity).

Known traps of pycma 4.5, handled here: ``tell`` minimises, so fitness goes in negated;
runs loop a fixed number of generations (the stopping rules would end a run on tied
fitness after one iteration); each optimiser draws from its own generator (the ``seed``
option would reseed numpy's global one); radii live on a scale of 100 so that every
coordinate has a step size near 1; and thresholded judgements tie easily, so a small share
of the soft output (the classifier's probability) breaks ties.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cma
import numpy as np
from numpy.typing import NDArray

from fishswarm.learning.arena import (
    SPREADS,
    Arena,
    ideal_velocity,
    initial_positions,
    replica_velocity,
    simulate,
)
from fishswarm.learning.features import (
    check_inputs,
    feature_count,
    neighbor_counts,
    radii_count,
    samples_from,
)
from fishswarm.learning.networks import REPLICA_SIZE, classifier_size, classify

FloatArray = NDArray[np.float64]

RADIUS_SCALE = 100.0
"""A classifier genome holds radius / 100, so radii move at the pace of the weights."""

RADII_MODES = {"bounded": (0.0, 300.0), "unbounded": (-40.0, 300.0)}
"""Radii stay in [0, 300] (bounded), or start in [−40, 300] and roam free (unbounded: a
negative radius counts nobody).

Bounded radii are folded back into [0, 300] (a triangle wave of the genome), not clipped:
with clipping every genome below 0 means radius 0, a flat plateau that CMA-ES drifts into
while neighbour counts carry no signal yet, and never leaves (measured: the radii of all
100 classifiers ended at exactly 0 in every clipped 500-generation run)."""


@dataclass(frozen=True)
class LearningSettings:
    """What a learning run does.

    Attributes:
        behavior: ``aggregation`` (start spread 100) or ``dispersion`` (spread 20).
        inputs: classifier inputs, see :mod:`fishswarm.learning.features`. The default,
            speed and the counts of schoolmates within three fixed radii, shows the
            classifiers spacing from the first generation; the study's were speed and a
            count within one learned radius, ``("speed", "neighbors")``.
        radii: ``bounded`` or ``unbounded``.
        models: replica population size.
        classifiers: classifier population size.
        seed: master seed.
        arena: the 2-D world, with isotropic replicas by default (``Arena()`` is the
            study's world with the study's replica).
        soft_weight: share of the soft output added to the thresholded fitness (1: as much
            as the thresholded one; 0.001: it only breaks ties, the study's method).
        hall_of_fame: past champions drawn into each generation (0: the study's method).
            Models are also judged by this many past best classifiers, and classifiers also
            judge the tracks of this many past best models, against cycling and against
            disengagement (one side winning so completely that the other gets no signal).
        virulence: λ in (0, 1]: classifiers are fittest when their score (thresholded plus
            soft, scaled to [0, 1]) is λ, not when it is highest (1: the study's method;
            0.75 by default, against the classifiers winning outright).
            Cartlidge and Bullock's reduced virulence (Evolutionary Computation 12(2),
            2004): a classifier that leaves replicas no way to score is less fit than one
            they can learn from.
        trials: starts each generation is judged on (1: the study's method); the ideal fish
            and every model swim from each, and every fitness is averaged over them, so that
            a model is not ranked by one lucky or unlucky start. Each start costs a
            simulation and a judgement of every sample: the time per generation grows with it.
        radius_start: where the classifiers' learned radii start, units (None: the middle
            of their range, 150 bounded or 130 unbounded). Classifiers that judge spacing
            need a radius about the ideal fish's spacing; started at 150, the radius counts
            nearly the whole school, and the classifiers settle on judging speed alone.
    """

    behavior: str = "aggregation"
    inputs: tuple[str, ...] = ("speed", "counts")
    radii: str = "bounded"
    models: int = 100
    classifiers: int = 100
    seed: int = 0
    arena: Arena = field(default_factory=lambda: Arena(replica="isotropic"))
    soft_weight: float = 1.0
    hall_of_fame: int = 10
    virulence: float = 0.75
    trials: int = 1
    radius_start: float | None = None

    def __post_init__(self) -> None:
        if self.behavior not in SPREADS:
            raise ValueError(f"behavior must be one of {', '.join(SPREADS)}, got {self.behavior!r}")
        check_inputs(self.inputs)
        if self.radii not in RADII_MODES:
            raise ValueError(f"radii must be bounded or unbounded, got {self.radii!r}")
        if self.models < 2 or self.classifiers < 2:
            raise ValueError("models and classifiers need populations of at least 2")
        if self.seed < 0:
            raise ValueError(f"seed must be non-negative, got {self.seed}")
        if not (math.isfinite(self.soft_weight) and self.soft_weight >= 0):
            raise ValueError(
                f"soft_weight must be a finite number, 0 or more, got {self.soft_weight}"
            )
        if not 0 < self.virulence <= 1:
            raise ValueError(f"virulence must be in (0, 1], got {self.virulence}")
        if self.hall_of_fame < 0:
            raise ValueError(f"hall_of_fame must be 0 or more, got {self.hall_of_fame}")
        if self.trials < 1:
            raise ValueError(f"trials must be 1 or more, got {self.trials}")
        low, high = RADII_MODES[self.radii]
        if self.radius_start is not None and not (
            math.isfinite(self.radius_start) and low <= self.radius_start <= high
        ):
            raise ValueError(
                f"radius_start must lie in [{low:g}, {high:g}] for {self.radii} radii, "
                f"got {self.radius_start:g}"
            )
        if self.radius_start is not None and self.radius_count == 0:
            raise ValueError(
                f"radius_start {self.radius_start:g} sets where learned radii start, but the "
                f"inputs {','.join(self.inputs)} learn none: give inputs that count "
                "neighbours within learned radii (e.g. speed,neighbors2), or leave it out"
            )

    @property
    def first_radius(self) -> float:
        """Where the classifiers' radii start, units."""
        low, high = RADII_MODES[self.radii]
        return (low + high) / 2 if self.radius_start is None else self.radius_start

    @property
    def replica(self) -> str:
        """How a replica's network makes a neighbour's contribution: ``isotropic``,
        ``reciprocal`` or ``study``; see :class:`~fishswarm.learning.arena.Arena`."""
        return self.arena.replica

    @property
    def network_size(self) -> int:
        """Parameters of a classifier network (radii excluded)."""
        return classifier_size(feature_count(self.inputs))

    @property
    def radius_count(self) -> int:
        """Radii each classifier learns."""
        return radii_count(self.inputs)


@dataclass(frozen=True)
class Fitness:
    """Fitness of one generation, thresholded (the study's) and soft.

    Attributes:
        models: (M,) fraction of judgements each model fooled.
        classifiers: (C,) ½(sensitivity + specificity) of each classifier.
        models_soft: (M,) mean "ideal" probability the classifiers gave each model's samples.
        classifiers_soft: (C,) the same balance computed from probabilities.
    """

    models: FloatArray
    classifiers: FloatArray
    models_soft: FloatArray
    classifiers_soft: FloatArray


def fitness(judgement: FloatArray) -> Fitness:
    """Fitness from judgements.

    Args:
        judgement: (C, 1 + M, N) probability that a sample is genuine; trial 0 holds the
            ideal fish, trials 1..M the models' fish.
    """
    hard = (judgement > 0.5).astype(np.float64)
    sensitivity = hard[:, 0].mean(axis=1)
    specificity = 1.0 - hard[:, 1:].mean(axis=(1, 2))
    soft_sensitivity = judgement[:, 0].mean(axis=1)
    soft_specificity = 1.0 - judgement[:, 1:].mean(axis=(1, 2))
    return Fitness(
        models=hard[:, 1:].mean(axis=(0, 2)),
        classifiers=0.5 * (sensitivity + specificity),
        models_soft=judgement[:, 1:].mean(axis=(0, 2)),
        classifiers_soft=0.5 * (soft_sensitivity + soft_specificity),
    )


def reduced_virulence(score: FloatArray, virulence: float) -> FloatArray:
    """Cartlidge and Bullock's fitness of a score in [0, 1]: 2s/λ − s²/λ², which is 1 at
    s = λ and falls on both sides (at λ = 1 it only rescales, keeping the order)."""
    ratio = score / virulence
    result: FloatArray = 2 * ratio - ratio * ratio
    return result


def radii_of(genomes: FloatArray, settings: LearningSettings) -> FloatArray:
    """(C, R) radii from classifier genomes (C, network_size + R)."""
    radii = genomes[:, settings.network_size :] * RADIUS_SCALE
    if settings.radii == "bounded":
        low, high = RADII_MODES["bounded"]
        span = high - low
        radii = low + span - np.abs(np.mod(radii - low, 2 * span) - span)
    return radii


_TRIALS, _MODELS, _CLASSIFIERS, _HALL, _TOURNAMENT = 1, 2, 3, 4, 5

FLAT_GENERATIONS = 10
"""After this many generations in which every model scored the same, the model optimiser
starts again (see :meth:`Coevolution.step`)."""

TOURNAMENT_GENERATIONS = 100
"""The master tournament pits the champions of this many last generations against each
other."""


def _stream(seed: int, role: int, *key: int) -> np.random.Generator:
    """The generator of one role (and generation) of a run, derived from the seed alone."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(role, *key)))


class PrivateNormal:
    """Standard normal samples for pycma from a generator of our own (so that a replay asks
    for the same solutions)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def __call__(self, *shape: int) -> FloatArray:
        result: FloatArray = self.rng.standard_normal(shape)
        return result


def _strategy(x0: FloatArray, popsize: int, rng: np.random.Generator) -> Any:
    options = {
        "popsize": popsize,
        "seed": math.nan,
        "randn": PrivateNormal(rng),
        "verbose": -9,
        "verb_log": 0,
        "verb_disp": 0,
        "tolfun": 0,
        "tolfunhist": 0,
        "tolflatfitness": 10**9,
        "tolstagnation": 10**9,
        "tolx": 0,
        "tolxstagnation": [0, 10**9, 0],
        "maxiter": 10**9,
    }
    return cma.CMAEvolutionStrategy(x0, 1.0, options)


class Coevolution:
    """A learning run, one generation per :meth:`step` (checkpoints:
    :mod:`fishswarm.learning.checkpoint`)."""

    def __init__(self, settings: LearningSettings) -> None:
        self.settings = settings
        self.generation = 0
        self.history: list[dict[str, float]] = []
        self._models = _strategy(
            np.zeros(REPLICA_SIZE), settings.models, _stream(settings.seed, _MODELS)
        )
        radii_start = np.full(settings.radius_count, settings.first_radius / RADIUS_SCALE)
        self._classifiers = _strategy(
            np.concatenate([np.zeros(settings.network_size), radii_start]),
            settings.classifiers,
            _stream(settings.seed, _CLASSIFIERS),
        )
        self.model_champions: list[FloatArray] = []
        self.classifier_champions: list[FloatArray] = []
        self.population: FloatArray = np.zeros((0, REPLICA_SIZE))
        self.classifier_population: FloatArray = np.zeros((0, 0))
        self.last_fitness: Fitness | None = None
        self.told_models: list[FloatArray] = []
        """The scores each generation told the model optimiser (what a replay needs)."""
        self.told_classifiers: list[FloatArray] = []
        """The scores each generation told the classifier optimiser."""
        self.model_restarts = 0
        """How often the model optimiser started again on flat fitness."""
        self._flat = 0

    def trial_start(self, generation: int, trials: int, start: int = 0) -> FloatArray:
        """The positions of a generation's ``start``-th start, repeated ``trials`` times
        (shared by the ideal fish and every model)."""
        extra = (start,) if start else ()  # the first start is the one a single trial had
        return self._start(_TRIALS, generation, trials, *extra)

    def _start(self, role: int, generation: int, trials: int, *key: int) -> FloatArray:
        """``trials`` start positions from the stream of ``role`` at ``generation``."""
        rng = _stream(self.settings.seed, role, generation, *key)
        spread = SPREADS[self.settings.behavior]
        return initial_positions(rng, arena=self.settings.arena, spread=spread, models=trials)

    def step(self) -> dict[str, float]:
        """Run one generation: simulate, judge, tell both optimisers; returns its record."""
        settings = self.settings
        models = np.array(self._models.ask())
        classifiers = np.array(self._classifiers.ask())
        current_models, current_classifiers = len(models), len(classifiers)
        if settings.hall_of_fame and self.model_champions:
            rng = _stream(settings.seed, _HALL, self.generation)
            picks = min(settings.hall_of_fame, len(self.model_champions))
            chosen = rng.choice(len(self.model_champions), picks, replace=False)
            models = np.concatenate([models, np.array(self.model_champions)[chosen]])
            chosen = rng.choice(len(self.classifier_champions), picks, replace=False)
            classifiers = np.concatenate([classifiers, np.array(self.classifier_champions)[chosen]])
        # Each start's judgements (C, 1 + M, N), side by side: every fitness is a mean over
        # fish, so over fish of all the starts.
        judgement = np.concatenate(
            [
                self._judgement(
                    self._trial(self.trial_start(self.generation, 1 + len(models), n), models),
                    classifiers,
                )
                for n in range(settings.trials)
            ],
            axis=2,
        )
        everything = fitness(judgement)
        # Champions only judge and are judged: the optimisers hear about the current ones.
        result = Fitness(
            everything.models[:current_models],
            everything.classifiers[:current_classifiers],
            everything.models_soft[:current_models],
            everything.classifiers_soft[:current_classifiers],
        )
        models, classifiers = models[:current_models], classifiers[:current_classifiers]
        weight = settings.soft_weight
        model_score = self._model_score(result)
        classifier_score = reduced_virulence(
            (result.classifiers + weight * result.classifiers_soft) / (1 + weight),
            settings.virulence,
        )
        self._tell(models, classifiers, model_score, classifier_score)
        if settings.hall_of_fame:
            self.model_champions.append(models[int(np.argmax(model_score))])
            self.classifier_champions.append(classifiers[int(np.argmax(classifier_score))])
        self.population, self.classifier_population = models, classifiers
        self.last_fitness = result
        record = {
            # Counted from 1, as the progress line, radii.md and the summary count them.
            "generation": self.generation + 1,
            "model_best": float(result.models.max()),
            "model_mean": float(result.models.mean()),
            "classifier_best": float(result.classifiers.max()),
            "classifier_mean": float(result.classifiers.mean()),
        }
        self.history.append(record)
        self.generation += 1
        return record

    def best_model(self) -> FloatArray:
        """Weights of the fittest model of the last generation (soft output breaks ties)."""
        if self.last_fitness is None:
            raise RuntimeError("no generation has run yet")
        score = self.last_fitness.models + self.settings.soft_weight * self.last_fitness.models_soft
        best: FloatArray = self.population[int(np.argmax(score))]
        return best

    def tournament_model(self) -> FloatArray:
        """The replica to keep: with a hall of fame, the model champion of the last
        :data:`TOURNAMENT_GENERATIONS` generations that fooled their classifier champions
        most, all judging one fresh start (Nolfi and Floreano's master tournament, 1998:
        co-evolution cycles, so the last generation's best is often not the best there
        was); without one, :meth:`best_model`."""
        if not self.model_champions:
            return self.best_model()
        models = np.array(self.model_champions[-TOURNAMENT_GENERATIONS:])
        classifiers = np.array(self.classifier_champions[-TOURNAMENT_GENERATIONS:])
        start = self._start(_TOURNAMENT, self.generation, 1 + len(models))
        score = self._model_score(self._judge(self._trial(start, models), classifiers))
        best: FloatArray = models[int(np.argmax(score))]
        return best

    def _model_score(self, scores: Fitness) -> FloatArray:
        """What the model optimiser maximises: fooled verdicts plus the weighted soft ones."""
        score: FloatArray = scores.models + self.settings.soft_weight * scores.models_soft
        return score

    def _trial(self, start: FloatArray, models: FloatArray) -> FloatArray:
        """Tracks (1 + M, T + 1, N, 2): the ideal fish from ``start[0]``, then each model's."""
        arena = self.settings.arena
        ideal = simulate(lambda p: ideal_velocity(p, arena=arena), start[:1], arena=arena)
        replicas = simulate(
            lambda p: replica_velocity(p, models, arena=arena), start[1:], arena=arena
        )
        return np.concatenate([ideal, replicas])

    def _judge(self, tracks: FloatArray, classifiers: FloatArray) -> Fitness:
        """Every classifier judges every fish of ``tracks`` (the ideal fish's trial first)."""
        return fitness(self._judgement(tracks, classifiers))

    def _judgement(self, tracks: FloatArray, classifiers: FloatArray) -> FloatArray:
        """(C, 1 + M, N) each classifier's probability that each fish of ``tracks`` (the
        ideal fish's trial first) is an ideal fish."""
        settings = self.settings
        samples = samples_from(tracks, settings.inputs, arena=settings.arena)
        own = (
            neighbor_counts(samples, radii_of(classifiers, settings))
            if settings.radius_count
            else np.zeros((len(classifiers), *samples.fixed.shape[:2], 0))
        )
        judgement = classify(classifiers[:, : settings.network_size], samples.fixed, own)
        result: FloatArray = judgement.reshape(len(classifiers), len(tracks), settings.arena.fish)
        return result

    def final_radii(self) -> FloatArray:
        """(C, R) radii of the last classifier population."""
        return radii_of(self.classifier_population, self.settings)

    def _tell(
        self,
        models: FloatArray,
        classifiers: FloatArray,
        model_score: FloatArray,
        classifier_score: FloatArray,
    ) -> None:
        # pycma minimises: tell it the negated fitness.
        self._models.tell(list(models), list(-model_score))
        self._classifiers.tell(list(classifiers), list(-classifier_score))
        self.told_models.append(model_score)
        self.told_classifiers.append(classifier_score)
        # Replicas whose speed output has saturated at 0 all stand still, whatever their
        # weights: every model scores the same, and CMA-ES drifts on that plateau without a
        # way back (measured: 5 of 9 runs at the study's size ended that way).
        # pycma's own answer to flat fitness is to stop (tolflatfitness); a run restarts
        # the model optimiser from where it began, with a fresh generator, instead.
        self._flat = self._flat + 1 if np.ptp(model_score) <= 1e-12 else 0
        if self._flat >= FLAT_GENERATIONS:
            self.model_restarts += 1
            self._flat = 0
            self._models = _strategy(
                np.zeros(REPLICA_SIZE),
                self.settings.models,
                _stream(self.settings.seed, _MODELS, self.model_restarts),
            )

    def replay(self, told_models: FloatArray, told_classifiers: FloatArray) -> None:
        """Bring a fresh run's optimisers to where a run stood after telling these scores:
        (G, M) and (G, C), one row per generation. Nothing is simulated."""
        if self.generation:
            raise RuntimeError("only a fresh run can replay")
        for model_score, classifier_score in zip(told_models, told_classifiers, strict=True):
            models = np.array(self._models.ask())
            classifiers = np.array(self._classifiers.ask())
            if models.shape[0] != model_score.shape[0] or (
                classifiers.shape[0] != classifier_score.shape[0]
            ):
                raise ValueError("the told scores do not match the population sizes")
            self._tell(models, classifiers, model_score, classifier_score)
            self.generation += 1
