"""The fisheye model: pixels to rays and back, and where the cameras look."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fishswarm.bluebot.fisheye import Fisheye, camera_position, camera_to_body
from fishswarm.bluebot.parameters import FisheyeCalibration

FISHEYE = Fisheye()


def test_the_image_centre_looks_along_the_optical_axis() -> None:
    centre = np.array(FisheyeCalibration().center) / FISHEYE.scale
    ray = FISHEYE.pixel_to_ray(centre[None, :])[0]
    np.testing.assert_allclose(ray, [0.0, 0.0, 1.0], atol=1e-12)


def test_a_point_500_full_resolution_pixels_out_looks_49_degrees_off_axis() -> None:
    # By hand: f(500) = −550.632 + 4.1997e-4·500² − 3.65763e-8·500³ + 2.906e-10·500⁴
    # = −432.05, so the ray leaves the axis at atan2(500, 432.05) = 49.17°.
    centre = np.array(FisheyeCalibration().center)
    pixel = (centre + np.array([0.0, 500.0])) / FISHEYE.scale
    ray = FISHEYE.pixel_to_ray(pixel[None, :])[0]
    angle = math.degrees(math.atan2(math.hypot(ray[0], ray[1]), ray[2]))
    assert angle == pytest.approx(49.17, abs=0.01)
    assert ray[1] > 0 and abs(ray[0]) < 1e-3  # along the columns


# Pixels at least 0.1 px inside the image's edge (−0.5 and size − 0.5): a pixel on the edge
# itself can come back a rounding error outside it, and then counts as not in the image.
@settings(max_examples=300, deadline=None)
@given(
    row=st.floats(min_value=-0.4, max_value=191.4),
    column=st.floats(min_value=-0.4, max_value=255.4),
)
def test_pixel_to_ray_to_pixel_returns_within_a_tenth_of_a_pixel(row: float, column: float) -> None:
    pixel = np.array([[row, column]])
    back, inside = FISHEYE.ray_to_pixel(FISHEYE.pixel_to_ray(pixel))
    angle = math.degrees(math.acos(np.clip(FISHEYE.pixel_to_ray(pixel)[0, 2], -1.0, 1.0)))
    assert inside[0] == (angle <= FisheyeCalibration().half_angle_deg)
    if inside[0]:
        assert np.abs(back - pixel).max() < 0.1


def test_rays_behind_the_lens_edge_do_not_reach_the_image() -> None:
    _, inside = FISHEYE.ray_to_pixel(
        np.array([[0.0, 0.0, -1.0], [0.0, 1.0, -0.5], [0.0, 1.0, 0.0]])
    )
    assert inside.tolist() == [False, False, True]


def test_the_cameras_look_sideways_ten_degrees_ahead_with_rows_pointing_down() -> None:
    right, left = camera_to_body("right"), camera_to_body("left")
    axis = math.radians(80)
    np.testing.assert_allclose(right @ [0, 0, 1], [math.cos(axis), math.sin(axis), 0], atol=1e-12)
    np.testing.assert_allclose(left @ [0, 0, 1], [math.cos(axis), -math.sin(axis), 0], atol=1e-12)
    np.testing.assert_allclose(right @ [1, 0, 0], [0, 0, 1], atol=1e-12)
    # Columns run from the front to the back on the right camera, back to front on the left.
    assert (right @ [0, 1, 0])[0] < 0 < (left @ [0, 1, 0])[0]
    np.testing.assert_allclose(camera_position("left"), [0.025, -0.020, 0.0])


def test_a_calibration_that_never_reaches_the_lens_edge_is_refused() -> None:
    with pytest.raises(ValueError, match="half angle"):
        Fisheye(FisheyeCalibration(polynomial=(-550.0, 0.0, 0.0), half_angle_deg=100.0))


@pytest.mark.parametrize(("width", "height"), [(0, 192), (256, 0), (-4, 192)])
def test_an_image_with_no_pixels_is_refused(width: int, height: int) -> None:
    with pytest.raises(ValueError, match="image size must be positive"):
        Fisheye(width=width, height=height)
