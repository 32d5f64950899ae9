"""Fitness by hand, determinism, checkpoint and resume, and pycma's traps."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fishswarm.learning.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from fishswarm.learning.coevolution import (
    FLAT_GENERATIONS,
    TOURNAMENT_GENERATIONS,
    Coevolution,
    LearningSettings,
    fitness,
    radii_of,
    reduced_virulence,
)

SMALL = LearningSettings(models=6, classifiers=5, seed=3, hall_of_fame=0, soft_weight=1e-3)


def test_fitness_on_a_hand_made_example() -> None:
    # 2 classifiers, the ideal fish and 2 models, 2 samples each.
    judgement = np.array(
        [
            # ideal        model 1      model 2
            [[0.9, 0.8], [0.6, 0.1], [0.2, 0.3]],  # classifier 1
            [[0.4, 0.7], [0.9, 0.9], [0.1, 0.6]],  # classifier 2
        ]
    )
    result = fitness(judgement)
    # Model 1 fooled 1 of 2 (c1) and 2 of 2 (c2): 3/4. Model 2: 0 and 1: 1/4.
    np.testing.assert_allclose(result.models, [0.75, 0.25])
    # c1: sensitivity 2/2, specificity 3/4 → 0.875. c2: 1/2 and 1/4 → 0.375.
    np.testing.assert_allclose(result.classifiers, [0.875, 0.375])
    np.testing.assert_allclose(
        result.models_soft, [(0.6 + 0.1 + 0.9 + 0.9) / 4, (0.2 + 0.3 + 0.1 + 0.6) / 4]
    )


def test_a_judgement_of_exactly_one_half_calls_no_fish_genuine() -> None:
    # A classifier with all weights zero answers sigmoid(0) = 0.5 for every fish: it has
    # called none genuine, so it fools no model and finds no ideal fish (sensitivity 0,
    # specificity 1).
    result = fitness(np.full((1, 3, 2), 0.5))
    np.testing.assert_array_equal(result.models, [0.0, 0.0])
    np.testing.assert_array_equal(result.classifiers, [0.5])
    np.testing.assert_array_equal(result.models_soft, [0.5, 0.5])


def test_bounded_radii_fold_back_into_range() -> None:
    settings = LearningSettings(inputs=("neighbors2",))
    genomes = np.zeros((3, settings.network_size + 2))
    # Radii 100·genome folded into [0, 300]: −100 → 100, 200 → 200, 400 → 200, 50 → 50,
    # 300 → 300, 650 → 50.
    genomes[:, -2:] = [[-1.0, 2.0], [4.0, 0.5], [3.0, 6.5]]
    np.testing.assert_allclose(radii_of(genomes, settings), [[100, 200], [200, 50], [300, 50]])
    free = LearningSettings(inputs=("neighbors2",), radii="unbounded")
    np.testing.assert_allclose(radii_of(genomes, free), [[-100, 200], [400, 50], [300, 650]])


def _run(settings: LearningSettings, generations: int) -> Coevolution:
    run = Coevolution(settings)
    for _ in range(generations):
        run.step()
    return run


def test_same_seed_same_run_and_global_numpy_untouched() -> None:
    # pycma's seed option would reseed numpy's global generator; ours must leave it alone.
    np.random.seed(123)  # noqa: NPY002 - the global generator is what is being checked
    first, second = _run(SMALL, 3), _run(SMALL, 3)
    after = np.random.random()  # noqa: NPY002
    np.random.seed(123)  # noqa: NPY002
    assert after == np.random.random()  # noqa: NPY002
    assert first.history == second.history
    np.testing.assert_array_equal(first.population, second.population)
    other = _run(LearningSettings(models=6, classifiers=5, seed=4), 3)
    assert not np.array_equal(other.population, first.population)


def _resumed(settings: LearningSettings, path: Path, *, before: int, after: int) -> Coevolution:
    """Run ``before`` generations, checkpoint, load, and run ``after`` more."""
    save_checkpoint(_run(settings, before), path)
    resumed = load_checkpoint(path)
    for _ in range(after):
        resumed.step()
    return resumed


def test_resume_continues_exactly(tmp_path: Path) -> None:
    straight = _run(SMALL, 4)
    resumed = _resumed(SMALL, tmp_path / "checkpoint.npz", before=2, after=2)
    assert resumed.history == straight.history
    np.testing.assert_array_equal(resumed.population, straight.population)
    np.testing.assert_array_equal(resumed.best_model(), straight.best_model())


def test_fitness_is_maximised_not_minimised() -> None:
    # With pycma minimising, negated fitness must make classifiers better over generations.
    run = _run(LearningSettings(models=10, classifiers=10, seed=1, inputs=("speed",)), 15)
    early = np.mean([h["classifier_mean"] for h in run.history[:3]])
    late = np.mean([h["classifier_mean"] for h in run.history[-3:]])
    assert late > early


def test_bad_settings_are_explained() -> None:
    with pytest.raises(ValueError, match="classifier inputs must be distinct names"):
        LearningSettings(inputs=("speed", "speed"))
    with pytest.raises(ValueError, match="not both"):
        LearningSettings(inputs=("neighbors", "neighbors2"))
    with pytest.raises(ValueError, match="behavior must be one of"):
        LearningSettings(behavior="schooling")
    with pytest.raises(ValueError, match=r"virulence must be in \(0, 1\], got 0"):
        LearningSettings(virulence=0.0)
    for models, classifiers in ((1, 2), (2, 1)):
        with pytest.raises(ValueError, match="models and classifiers need populations of at"):
            LearningSettings(models=models, classifiers=classifiers)
    for weight in ("nan", "inf", "-1"):
        with pytest.raises(
            ValueError, match=f"soft_weight must be a finite number, 0 or more, got {float(weight)}"
        ):
            LearningSettings(soft_weight=float(weight))


def test_hall_of_fame_keeps_champions_and_resumes_exactly(tmp_path: Path) -> None:
    settings = LearningSettings(models=6, classifiers=5, seed=3, hall_of_fame=2)
    straight = _run(settings, 4)
    assert len(straight.model_champions) == 4
    assert straight.population.shape == (6, 21)
    resumed = _resumed(settings, tmp_path / "checkpoint.npz", before=2, after=2)
    assert resumed.history == straight.history
    # The champions judged beside each generation change every score from the first on.
    without = _run(dataclasses.replace(settings, hall_of_fame=0), 4)
    assert straight.history[0] == without.history[0]  # no champions yet
    assert all(a != b for a, b in zip(straight.history[1:], without.history[1:], strict=True))


def test_a_checkpoint_from_before_a_setting_existed_resumes_as_it_ran(tmp_path: Path) -> None:
    path = tmp_path / "checkpoint.npz"
    save_checkpoint(_run(SMALL, 1), path)
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    meta = json.loads(str(arrays["meta"]))
    for name in ("hall_of_fame", "virulence", "trials", "radius_start"):
        del meta["settings"][name]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)
    settings = load_checkpoint(path).settings
    # Today's defaults are a hall of fame of 10 and virulence 0.75; the run had neither.
    assert (settings.hall_of_fame, settings.virulence, settings.trials) == (0, 1.0, 1)
    assert settings.radius_start is None


def test_a_checkpoint_is_plain_data_and_a_truncated_one_is_explained(tmp_path: Path) -> None:
    path = tmp_path / "checkpoint.npz"
    save_checkpoint(_run(SMALL, 2), path)
    with np.load(path, allow_pickle=False) as data:  # no object arrays: nothing runs on load
        assert {"meta", "told_models", "told_classifiers", "population"} <= set(data.files)
        assert data["told_models"].shape == (2, SMALL.models)
    whole = path.read_bytes()
    path.write_bytes(whole[: len(whole) // 2])
    unreadable = r"not a readable learning checkpoint .*; start afresh with --force instead"
    with pytest.raises(CheckpointError, match=unreadable):
        load_checkpoint(path)
    path.write_bytes(b"\x80\x04K\x01.")  # a pickle is refused, not run
    with pytest.raises(CheckpointError, match="not a readable learning checkpoint"):
        load_checkpoint(path)
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.npz")


def test_a_loaded_checkpoint_is_the_run_as_it_was_saved(tmp_path: Path) -> None:
    path = tmp_path / "checkpoint.npz"
    saved = _run(SMALL, 2)
    save_checkpoint(saved, path)
    loaded = load_checkpoint(path)
    # Before any further generation: the last judgement and the population as they were.
    assert loaded.generation == 2
    np.testing.assert_array_equal(loaded.population, saved.population)
    np.testing.assert_array_equal(loaded.best_model(), saved.best_model())
    assert saved.last_fitness is not None and loaded.last_fitness is not None
    for field in dataclasses.fields(saved.last_fitness):
        np.testing.assert_array_equal(
            getattr(loaded.last_fitness, field.name), getattr(saved.last_fitness, field.name)
        )


def test_a_checkpoint_that_counted_generations_from_0_is_counted_from_1(tmp_path: Path) -> None:
    path = tmp_path / "checkpoint.npz"
    saved = _run(SMALL, 3)
    assert [record["generation"] for record in saved.history] == [1, 2, 3]
    save_checkpoint(saved, path)
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    meta = json.loads(str(arrays["meta"]))
    for number, record in enumerate(meta["history"]):
        record["generation"] = number  # as written before history.csv counted from 1
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)
    loaded = load_checkpoint(path)
    assert [record["generation"] for record in loaded.history] == [1, 2, 3]
    assert loaded.history[2]["model_best"] == saved.history[2]["model_best"]


def _rewritten(path: Path, change: str) -> None:
    """The checkpoint at ``path`` with its metadata changed (``format`` or ``generation``)
    or its classifiers' told scores one generation short (``told_classifiers``)."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    meta = json.loads(str(arrays["meta"]))
    if change == "format":
        meta["format"] = "somebody-elses-checkpoint/1"
    elif change == "generation":
        meta["generation"] += 1
    else:
        arrays[change] = arrays[change][:-1]
    arrays["meta"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ("format", "is not a fishswarm learning checkpoint"),
        ("generation", "the told scores do not cover every generation"),
        ("told_classifiers", "the told scores do not cover every generation"),
    ],
)
def test_a_checkpoint_that_is_not_ours_or_does_not_add_up_is_refused(
    tmp_path: Path, change: str, reason: str
) -> None:
    path = tmp_path / "checkpoint.npz"
    save_checkpoint(_run(SMALL, 2), path)
    _rewritten(path, change)
    with pytest.raises(CheckpointError, match=reason):
        load_checkpoint(path)


