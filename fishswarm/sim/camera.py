"""Camera images rendered from the simulated world: what a BlueBot's two fisheye cameras see.

For one fish, each of its cameras sees the other fish's three LEDs (the robot's LED
geometry, ``LED_POSITIONS``) through the robot's fisheye model: a blurred spot whose peak
falls with the square of the distance and with the water's absorption, hidden when another
fish's body (an ellipsoid of the robot's length, width and height) lies on the line of
sight; the LEDs sit proud of their own hull, which does not hide them.
The water surface mirrors every LED: seen from below, a mirror image above the real one,
as bright as Fresnel's reflectance at that angle makes it (total beyond the critical angle).
A mirror image is a straight line of sight in the mirrored tank, so its occlusion is tested
against the bodies and their mirror images. Images are RGB like the robot's camera port,
over a dim noisy background from a seeded stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.fisheye import Fisheye, camera_position, camera_to_body
from fishswarm.bluebot.parameters import LED_POSITIONS, BlueBot
from fishswarm.bluebot.ports import CAMERA_SIDES, CameraSide

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_WATER_INDEX = 1.333


@dataclass(frozen=True)
class Optics:
    """How LEDs and water look to the rendered cameras.

    Attributes:
        led_brightness: the peak value of an LED's spot seen from 1 m, before the image
            saturates at 255.
        led_radius: the LED's radius, m (its spot grows with nearness).
        blur_px: the optics' blur, standard deviation of a point's spot, px.
        absorption: the water's attenuation of blue light, 1/m.
        background: the water's (red, green, blue) level, 0–255.
        noise: standard deviation of the sensor noise, 0–255 units.
        reflections: whether the water surface mirrors the LEDs.
    """

    led_brightness: float = 800.0
    led_radius: float = 0.0025
    blur_px: float = 0.5
    absorption: float = 0.05
    background: tuple[float, float, float] = (4.0, 9.0, 14.0)
    noise: float = 2.0
    reflections: bool = True


def _rotation(yaw: FloatArray) -> FloatArray:
    """(N, 3, 3) body → tank rotations about z."""
    cos, sin = np.cos(yaw), np.sin(yaw)
    matrix = np.zeros((yaw.size, 3, 3))
    matrix[:, 0, 0], matrix[:, 0, 1] = cos, -sin
    matrix[:, 1, 0], matrix[:, 1, 1] = sin, cos
    matrix[:, 2, 2] = 1.0
    return matrix


def fresnel_reflectance(cos_incidence: FloatArray) -> FloatArray:
    """Share of light reflected back into the water at the surface, for light inside the
    water meeting it at an angle whose cosine (to the vertical) is given; 1 beyond the
    critical angle (unpolarised light, Fresnel's equations)."""
    cos_i = np.clip(np.abs(cos_incidence), 0.0, 1.0)
    sin_t = _WATER_INDEX * np.sqrt(1.0 - cos_i**2)
    total = sin_t >= 1.0
    cos_t = np.sqrt(np.clip(1.0 - sin_t**2, 0.0, 1.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        rs = ((_WATER_INDEX * cos_i - cos_t) / (_WATER_INDEX * cos_i + cos_t)) ** 2
        rp = ((_WATER_INDEX * cos_t - cos_i) / (_WATER_INDEX * cos_t + cos_i)) ** 2
    reflectance: FloatArray = np.where(total, 1.0, np.nan_to_num((rs + rp) / 2, nan=1.0))
    return reflectance


def _blocked(
    start: FloatArray,
    ends: FloatArray,
    owners: NDArray[np.intp],
    centres: FloatArray,
    inverse: FloatArray,
) -> NDArray[np.bool_]:
    """(M,) whether the segment from ``start`` (3,) to each of ``ends`` (M, 3) passes through
    an ellipsoid other than its end's own (``owners`` (M,)); ``inverse`` (K, 3, 3) maps tank
    offsets from ``centres`` (K, 3) into each ellipsoid's unit sphere."""
    if centres.shape[0] == 0 or ends.shape[0] == 0:
        return np.zeros(ends.shape[0], dtype=bool)
    origin = np.einsum("kij,kj->ki", inverse, start - centres)  # (K, 3)
    along = np.einsum("kij,mj->mki", inverse, ends - start)  # (M, K, 3)
    a = np.einsum("mki,mki->mk", along, along)
    b = 2.0 * np.einsum("mki,ki->mk", along, origin)
    c = np.einsum("ki,ki->k", origin, origin)[None, :] - 1.0
    discriminant = b * b - 4.0 * a * c
    root = np.sqrt(np.maximum(discriminant, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        entry = (-b - root) / (2.0 * a)
        leave = (-b + root) / (2.0 * a)
    crossing = (discriminant > 0) & (entry < 1.0) & (leave > 0.0)
    crossing[np.arange(ends.shape[0]), owners] = False
    blocked: NDArray[np.bool_] = crossing.any(axis=1)
    return blocked


def render_views(
    position: FloatArray,
    yaw: FloatArray,
    viewer: int,
    *,
    fisheye: Fisheye,
    optics: Optics,
    robot: BlueBot,
    rng: np.random.Generator,
    lit: BoolArray | None = None,
) -> dict[CameraSide, NDArray[np.uint8]]:
    """Both camera images of fish ``viewer``.

    Args:
        position: (N, 3) tank-frame positions of all fish, m (z down, surface at z = 0).
        yaw: (N,) their yaws, rad.
        viewer: the index of the fish whose cameras look.
        fisheye: the cameras' projection.
        optics: LEDs and water.
        robot: body dimensions (the occluding ellipsoids).
        rng: the stream of the viewer's sensor noise.
        lit: (N,) whether each fish's LEDs shine (a flashing fish's are dark for half of
            each flash period); None: all shine. A dark fish's body still hides what lies
            behind it.

    Returns:
        The left and right image, each (H, W, 3) RGB uint8.
    """
    others = np.flatnonzero(np.arange(position.shape[0]) != viewer)
    shining = np.ones(others.size, dtype=bool) if lit is None else np.asarray(lit)[others]
    rotation = _rotation(yaw)
    leds = np.asarray(LED_POSITIONS)
    sources = (
        position[others, None, :] + np.einsum("nij,lj->nli", rotation[others], leds)
    ).reshape(-1, 3)
    owners = np.repeat(np.arange(others.size), leds.shape[0])
    lights = shining[owners]
    semi_axes = np.array([robot.length, robot.width, robot.height]) / 2
    inverse = np.transpose(rotation[others], (0, 2, 1)) / semi_axes[None, :, None]
    centres = position[others]
    if optics.reflections:
        mirror = np.array([1.0, 1.0, -1.0])
        mirrored = sources * mirror
        centres = np.concatenate([centres, centres * mirror])
        inverse = np.concatenate([inverse, inverse * mirror[None, None, :]])
        sources = np.concatenate([sources, mirrored])
        owners = np.concatenate([owners, owners + others.size])
        lights = np.concatenate([lights, lights])
    images: dict[CameraSide, NDArray[np.uint8]] = {}
    for side in CAMERA_SIDES:
        camera = position[viewer] + rotation[viewer] @ camera_position(side)
        offsets = sources - camera
        distance = np.linalg.norm(offsets, axis=1)
        strength = optics.led_brightness * np.exp(-optics.absorption * distance)
        if optics.reflections:
            half = sources.shape[0] // 2
            strength[half:] *= fresnel_reflectance(offsets[half:, 2] / distance[half:])
        to_camera = (rotation[viewer] @ camera_to_body(side)).T
        pixels, inside = fisheye.ray_to_pixel(offsets @ to_camera.T)
        inside &= (distance > 1e-6) & lights
        inside[inside] &= ~_blocked(camera, sources[inside], owners[inside], centres, inverse)
        images[side] = _expose(
            pixels[inside],
            strength[inside] / distance[inside] ** 2,
            optics.led_radius / distance[inside] * fisheye.pixels_per_radian,
            fisheye,
            optics,
            rng,
        )
    return images


def _expose(
    pixels: FloatArray,
    peak: FloatArray,
    spread: FloatArray,
    fisheye: Fisheye,
    optics: Optics,
    rng: np.random.Generator,
) -> NDArray[np.uint8]:
    """An image of blue spots at ``pixels`` (M, 2) with ``peak`` (M,) values and
    ``spread`` (M,) extra radius, px, over the noisy background."""
    height, width = fisheye.height, fisheye.width
    light = np.zeros((height, width))
    sigma = np.hypot(optics.blur_px, spread)
    for (row, column), top, size in zip(pixels, peak, sigma, strict=True):
        # Out to where the spot falls below half a grey level.
        reach = math.ceil(size * math.sqrt(2.0 * math.log(max(2.0 * top, 1.0)))) + 1
        r0, r1 = max(0, int(row) - reach), min(height, int(row) + reach + 2)
        c0, c1 = max(0, int(column) - reach), min(width, int(column) + reach + 2)
        rows = np.arange(r0, r1)[:, None] - row
        columns = np.arange(c0, c1)[None, :] - column
        light[r0:r1, c0:c1] += top * np.exp(-(rows**2 + columns**2) / (2.0 * size**2))
    noise = rng.standard_normal((height, width), dtype=np.float32) * optics.noise
    image = np.empty((height, width, 3), dtype=np.uint8)
    colour = (0.05, 0.3, 1.0)  # a blue LED's light in the red, green and blue channels
    for channel in range(3):
        value = optics.background[channel] + colour[channel] * light + noise
        image[:, :, channel] = np.clip(np.rint(value), 0, 255).astype(np.uint8)
    return image
