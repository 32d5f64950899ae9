"""Lennard-Jones forces: signs, magnitudes and the averaging over neighbours."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.behaviors.lennard_jones import lennard_jones, lennard_jones_force


def test_force_is_zero_at_the_target_distance_and_changes_sign() -> None:
    assert lennard_jones_force(np.array(0.26), target_distance=0.26, epsilon=1.0) == 0.0
    assert lennard_jones_force(np.array(0.2), target_distance=0.26, epsilon=1.0) > 0
    assert lennard_jones_force(np.array(0.3), target_distance=0.26, epsilon=1.0) < 0


def test_force_magnitude_by_hand() -> None:
    # r = r_t/2: −dV/dr = 12ε/r·(2¹² − 2⁶) = 12·1/0.5·4032 = 96768 for r_t = 1.
    value = lennard_jones_force(np.array(0.5), target_distance=1.0, epsilon=1.0)
    assert float(value) == pytest.approx(96768.0)


def test_near_neighbour_repels_far_one_attracts() -> None:
    neighbors = np.array([[[0.1, 0.0, 0.0]], [[1.0, 0.0, 0.0]]])
    mask = np.ones((2, 1), dtype=bool)
    result = lennard_jones(neighbors, mask, target_distance=0.26)
    assert result[0, 0] < 0  # neighbour ahead and too close: move back
    assert result[1, 0] > 0  # neighbour ahead and far: move towards it
    np.testing.assert_array_equal(result[:, 1:], 0.0)


def test_vector_magnitude_by_hand() -> None:
    # One neighbour 0.39 m ahead (= r_t + 1 body length), ε = 1, r_t = 0.26:
    # −dV/dr = 12/0.39·(0.0077073 − 0.0877915) = −2.4641 → 2.4641 m towards it.
    result = lennard_jones(
        np.array([[[0.39, 0.0, 0.0]]]), np.ones((1, 1), bool), target_distance=0.26
    )
    ratio6 = (0.26 / 0.39) ** 6
    expected = -12.0 / 0.39 * (ratio6**2 - ratio6)
    assert result[0, 0] == pytest.approx(expected)
    assert result[0, 0] == pytest.approx(2.4641, abs=1e-4)


def test_far_distances_are_capped() -> None:
    mask = np.ones((1, 1), bool)
    near_cap = lennard_jones(np.array([[[0.39, 0, 0]]]), mask, target_distance=0.26)
    far = lennard_jones(np.array([[[2.5, 0, 0]]]), mask, target_distance=0.26)
    np.testing.assert_allclose(near_cap, far)


def test_contributions_are_averaged_and_padding_ignored() -> None:
    neighbors = np.array([[[0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [9.0, 9.0, 9.0]]])
    mask = np.array([[True, True, False]])
    result = lennard_jones(neighbors, mask, target_distance=0.26, epsilon=1.0)
    single = lennard_jones(neighbors[:, :1], mask[:, :1], target_distance=0.26, epsilon=1.0)
    assert result[0, 0] == pytest.approx(single[0, 0] / 2)
    assert result[0, 1] == pytest.approx(single[0, 0] / 2)


def test_lonely_and_coincident_fish_stay_finite() -> None:
    result = lennard_jones(np.zeros((2, 1, 3)), np.array([[False], [True]]), target_distance=2.5)
    np.testing.assert_array_equal(result, 0.0)


def _study(neighbors: list[list[float]], target_distance: float) -> np.ndarray:
    result = lennard_jones(
        np.array([neighbors]),
        np.ones((1, len(neighbors)), bool),
        target_distance=target_distance,
        study_form=True,
    )
    row: np.ndarray = result[0]
    return row


def test_study_form_repulsion_by_hand() -> None:
    # One neighbour at r = r_t/2 = 0.13 m ahead: f = −(γε/r)·12·(2¹² − 2⁶) with γε = 10 m
    # (100·100 in mm), times the relative position itself (0.13 m):
    # −10·12·4032 = −483 840 m along x.
    assert _study([[0.13, 0.0, 0.0]], 0.26) == pytest.approx([-483_840.0, 0.0, 0.0], rel=1e-12)


def test_study_form_floors_distances_at_a_micrometre_not_a_millimetre() -> None:
    # As above at a thousandth of the scale: r = 0.1 mm, r_t = 0.2 mm, ratio 2 again, so
    # the same −483 840 m. Floored at the paper form's millimetre instead, the ratio would
    # be 0.2 and the neighbour would attract (+7.7e-4 m).
    assert _study([[1e-4, 0.0, 0.0]], 2e-4) == pytest.approx([-483_840.0, 0.0, 0.0], rel=1e-9)


def test_a_target_distance_of_zero_or_less_is_refused() -> None:
    for target in (0.0, -0.26):
        with pytest.raises(ValueError, match="target_distance must be positive"):
            lennard_jones(np.ones((1, 1, 3)), np.ones((1, 1), bool), target_distance=target)


def test_study_form_attraction_is_capped_but_grows_with_the_offset() -> None:
    # 0.5 m to the right, r_t = 0.26: r is capped at r_t + 1 body length = 0.39, ratio 2/3:
    # (2/3)¹² − (2/3)⁶ = (4096 − 46656)/531441 = −42560/531441, so
    # f·Δy = (10/0.39)·12·(42560/531441)·0.5 = 12.3206 m towards it.
    expected = 10 / 0.39 * 12 * 42560 / 531441 * 0.5
    assert expected == pytest.approx(12.3206, abs=1e-4)
    assert _study([[0.0, 0.5, 0.0]], 0.26) == pytest.approx([0.0, expected, 0.0], rel=1e-12)
    # Twice as far: the same capped force times twice the offset (the paper's form would
    # give the same vector for both).
    assert _study([[0.0, 1.0, 0.0]], 0.26)[1] == pytest.approx(2 * expected, rel=1e-12)
    paper = lennard_jones(
        np.array([[[0.0, 0.5, 0.0]], [[0.0, 1.0, 0.0]]]),
        np.ones((2, 1), bool),
        target_distance=0.26,
    )
    np.testing.assert_allclose(paper[0], paper[1])
    # Both neighbours: the mean of the two vectors.
    both = _study([[0.13, 0.0, 0.0], [0.0, 0.5, 0.0]], 0.26)
    assert both == pytest.approx([-483_840.0 / 2, expected / 2, 0.0], rel=1e-12)


def test_study_form_equals_the_study_codes_millimetre_arithmetic() -> None:
    # The study's lj_force in its own units (mm, γ = ε = 100, r clipped to
    # [0.001, r_t + 130] mm), averaged; ours in metres is its result / 1000.
    rng = np.random.default_rng(3)
    for _ in range(20):
        neighbors = rng.uniform(-1.5, 1.5, (6, 3))
        target_distance = float(rng.choice([0.26, 2.517]))
        centre = np.zeros(3)
        for offset in neighbors * 1000:
            r = np.clip(np.linalg.norm(offset), 0.001, target_distance * 1000 + 130)
            ratio = target_distance * 1000 / r
            centre += -100 * 100 / r * (12 * ratio**12 - 2 * 6 * ratio**6) * offset
        centre /= len(neighbors)
        ours = _study(neighbors.tolist(), target_distance)
        np.testing.assert_allclose(ours, centre / 1000, rtol=1e-10)


def test_a_large_batch_sums_neighbours_as_each_fish_alone_does() -> None:
    from fishswarm.behaviors.lennard_jones import RUNNING_SUM_LOOP_MIN

    # A batch large enough to be summed neighbour by neighbour, padded with zero rows as
    # batches are, some fish seeing nobody: every row equals the fish deciding alone, bit
    # for bit.
    rng = np.random.default_rng(8)
    count, rows = RUNNING_SUM_LOOP_MIN + 72, 30
    seen = rng.integers(0, rows + 1, count)
    mask = np.arange(rows)[None, :] < seen[:, None]
    neighbors = np.where(mask[..., None], rng.normal(0.0, 0.4, (count, rows, 3)), 0.0)
    together = lennard_jones(neighbors, mask, target_distance=0.26)
    for fish in range(count):
        alone = lennard_jones(
            neighbors[fish : fish + 1, : seen[fish]], mask[fish : fish + 1, : seen[fish]],
            target_distance=0.26,
        )  # fmt: skip
        np.testing.assert_array_equal(together[fish], alone[0])
    assert not np.signbit(together[seen == 0]).any()  # +0.0, not −0.0, for the lonely


@pytest.mark.parametrize("study_form", [False, True])
def test_a_batch_of_several_blocks_decides_as_each_fish_alone(study_form: bool) -> None:
    from fishswarm.behaviors.lennard_jones import BLOCK_FISH

    # Two whole blocks and a part: the blocks' rows come back in order, bit for bit as each
    # fish deciding alone (a block smaller than the running-sum threshold included).
    rng = np.random.default_rng(9)
    count, rows = 2 * BLOCK_FISH + 37, 12
    seen = rng.integers(0, rows + 1, count)
    mask = np.arange(rows)[None, :] < seen[:, None]
    neighbors = np.where(mask[..., None], rng.normal(0.0, 0.4, (count, rows, 3)), 0.0)
    together = lennard_jones(neighbors, mask, target_distance=0.26, study_form=study_form)
    assert together.shape == (count, 3)
    for fish in range(count):
        alone = lennard_jones(
            neighbors[fish : fish + 1, : seen[fish]], mask[fish : fish + 1, : seen[fish]],
            target_distance=0.26, study_form=study_form,
        )  # fmt: skip
        np.testing.assert_array_equal(together[fish], alone[0])


def test_no_fish_at_all_get_no_motion() -> None:
    assert lennard_jones(
        np.zeros((0, 4, 3)), np.zeros((0, 4), bool), target_distance=0.26
    ).shape == (0, 3)


@pytest.mark.parametrize("distance", [0.0, -0.3, float("nan")])
def test_a_target_distance_that_is_no_length_is_refused(distance: float) -> None:
    from fishswarm.behaviors.lennard_jones import LennardJonesParams

    with pytest.raises(ValueError, match="target_distance must be positive"):
        LennardJonesParams(target_distance=distance)