def test_a_crash_while_saving_leaves_the_last_checkpoint_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "checkpoint.npz"
    save_checkpoint(_run(SMALL, 1), path)
    before = path.read_bytes()

    def crash(stream: object, **arrays: object) -> None:
        stream.write(b"PK\x03\x04 half a zip")  # type: ignore[attr-defined]
        raise OSError("disk full")

    monkeypatch.setattr("fishswarm.learning.checkpoint.np.savez", crash)
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint(_run(SMALL, 2), path)
    assert path.read_bytes() == before
    assert load_checkpoint(path).generation == 1


def test_reduced_virulence_peaks_at_lambda_and_keeps_the_order_at_one() -> None:
    # λ = 0.75: 2s/λ − s²/λ² is 1 at s = 0.75, and 0.8889 at both 0.5 and 1 (by hand:
    # 1.3333 − 0.4444 and 2.6667 − 1.7778).
    scores = np.array([0.5, 0.75, 1.0])
    np.testing.assert_allclose(reduced_virulence(scores, 0.75), [8 / 9, 1.0, 8 / 9])
    ranked = np.array([0.2, 0.9, 0.5, 1.0])
    full = reduced_virulence(ranked, 1.0)
    assert list(np.argsort(full)) == list(np.argsort(ranked))


def test_a_virulent_classifier_population_is_told_it_overshot() -> None:
    settings = LearningSettings(models=6, classifiers=6, seed=4, virulence=0.6)
    run = Coevolution(settings)
    run.step()
    fitness = run.last_fitness
    assert fitness is not None
    share = (fitness.classifiers + settings.soft_weight * fitness.classifiers_soft) / (
        1 + settings.soft_weight
    )
    np.testing.assert_allclose(run.told_classifiers[0], reduced_virulence(share, 0.6))
    assert np.all(run.told_classifiers[0] <= 1.0)


