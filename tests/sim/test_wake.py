"""Wake shelter on drawn cases."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.bluebot.dynamics import State
from fishswarm.sim.wake import wake_shelter


def _fish(*rows: tuple[float, float, float, float, float]) -> State:
    """Fish as (x, y, z, yaw, forward speed through the water)."""
    table = np.array(rows, dtype=np.float64)
    velocity = np.zeros((table.shape[0], 3))
    velocity[:, 0] = table[:, 4]
    return State(table[:, :3], table[:, 3], velocity, np.zeros(table.shape[0]))


def test_shelter_behind_a_swimming_fish_drawn_on_paper() -> None:
    # Fish 0 at (1, 1, 0.5) swims along +x. Fish 1 is 0.3 m behind it and 0.1 m to the
    # side: (1 − 0.3/0.6)·(1 − 0.1/0.2) = 0.25. Fish 2 is ahead of it: nothing. Fish 3 is
    # straight behind fish 1 at 0.15 m: from fish 1, (1 − 0.25)·1 = 0.75; from fish 0 (0.45
    # m behind, 0.1 off), 0.25·0.5 = 0.125; the better counts. Fish 4 is 0.25 m off the
    # axis: outside the wake.
    fish = _fish(
        (1.0, 1.0, 0.5, 0.0, 0.1),
        (0.7, 1.1, 0.5, 0.0, 0.1),
        (1.4, 1.0, 0.5, 0.0, 0.1),
        (0.55, 1.1, 0.5, 0.0, 0.1),
        (0.8, 1.25, 0.5, 0.0, 0.1),
    )
    shelter = wake_shelter(fish, length=0.6, width=0.2)
    # Fish 0 sits 0.4 m behind fish 2 on its axis: 1 − 0.4/0.6.
    np.testing.assert_allclose(shelter, [1 / 3, 0.25, 0.0, 0.75, 0.0], atol=1e-12)


def test_a_fish_that_does_not_swim_forward_leaves_no_wake_and_depth_counts() -> None:
    # Fish 0 heads +y and drifts backwards; fish 1 sits 0.2 m behind it.
    drifting = _fish((1.0, 1.0, 0.5, np.pi / 2, -0.02), (1.0, 0.8, 0.5, np.pi / 2, 0.05))
    np.testing.assert_array_equal(wake_shelter(drifting, length=0.6, width=0.2), [0.0, 0.0])
    # Swimming forward, fish 1 gets (1 − 0.2/0.6) = 2/3; 0.1 m deeper, half of that.
    swimming = _fish((1.0, 1.0, 0.5, np.pi / 2, 0.05), (1.0, 0.8, 0.6, np.pi / 2, 0.05))
    np.testing.assert_allclose(
        wake_shelter(swimming, length=0.6, width=0.2), [0.0, (2 / 3) * 0.5], atol=1e-12
    )
    assert wake_shelter(_fish((1.0, 1.0, 0.5, 0.0, 0.1)), length=0.6, width=0.2).tolist() == [0]
    with pytest.raises(ValueError, match="positive length and width"):
        wake_shelter(swimming, length=0.0, width=0.2)


def test_a_fish_at_rest_casts_no_wake() -> None:
    # Fish 1 sits 0.2 m straight behind fish 0, which is not moving through the water.
    resting = _fish((1.0, 1.0, 0.5, 0.0, 0.0), (0.8, 1.0, 0.5, 0.0, 0.1))
    np.testing.assert_array_equal(wake_shelter(resting, length=0.6, width=0.2), [0.0, 0.0])


def test_a_fish_abreast_of_another_is_not_in_its_wake() -> None:
    # Fish 1 is level with fish 0, 0.1 m to its side: 0 m behind it, so outside the wake
    # (were it inside, it would get 1 − 0.1/0.2 = 0.5). Fish 2 sits on fish 0 itself.
    abreast = _fish((1.0, 1.0, 0.5, 0.0, 0.1), (1.0, 1.1, 0.5, 0.0, 0.1), (1.0, 1.0, 0.5, 0.0, 0.1))
    np.testing.assert_array_equal(wake_shelter(abreast, length=0.6, width=0.2), [0.0, 0.0, 0.0])
