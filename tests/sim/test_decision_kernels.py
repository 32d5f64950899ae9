"""The compiled Lennard-Jones loop against the numpy path, bit for bit, and who takes it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fishswarm.behaviors.core import FishParams
from fishswarm.behaviors.lennard_jones import (
    MIN_DISTANCE,
    STUDY_GAIN,
    lennard_jones,
)
from fishswarm.bluebot.parameters import BODY_LENGTH
from fishswarm.sim import decision_kernels, kernels
from fishswarm.sim.decision_kernels import (
    lennard_jones_target_vectors,
    prepare,
    with_compiled_decisions,
)
from fishswarm.sim.engine import simulate_batch
from fishswarm.sim.scenario import Scenario

needs_numba = pytest.mark.skipif(not kernels.available(), reason="numba is not installed")


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool((a.view(np.int64) == b.view(np.int64)).all())


def _school(seed: int, fish: int, rows: int, coincident: bool) -> tuple[np.ndarray, np.ndarray]:
    """A padded batch as the fish core builds one: each fish's neighbours first, zero rows
    after; some fish see nobody; some neighbours (``coincident``) at the fish's own place."""
    rng = np.random.default_rng(seed)
    seen = rng.integers(0, rows + 1, fish)
    mask = np.arange(rows)[None, :] < seen[:, None]
    scale = rng.choice([0.01, 0.3, 2.0], size=(fish, rows, 1))  # near, around r_t, far
    neighbors = np.where(mask[..., None], rng.normal(0.0, 1.0, (fish, rows, 3)) * scale, 0.0)
    if coincident:
        neighbors[rng.random((fish, rows)) < 0.1] = 0.0
    return neighbors, mask


@needs_numba
@settings(max_examples=80, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    fish=st.integers(1, 40),
    rows=st.integers(1, 30),
    target_distance=st.sampled_from([0.26, 1.0, 2.517]),
    epsilon=st.sampled_from([1.0, 0.26**2 / 72]),
    cap=st.sampled_from([BODY_LENGTH, 0.02, 1.5]),
    study_form=st.booleans(),
    coincident=st.booleans(),
)
def test_the_compiled_loop_equals_the_numpy_path_bit_for_bit(
    seed: int,
    fish: int,
    rows: int,
    target_distance: float,
    epsilon: float,
    cap: float,
    study_form: bool,
    coincident: bool,
) -> None:
    neighbors, mask = _school(seed, fish, rows, coincident)
    expected, got = (
        lennard_jones(
            neighbors,
            mask,
            target_distance=target_distance,
            epsilon=epsilon,
            cap=cap,
            study_form=study_form,
            compiled=compiled,
        )
        for compiled in (None, lennard_jones_target_vectors)
    )
    assert _same_bits(got, expected)


@needs_numba
@pytest.mark.parametrize("study_form", [False, True])
def test_a_large_school_decides_as_the_numpy_path_and_as_each_fish_alone(
    study_form: bool,
) -> None:
    # Over several of the numpy path's blocks (and its neighbour-by-neighbour sum): the
    # compiled loop gives the numpy path's bits, and each fish's row is the fish deciding
    # alone on the numpy path, as a robot's fish would.
    neighbors, mask = _school(5, 2 * 1024 + 37, 46, coincident=True)
    together, numpy_path = (
        lennard_jones(
            neighbors, mask, target_distance=0.26, study_form=study_form, compiled=compiled
        )
        for compiled in (lennard_jones_target_vectors, None)
    )
    assert _same_bits(together, numpy_path)
    for fish in range(0, neighbors.shape[0], 97):
        seen = int(mask[fish].sum())
        alone = lennard_jones(
            neighbors[fish : fish + 1, :seen], mask[fish : fish + 1, :seen],
            target_distance=0.26, study_form=study_form,
        )  # fmt: skip
        assert _same_bits(together[fish], alone[0])
    lonely = mask.sum(axis=1) == 0
    assert lonely.any() and not np.signbit(together[lonely]).any()  # +0.0, as the numpy path


@needs_numba
def test_one_neighbour_by_hand() -> None:
    # A neighbour 0.13 m ahead, r_t 0.26, ε 1: ratio 2, −dV/dr = 12/0.13·(2¹² − 2⁶) ≈ 372 185
    # pushes the fish back along x (the one neighbour's direction, averaged over one); a
    # second fish sees it and a padding row: the mean is over the one real neighbour.
    neighbors = np.array([[[0.13, 0.0, 0.0], [0.0, 0.0, 0.0]]] * 2)
    mask = np.array([[True, False], [True, False]])
    result = lennard_jones_target_vectors(
        neighbors,
        mask,
        target_distance=0.26,
        epsilon=1.0,
        cap=BODY_LENGTH,
        floor=MIN_DISTANCE,
        study_form=False,
    )
    np.testing.assert_allclose(result[:, 0], -12.0 / 0.13 * (2.0**12 - 2.0**6), rtol=1e-12)
    np.testing.assert_array_equal(result[:, 1:], 0.0)