def test_the_master_tournament_keeps_the_champion_that_fooled_most() -> None:
    plain = Coevolution(LearningSettings(models=5, classifiers=5, seed=6, hall_of_fame=0))
    plain.step()
    np.testing.assert_array_equal(plain.tournament_model(), plain.best_model())
    # Two planted champions: zero weights give direction 0 (a fish at rest); output biases
    # of +50 give direction (1, 1) at full speed (a drifting fish). The classifier calls a
    # fish ideal when its hidden unit sees a low speed: sigmoid(20 h - 10) with
    # h = sigmoid(-20 speed + 5), near 1 at rest and near 0 at full speed.
    settings = LearningSettings(models=4, classifiers=4, seed=6, hall_of_fame=2, inputs=("speed",))
    rest, drift = np.zeros(21), np.zeros(21)
    drift[18:21] = 50.0
    judge = np.zeros(settings.network_size)
    judge[0], judge[5 + 25], judge[5 + 25 + 5], judge[-1] = -20.0, 5.0, 20.0, -10.0
    run = Coevolution(settings)
    run.step()
    run.model_champions = [rest, drift]
    run.classifier_champions = [judge, judge]
    np.testing.assert_array_equal(run.tournament_model(), rest)
    run.model_champions = [drift, rest]
    np.testing.assert_array_equal(run.tournament_model(), rest)

    # The tournament takes the last TOURNAMENT_GENERATIONS champions exactly: the resting
    # one is in when it is the oldest of them, out when one more generation has passed.
    run.model_champions = [rest] + [drift] * (TOURNAMENT_GENERATIONS - 1)
    run.classifier_champions = [judge] * TOURNAMENT_GENERATIONS
    np.testing.assert_array_equal(run.tournament_model(), rest)
    run.model_champions = [rest] + [drift] * TOURNAMENT_GENERATIONS
    run.classifier_champions = [judge] * (TOURNAMENT_GENERATIONS + 1)
    np.testing.assert_array_equal(run.tournament_model(), drift)


