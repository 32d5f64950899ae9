"""The LED pipeline: vertical pairs, mirror images, robots seen from above, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.leds import FrameUnusable, LedVision, pair_leds, perceive_leds
from fishswarm.bluebot.parameters import LED_SPACING

VISION = LedVision()


def rays_to(origin: np.ndarray, points: list[np.ndarray]) -> np.ndarray:
    offsets = np.array(points) - origin
    rays: np.ndarray = offsets / np.linalg.norm(offsets, axis=1, keepdims=True)
    return rays


def lit(origin: np.ndarray, points: list[np.ndarray]) -> np.ndarray:
    """Each LED's blob brightness as the calibration expects it at its distance."""
    distance = np.linalg.norm(np.array(points) - origin, axis=1)
    fluxes: np.ndarray = VISION.flux_range / distance
    return fluxes


def pair_at(middle: np.ndarray) -> list[np.ndarray]:
    half = np.array([0.0, 0.0, LED_SPACING / 2])
    return [middle + half, middle - half]


def mirrored(point: np.ndarray, depth: float) -> np.ndarray:
    # The surface lies at z = −depth in the frame of a fish at ``depth``.
    return np.array([point[0], point[1], -2.0 * depth - point[2]])


def test_a_vertical_pair_gives_its_midpoint() -> None:
    origin = np.array([0.025, 0.02, 0.0])
    middle = np.array([0.4, 0.9, 0.15])
    rays = rays_to(origin, pair_at(middle))
    found = pair_leds(origin, rays, lit(origin, pair_at(middle)), depth=0.5, vision=VISION)
    np.testing.assert_allclose(found, [middle], atol=1e-9)


def test_mirror_images_and_the_front_led_are_not_fish() -> None:
    origin = np.zeros(3)
    depth = 0.4
    middle = np.array([1.2, 0.3, -0.25])  # 0.15 m below the surface
    lower, upper = pair_at(middle)
    front = upper + np.array([LED_SPACING * np.cos(0.7), LED_SPACING * np.sin(0.7), 0.0])
    points = [lower, upper, front, mirrored(lower, depth), mirrored(upper, depth)]
    points.append(mirrored(front, depth))
    rays = rays_to(origin, points)
    found = pair_leds(origin, rays, lit(origin, points), depth=depth, vision=VISION)
    np.testing.assert_allclose(found, [middle], atol=1e-9)


def test_a_robot_just_below_the_surface_is_not_paired_with_its_mirror_image() -> None:
    # Its upper LED lies 0.03 m below the surface, so its mirror image is nearer to it (0.06 m)
    # than its lower LED is (0.086 m).
    origin = np.zeros(3)
    depth = 0.6
    middle = np.array([1.1, 0.75, -0.6 + 0.073])
    lower, upper = pair_at(middle)
    points = [lower, upper, mirrored(upper, depth), mirrored(lower, depth)]
    rays = rays_to(origin, points)
    found = pair_leds(origin, rays, lit(origin, points), depth=depth, vision=VISION)
    np.testing.assert_allclose(found, [middle], atol=1e-9)


def test_mirror_images_alone_are_nothing() -> None:
    origin = np.zeros(3)
    depth = 0.3
    lower, upper = pair_at(np.array([0.8, -0.4, 0.1]))
    images = [mirrored(lower, depth), mirrored(upper, depth)]
    rays = rays_to(origin, images)
    found = pair_leds(origin, rays, lit(origin, images), depth=depth, vision=VISION)
    assert found.shape == (0, 3)


def test_blobs_of_very_different_brightness_are_not_a_pair() -> None:
    origin = np.zeros(3)
    rays = rays_to(origin, pair_at(np.array([1.0, 0.0, 0.0])))
    # At 1 m both should shine about 1200 (flux_range / range); 4× apart is two robots.
    uneven = np.array([800.0, 3200.0])
    assert pair_leds(origin, rays, uneven, depth=1.0, vision=VISION).size == 0
    found = pair_leds(origin, rays, np.array([800.0, 2000.0]), depth=1.0, vision=VISION)
    assert found.shape == (1, 3)


def test_faint_far_leds_in_line_are_not_a_near_robot() -> None:
    # Two LEDs 0.2 m away as seen, but as faint as LEDs 2 m away: two far robots' LEDs that
    # happen to line up, not one near robot.
    origin = np.zeros(3)
    points = pair_at(np.array([0.2, 0.0, 0.0]))
    rays = rays_to(origin, points)
    far = np.full(2, VISION.flux_range / 2.0)
    assert pair_leds(origin, rays, far, depth=1.0, vision=VISION).size == 0
    found = pair_leds(origin, rays, lit(origin, points), depth=1.0, vision=VISION)
    np.testing.assert_allclose(found, [[0.2, 0.0, 0.0]], atol=1e-9)


