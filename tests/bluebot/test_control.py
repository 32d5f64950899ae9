"""Controllers: homing reproduces the research code's rules; pid steers the right way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.bluebot.control import PidState, homing, pid


def _homing(target: list[float], dorsal: bool = False) -> tuple[list[float], bool]:
    fins, state = homing(np.array([target]), dorsal_on=np.array([dorsal]))
    return fins[0].tolist(), bool(state[0])


def test_homing_straight_ahead_runs_caudal_by_distance() -> None:
    # 0.52 m ahead: caudal = 0.1 + 0.52/(8·0.13) = 0.6; no pectorals.
    fins, _ = _homing([0.52, 0.0, 0.0])
    assert fins == pytest.approx([0.6, 0.0, 0.0, 0.0])
    fins, _ = _homing([5.0, 0.0, 0.0])
    assert fins[0] == 1.0


def test_homing_target_right_drives_left_pectoral() -> None:
    # Bearing 45° right: left pectoral at 0.6 + 45/180 = 0.85, caudal off (|h| ≥ 20°).
    fins, _ = _homing([1.0, 1.0, 0.0])
    assert fins == pytest.approx([0.0, 0.0, 0.85, 0.0])
    fins, _ = _homing([1.0, -1.0, 0.0])
    assert fins == pytest.approx([0.0, 0.0, 0.0, 0.85])
    fins, _ = _homing([-1.0, 0.01, 0.0])
    assert fins[2] == 1.0


def test_homing_depth_bang_bang_with_band() -> None:
    below = math.tan(math.radians(2.0))
    within = math.tan(math.radians(0.5))
    assert _homing([1.0, 0.0, below])[1] is True
    assert _homing([1.0, 0.0, -below], dorsal=True)[1] is False
    assert _homing([1.0, 0.0, within], dorsal=True)[1] is True
    assert _homing([1.0, 0.0, within], dorsal=False)[1] is False


def test_pid_turns_towards_the_target_and_holds_depth_against_buoyancy() -> None:
    fins, state = pid(
        np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]), state=PidState.zeros(2), period=1.0
    )
    assert fins[0, 2] > 0 and fins[0, 3] == 0
    assert fins[1, 0] > 0 and fins[1, 2] == 0 and fins[1, 3] == 0
    assert fins[1, 1] == pytest.approx(0.5)
    assert np.all((fins >= 0) & (fins <= 1))
    assert state.integral.shape == (2, 3)


def test_batch_equals_loop_for_homing() -> None:
    rng = np.random.default_rng(5)
    targets = rng.normal(0, 1, (9, 3))
    dorsal = rng.uniform(size=9) > 0.5
    fins, new = homing(targets, dorsal_on=dorsal)
    for i in range(9):
        one, state = homing(targets[i : i + 1], dorsal_on=dorsal[i : i + 1])
        np.testing.assert_array_equal(one[0], fins[i])
        assert state[0] == new[i]


def test_study_codes_homing_turns_a_target_dead_ahead_or_none_to_the_right_pectoral() -> None:
    # The study's code: bearing > 0 → left pectoral, else (0 included) → right pectoral at
    # 0.6 + |h|/180 = 0.6. The caudal rule is the same in both.
    for target, caudal in (
        ([0.52, 0.0, 0.0], 0.6),
        ([0.0, 0.0, 0.0], 0.1),
        ([0.52, -0.0, 0.0], 0.6),
    ):
        paper, _ = homing(np.array([target]), dorsal_on=np.array([False]))
        study, _ = homing(np.array([target]), dorsal_on=np.array([False]), right_when_ahead=True)
        assert paper[0].tolist() == pytest.approx([caudal, 0.0, 0.0, 0.0])
        assert study[0].tolist() == pytest.approx([caudal, 0.0, 0.0, 0.6])
    # Off the axis both agree: a target 45° right drives the left pectoral at 0.85.
    for right_when_ahead in (False, True):
        fins, _ = homing(
            np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0]]),
            dorsal_on=np.array([False, False]),
            right_when_ahead=right_when_ahead,
        )
        np.testing.assert_allclose(fins, [[0.0, 0.0, 0.85, 0.0], [0.0, 0.0, 0.0, 0.85]])


@pytest.mark.parametrize("period", [0.0, np.array([0.5, 0.0])])
def test_pid_refuses_a_period_that_is_no_time(period: float) -> None:
    with pytest.raises(ValueError, match="period must be positive"):
        pid(np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), state=PidState.zeros(2), period=period)


def test_at_the_edges_of_its_bands_homing_keeps_the_dorsal_and_stops_the_caudal() -> None:
    """Bands of 45° (for exact bearings): a target exactly 45° above leaves a dorsal fin
    that was on, on (off only beyond the band); one exactly 45° aside is outside the caudal
    band (it runs only within)."""
    above = np.array([[1.0, 0.0, -1.0]])
    _, dorsal = homing(above, dorsal_on=np.array([True]), pitch_band_deg=45.0)
    assert dorsal.tolist() == [True]
    aside = np.array([[1.0, 1.0, 0.0]])
    fins, _ = homing(aside, dorsal_on=np.array([False]), heading_band_deg=45.0)
    assert fins[0, 0] == 0.0 and fins[0, 2] == pytest.approx(0.85)