@needs_numba
@pytest.mark.parametrize("compiled", [None, lennard_jones_target_vectors])
def test_the_study_form_floors_distances_at_a_micrometre(compiled: object) -> None:
    # A neighbour 0.5 mm ahead, within the paper's 1 mm floor but above the study's 1 µm:
    # the study's force at the distance itself, times the relative position (SPEC §8).
    distance, target = 5e-4, 0.26
    ratio = target / distance
    force = 12.0 * STUDY_GAIN / distance * (ratio**12 - ratio**6)
    result = lennard_jones(
        np.array([[[distance, 0.0, 0.0]]]),
        np.ones((1, 1), dtype=bool),
        target_distance=target,
        study_form=True,
        compiled=compiled,  # type: ignore[arg-type]
    )
    np.testing.assert_allclose(result[0], [-force * distance, 0.0, 0.0], rtol=1e-12)


@needs_numba
def test_mismatched_shapes_are_refused() -> None:
    with pytest.raises(ValueError, match="neighbors must be"):
        lennard_jones_target_vectors(
            np.zeros((3, 2, 3)),
            np.ones((3, 4), dtype=bool),
            target_distance=0.26,
            epsilon=1.0,
            cap=BODY_LENGTH,
            floor=MIN_DISTANCE,
            study_form=False,
        )


def _steering(params: FishParams) -> object:
    return getattr(params.steering, "compiled", "no such field")


def test_a_simulated_swarm_of_200_fish_or_more_decides_with_the_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(kernels, "available", lambda: True)
    large = kernels.COMPILED_MIN_FISH
    for behavior in ("dispersion", "aggregation"):
        params = Scenario(fish=large, behavior=behavior).fish_params()
        assert _steering(with_compiled_decisions(params, large)) is lennard_jones_target_vectors
        assert _steering(with_compiled_decisions(params, large - 1)) is None
        # What a robot's fish is given (fishswarm robot) never has it, whatever the swarm.
        assert _steering(params) is None
    orbit = Scenario(fish=large, behavior="orbit").fish_params()
    assert with_compiled_decisions(orbit, large) is orbit  # not a Lennard-Jones behaviour


def test_without_numba_a_large_swarm_decides_with_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(kernels, "available", lambda: False)
    large = kernels.COMPILED_MIN_FISH
    params = with_compiled_decisions(Scenario(fish=large).fish_params(), large)
    assert _steering(params) is None


def test_the_parameters_with_the_loop_travel_to_a_worker_process(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A fish worker gets its parameters pickled (spawn): the loop goes by name.
    import pickle

    monkeypatch.setattr(kernels, "available", lambda: True)
    large = kernels.COMPILED_MIN_FISH
    params = with_compiled_decisions(Scenario(fish=large).fish_params(), large)
    again = pickle.loads(pickle.dumps(params))
    assert _steering(again) is lennard_jones_target_vectors


def test_prepare_runs_the_loop_once_and_leaves_numpy_fish_alone() -> None:
    calls: list[tuple[int, ...]] = []

    def loop(neighbors: np.ndarray, mask: np.ndarray, **options: object) -> np.ndarray:
        calls.append(neighbors.shape)
        return np.zeros((neighbors.shape[0], 3))

    params = Scenario(fish=3).fish_params()
    prepare(params)
    assert calls == []
    steering = dataclasses.replace(params.steering, compiled=loop)
    prepare(dataclasses.replace(params, steering=steering))
    assert calls == [(1, 1, 3)]


@needs_numba
def test_the_batch_engine_of_a_large_swarm_decides_with_the_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls: list[int] = []
    original = decision_kernels.lennard_jones_target_vectors

    def spy(neighbors: np.ndarray, mask: np.ndarray, **options: object) -> np.ndarray:
        calls.append(neighbors.shape[0])
        return original(neighbors, mask, **options)  # type: ignore[arg-type]

    monkeypatch.setattr(decision_kernels, "lennard_jones_target_vectors", spy)
    simulate_batch(Scenario.crowded(kernels.COMPILED_MIN_FISH, duration=2.0, seed=1))
    assert calls and set(calls) == {kernels.COMPILED_MIN_FISH}