def test_pairs_beyond_the_range_or_nearer_than_a_body_are_dropped() -> None:
    origin = np.zeros(3)
    for distance in (3.5, 0.06):
        # Brightness as for a robot at that distance: only the range refuses it.
        points = pair_at(np.array([distance, 0.0, 0.0]))
        rays = rays_to(origin, points)
        assert pair_leds(origin, rays, lit(origin, points), depth=1.0, vision=VISION).size == 0


def test_rays_off_a_vertical_line_are_not_a_pair() -> None:
    origin = np.zeros(3)
    lower, upper = pair_at(np.array([1.0, 0.0, 0.0]))
    points = [lower, upper + np.array([0.0, 0.05, 0.0])]  # 2.9° aside
    rays = rays_to(origin, points)
    assert pair_leds(origin, rays, lit(origin, points), depth=1.0, vision=VISION).size == 0


@pytest.mark.parametrize(
    "name", ["threshold", "saddle_ratio", "visual_range", "flux_ratio", "flux_range"]
)
def test_settings_out_of_range_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match=name):
        LedVision(**{name: -1})


def test_a_frame_of_glare_or_noise_is_refused_quickly_not_paired() -> None:
    # Sensor noise in a dark frame: over a thousand lit spots, which pairing would need
    # gigabytes for; refused before pairing, so that the driver skips the period.
    rng = np.random.default_rng(3)
    noisy = np.clip(rng.normal(25.0, 15.0, (192, 256, 3)), 0, 255).astype(np.uint8)
    dark = np.zeros_like(noisy)
    with pytest.raises(FrameUnusable, match=r"the left camera's image has \d+ lit spots"):
        perceive_leds(
            {"left": noisy, "right": dark}, depth=0.5, fisheye=Fisheye(), vision=LedVision()
        )
    with pytest.raises(ValueError, match="max_blobs must be at least 2"):
        LedVision(max_blobs=1)


def test_rays_two_degrees_off_a_vertical_line_are_not_a_pair() -> None:
    # The tolerance is 1.5° seen from the camera: 0.035 m aside at 1 m is 2.0°.
    origin = np.zeros(3)
    lower, upper = pair_at(np.array([1.0, 0.0, 0.0]))
    for aside, pairs in ((0.035, 0), (0.02, 1)):
        points = [lower, upper + np.array([0.0, aside, 0.0])]
        rays, fluxes = rays_to(origin, points), lit(origin, points)
        found = pair_leds(origin, rays, fluxes, depth=1.0, vision=VISION)
        assert found.shape == (pairs, 3), aside


@pytest.mark.parametrize(("ratio", "found"), [(2.0, 1), (1.25, 1), (1.15, 0), (3.6, 0)])
def test_a_robot_straight_above_is_its_merged_pair_and_its_front_led(
    ratio: float, found: int
) -> None:
    """Seen from 0.5 m straight below, a robot's two LEDs fall on one ray (one blob about
    twice as bright as its front LED, one spacing aside): found where the merged blob is,
    when the two blobs' brightness ratio lies in 1.2–3.5."""
    origin = np.zeros(3)
    upper = np.array([0.0, 0.0, -0.5])
    front = upper + np.array([LED_SPACING, 0.0, 0.0])
    rays = rays_to(origin, [upper, front])
    single = VISION.flux_range / 0.5
    got = pair_leds(origin, rays, np.array([ratio * single, single]), depth=1.0, vision=VISION)
    assert got.shape == (found, 3)
    if found:
        # The range is one spacing over the angle between the rays: a little over 0.5 m.
        angle = np.arctan(LED_SPACING / 0.5)
        np.testing.assert_allclose(got[0], [0.0, 0.0, -LED_SPACING / angle], atol=1e-9)


def test_an_image_with_one_spot_more_than_max_blobs_is_refused() -> None:
    vision = LedVision(max_blobs=4)
    dark = np.zeros((64, 64, 3), dtype=np.uint8)
    spots = dark.copy()
    for n in range(4):
        spots[10 + 10 * n, 10, 2] = 200
    small = Fisheye(width=64, height=64)
    found = perceive_leds({"left": spots, "right": dark}, depth=0.5, fisheye=small, vision=vision)
    assert found.shape[1] == 3
    spots[50, 50, 2] = 200
    with pytest.raises(FrameUnusable, match="has 5 lit spots, more than LEDs make"):
        perceive_leds({"left": spots, "right": dark}, depth=0.5, fisheye=small, vision=vision)