def test_each_generations_champions_are_its_best_scoring_model_and_classifier() -> None:
    run = _run(LearningSettings(models=6, classifiers=5, seed=3, hall_of_fame=2), 2)
    # The last generation's population is at hand: its champions are its best rows (its
    # scores differ: no tie to hide a worst-first pick).
    assert np.ptp(run.told_models[-1]) > 0 and np.ptp(run.told_classifiers[-1]) > 0
    np.testing.assert_array_equal(
        run.model_champions[-1], run.population[np.argmax(run.told_models[-1])]
    )
    np.testing.assert_array_equal(
        run.classifier_champions[-1],
        run.classifier_population[np.argmax(run.told_classifiers[-1])],
    )


def test_models_start_again_after_ten_flat_generations_and_a_replay_does_too() -> None:
    settings = LearningSettings(models=4, classifiers=4, seed=8)
    flat = np.full((FLAT_GENERATIONS, 4), 0.25)
    varied = np.random.default_rng(0).uniform(0, 1, (FLAT_GENERATIONS, 4))
    run = Coevolution(settings)
    run.replay(flat[:-1], varied[:-1])
    assert run.model_restarts == 0
    assert np.abs(run._models.mean).max() > 0.1  # the optimiser has moved on
    run = Coevolution(settings)
    run.replay(flat, varied)
    assert run.model_restarts == 1
    # A fresh optimiser, back at zero weights with step 1.
    np.testing.assert_array_equal(run._models.mean, np.zeros(21))
    assert run._models.sigma == 1.0
    after = np.array(run._models.ask())
    again = Coevolution(settings)
    again.replay(flat, varied)
    np.testing.assert_array_equal(np.array(again._models.ask()), after)
    # A single generation with different scores resets the count.
    broken = flat.copy()
    broken[5, 0] = 0.5
    once = Coevolution(settings)
    once.replay(broken, varied)
    assert once.model_restarts == 0


def test_several_starts_a_generation_judge_every_model_on_each(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    settings = LearningSettings(models=6, classifiers=5, seed=3, hall_of_fame=0, trials=2)
    run = Coevolution(settings)
    starts: list[np.ndarray] = []
    judge = Coevolution._judgement

    def recording(self: Coevolution, tracks: np.ndarray, classifiers: np.ndarray) -> np.ndarray:
        starts.append(tracks[:, 0])
        result: np.ndarray = judge(self, tracks, classifiers)
        return result

    monkeypatch.setattr(Coevolution, "_judgement", recording)
    run.step()
    assert len(starts) == 2
    # The first start is the one a run of one trial has; the second another.
    np.testing.assert_array_equal(starts[0], run.trial_start(0, 7))
    np.testing.assert_array_equal(starts[1], run.trial_start(0, 7, 1))
    assert not np.array_equal(starts[0], starts[1])
    monkeypatch.undo()
    # Two starts are not one: the scores told differ; and a run of two resumes exactly.
    two, one = _run(settings, 2), _run(dataclasses.replace(settings, trials=1), 2)
    assert not np.array_equal(np.array(two.told_models), np.array(one.told_models))
    straight = _run(settings, 4)
    resumed = _resumed(settings, tmp_path / "checkpoint.npz", before=2, after=2)
    assert resumed.settings.trials == 2 and resumed.history == straight.history
    with pytest.raises(ValueError, match="trials must be 1 or more, got 0"):
        LearningSettings(trials=0)


def test_classifier_radii_start_where_asked() -> None:
    # The same seed draws the same steps: only the radius genes' starting point moves,
    # by (30 - 150) / 100 before folding.
    counted = ("speed", "neighbors2")  # inputs within two learned radii
    middle = Coevolution(LearningSettings(models=4, classifiers=4, seed=3, inputs=counted))
    short = Coevolution(
        LearningSettings(models=4, classifiers=4, seed=3, inputs=counted, radius_start=30.0)
    )
    middle.step()
    short.step()
    size = middle.settings.network_size
    np.testing.assert_allclose(
        short.classifier_population[:, size:] - middle.classifier_population[:, size:],
        -1.2,
        atol=1e-12,
    )
    np.testing.assert_array_equal(
        short.classifier_population[:, :size], middle.classifier_population[:, :size]
    )
    assert LearningSettings(radii="unbounded").first_radius == 130.0
    with pytest.raises(ValueError, match=r"radius_start must lie in \[0, 300\]"):
        LearningSettings(radius_start=-5.0)
    # The default inputs learn no radius: a start for one would be saved and mean nothing.
    with pytest.raises(ValueError, match="the inputs speed,counts learn none"):
        LearningSettings(radius_start=50.0)
