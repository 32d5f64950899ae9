"""Animation helpers: interpolation between snapshots and the fish's-eye geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fishswarm.bluebot.vision import Vision
from fishswarm.study.animation import AnimationError, eye_view, frames_per_step, interpolate


def test_interpolation_is_linear_and_turns_the_short_way() -> None:
    t = np.array([0.0, 1.0])
    position = np.array([[[0.0, 0.0, 0.5]], [[1.0, 2.0, 0.5]]])
    yaw = np.array([[math.radians(170)], [math.radians(-170)]])
    frames = interpolate(t, position, yaw, np.array([4]), per_step=4)
    np.testing.assert_allclose(frames.t, [0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(frames.position[2, 0], [0.5, 1.0, 0.5])
    # Halfway from 170° to −170° the short way is 180°, not 0°.
    assert abs(math.cos(frames.yaw[2, 0]) + 1) < 1e-12
    assert frames.position.shape == (5, 1, 3)
    with pytest.raises(AnimationError, match="at least 1"):
        interpolate(t, position, yaw, np.array([4]), per_step=0)


def test_frames_per_step_plays_at_the_asked_speed() -> None:
    assert frames_per_step(10, 1.0, 2.0) == 5
    assert frames_per_step(10, 1.0, 100.0) == 1


def test_eye_view_by_hand() -> None:
    # The viewer at (1, 1, 1) faces +x. One neighbour 1 m ahead and 1 m higher (z down),
    # one 1 m to its right (+y), one 1 m straight behind (in the blind spot).
    position = np.array([[1.0, 1.0, 1.0], [2.0, 1.0, 0.0], [1.0, 2.0, 1.0], [0.0, 1.0, 1.0]])
    yaw = np.zeros(4)
    bearing, elevation, distance = eye_view(position, yaw, 0, Vision(sphere_radius=0.0))
    order = np.argsort(bearing)
    np.testing.assert_allclose(bearing[order], [0.0, 90.0], atol=1e-9)
    np.testing.assert_allclose(elevation[order], [45.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(distance[order], [math.sqrt(2), 1.0])
