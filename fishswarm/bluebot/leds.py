"""Neighbours from LED blobs: what a BlueBot sees of the others in its two camera images.

SPEC §6. Each robot carries a vertical pair of blue LEDs 0.086 m apart; seen from a camera,
the pair's two rays and that known spacing fix the range. The pipeline, per image:

1. threshold the blue channel and split the lit pixels into blobs — each pixel climbs to
   the brightest pixel it can reach, and two peaks stay apart only where the light between
   them dips well below the fainter one (two LEDs far away lie a few pixels apart);
2. blob centroids → unit rays through the fisheye model → the body frame;
3. every two blobs, one above the other, whose rays fit a vertical pair of the LED spacing
   (least squares, the mismatch as an angle within tolerance), with brightnesses that match
   each other and the range, are candidates; the pair's midpoint is the neighbour;
4. drop candidates out of the water (mirror images in the surface appear above the real
   LEDs) or out of range, and take the rest greedily, those whose mirror images are seen
   first, then those most like one robot's pair; a pair taken explains away its front LED
   and its mirror images; then find robots seen from steeply above or below, whose two
   LEDs fall on one blob, by their front LED;

then the two cameras' neighbours are merged (a neighbour ahead is seen by both) and sorted
near to far. Output: body-frame positions relative to the body centre, as the world's
geometric vision gives. Pure numpy: this runs on the robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.blobs import find_blobs
from fishswarm.bluebot.fisheye import Fisheye, camera_position, camera_to_body
from fishswarm.bluebot.flashes import merge_frames
from fishswarm.bluebot.parameters import LED_SPACING
from fishswarm.bluebot.ports import CameraSide

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_CIRCLE_POINTS = 36
_EXPLAIN_SLACK = 0.01  # m: the chord between circle points, and the LEDs' size
# How far one robot's LED pairs stray from a perfect fit, measured on 877 pairs in rendered
# images (typical deviations): the rays' mismatch, deg; |ln| of the two blobs' brightness
# ratio; |ln| of brightness × range over the calibration. A candidate's misfit adds them up in
# these units, so that the pairs most like a robot are taken first.
_STEEP_SINE = 0.8  # rays more than 53° above or below the horizon are steep
_MISMATCH_SPREAD_DEG = 0.3
_BALANCE_SPREAD = 0.4
_BRIGHTNESS_SPREAD = 0.2


@dataclass(frozen=True)
class LedVision:
    """Settings of the LED pipeline.

    Attributes:
        threshold: a pixel is lit when its blue value exceeds this (0–255; the research code
            used 40–60).
        saddle_ratio: two brightness peaks of one lit region count as one blob when the
            light between them stays at or above this fraction of the fainter peak.
        pair_tolerance_deg: the largest mismatch, as an angle seen from the camera, between
            two rays and a vertical LED pair, deg.
        flux_ratio: two blobs whose summed brightness differs by more than this factor are
            not one robot's pair.
        flux_range: an LED blob's summed brightness times its distance from the camera, for
            these cameras and LEDs (a calibration: measured on rendered images, about constant
            from 0.15 to 3 m because a near LED's spot saturates and grows rather than
            brightens).
        flux_range_ratio: a pair whose mean brightness times its range lies more than this
            factor off ``flux_range`` is not one robot's pair (two faint far LEDs do not make
            a near robot).
        min_range: pairs nearer than this are dropped, m (two robots' centres cannot come
            closer; such pairs are LEDs of different robots that happen to line up).
        visual_range: pairs farther than this are dropped, m.
        merge_distance: a neighbour seen by both cameras is one neighbour when the two
            estimates lie closer than this fraction of its range (at least 0.05 m).
        max_blobs: a camera image with more lit spots than this is not LEDs but glare or
            sensor noise, and is not paired (pairing costs grow with the square of the
            spots: a noisy frame of 1 500 took gigabytes). 24 robots in view made up to 144
            spots in two images (docs/camera.md).
    """

    threshold: int = 40
    saddle_ratio: float = 0.7
    pair_tolerance_deg: float = 1.5
    flux_ratio: float = 3.0
    flux_range: float = 1200.0
    flux_range_ratio: float = 3.0
    min_range: float = 0.1
    visual_range: float = 3.0
    merge_distance: float = 0.15
    max_blobs: int = 160

    def __post_init__(self) -> None:
        if self.max_blobs < 2:
            raise ValueError(f"max_blobs must be at least 2, got {self.max_blobs}")
        if not 0 <= self.threshold < 255:
            raise ValueError(f"threshold must lie in [0, 255), got {self.threshold}")
        if not 0 < self.saddle_ratio <= 1:
            raise ValueError(f"saddle_ratio must lie in (0, 1], got {self.saddle_ratio}")
        for name in (
            "pair_tolerance_deg",
            "flux_ratio",
            "flux_range",
            "flux_range_ratio",
            "min_range",
            "visual_range",
            "merge_distance",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value}")


def pair_leds(
    origin: FloatArray,
    directions: FloatArray,
    fluxes: FloatArray,
    *,
    depth: float,
    vision: LedVision,
) -> FloatArray:
    """Neighbours from the rays of one camera's blobs.

    Every two blobs, one above the other, that fit a vertical LED pair are candidates. Those
    whose midpoint would be out of the water (mirror images), out of range, or whose
    brightness does not fit their range are dropped; the rest are taken one by one — first
    those whose own mirror images are seen, then those that fit one robot best — and each
    pair taken explains the blobs it accounts for (its front LED, level with the upper one,
    one spacing away, and the mirror images of its LEDs in the surface), so that those are
    not paired again. The blobs left over are then tried as robots seen from steeply above
    or below.

    Args:
        origin: (3,) the camera's position in the body frame, m.
        directions: (M, 3) unit rays in the body frame (z down).
        fluxes: (M,) each blob's summed brightness (the two LEDs of a pair lie at about the
            same distance, so they shine about equally).
        depth: the seeing fish's own depth, m (from its pressure sensor).
        vision: the pipeline's settings.

    Returns:
        (K, 3) body-frame positions of the neighbours found, m.
    """
    tolerance = math.radians(vision.pair_tolerance_deg)
    lower, upper, middles, mismatch = _candidate_pairs(
        directions, fluxes, tolerance, vision.flux_ratio
    )
    brightness = (fluxes[lower] + fluxes[upper]) / 2 * np.linalg.norm(middles, axis=1)
    middles = origin + middles
    distance = np.linalg.norm(middles, axis=1)
    valid = (
        (depth + middles[:, 2] >= LED_SPACING / 2)
        & (brightness >= vision.flux_range / vision.flux_range_ratio)
        & (brightness <= vision.flux_range * vision.flux_range_ratio)
        & (distance >= vision.min_range)
        & (distance <= vision.visual_range)
    )
    lower, upper, middles = lower[valid], upper[valid], middles[valid]
    explains, mirrored = _explained(origin, directions, middles, depth, tolerance)
    # Pairs whose mirror images in the surface are seen where they should be first (near the
    # surface a robot's upper LED lies closer to its own mirror image than to its lower LED),
    # then the pairs that look most like one robot's LEDs.
    misfit = (
        np.degrees(mismatch[valid]) / _MISMATCH_SPREAD_DEG
        + np.abs(np.log(fluxes[lower] / fluxes[upper])) / _BALANCE_SPREAD
        + np.abs(np.log(brightness[valid] / vision.flux_range)) / _BRIGHTNESS_SPREAD
    )
    order = np.lexsort((misfit, -mirrored.sum(axis=1)))
    taken = np.zeros(directions.shape[0], dtype=bool)
    found: list[FloatArray] = []
    for index in order:
        first, second = int(lower[index]), int(upper[index])
        if taken[first] or taken[second]:
            continue
        taken[first] = taken[second] = True
        found.append(middles[index])
        taken |= explains[index]
    steep = _seen_from_above_or_below(origin, directions, fluxes, taken, depth=depth, vision=vision)
    return np.concatenate([np.array(found).reshape(-1, 3), steep])


def _seen_from_above_or_below(
    origin: FloatArray,
    directions: FloatArray,
    fluxes: FloatArray,
    taken: NDArray[np.bool_],
    *,
    depth: float,
    vision: LedVision,
) -> FloatArray:
    """Robots seen from steeply above or below, whose two vertical LEDs fall on one blob.

    Seen along its vertical axis a robot's pair is one blob twice as bright as one LED, and
    its front LED — level, one spacing from the upper one, so across the line of sight from
    any heading — a blob half as bright at an angle of spacing / range beside it: that angle
    gives the range. Only blobs nobody's pair has taken are considered, and only steep
    rays (more than 53° from the horizontal), where a pair cannot appear as two blobs; a
    robot found this way that would stand out of the water is a mirror image.
    """
    free = np.flatnonzero(~taken)
    if free.size < 2:
        return np.zeros((0, 3))
    rays = directions[free]
    steep = np.abs(rays[:, 2]) >= _STEEP_SINE
    cosine = np.clip(rays @ rays.T, -1.0, 1.0)
    angle = np.arccos(cosine)
    np.fill_diagonal(angle, np.inf)
    distance = LED_SPACING / np.maximum(angle, 1e-9)
    flux = fluxes[free]
    ratio = flux[:, None] / flux[None, :]  # merged pair over front LED, about 2
    single = flux[None, :] * distance  # the front LED's brightness × range
    fits = (
        steep[:, None]
        & steep[None, :]
        & (ratio >= 1.2)
        & (ratio <= 3.5)
        & (distance >= vision.min_range)
        & (distance <= vision.visual_range)
        & (single >= vision.flux_range / vision.flux_range_ratio)
        & (single <= vision.flux_range * vision.flux_range_ratio)
    )
    pair, front = np.nonzero(fits)
    if pair.size == 0:
        return np.zeros((0, 3))
    misfit = np.abs(np.log(ratio[pair, front] / 2.0)) + np.abs(
        np.log(single[pair, front] / vision.flux_range)
    )
    used = np.zeros(free.size, dtype=bool)
    found: list[FloatArray] = []
    for index in np.argsort(misfit, kind="stable").tolist():
        a, b = int(pair[index]), int(front[index])
        if used[a] or used[b]:
            continue
        position = origin + distance[a, b] * rays[a]
        if depth + position[2] < LED_SPACING / 2:
            continue  # a mirror image above the surface
        used[a] = used[b] = True
        found.append(position)
    return np.array(found).reshape(-1, 3)


def _candidate_pairs(
    directions: FloatArray, fluxes: FloatArray, tolerance: float, flux_ratio: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray, FloatArray]:
    """Blob pairs (lower, upper) that fit a vertical LED pair, with the pair's midpoint
    relative to the camera and the mismatch as an angle (rad).

    For rays b1 (lower) and b2 (upper), the ranges d1, d2 that best satisfy
    d1·b1 − d2·b2 = (0, 0, spacing) solve [[1, −c], [−c, 1]]·(d1, d2) = spacing·(b1z, −b2z)
    with c = b1·b2; the pair fits when both ranges are positive and the mismatch, over the
    mean range, is within ``tolerance`` (rad)."""
    first, second = np.nonzero(directions[:, None, 2] > directions[None, :, 2])
    cosine = np.einsum("ij,ij->i", directions[first], directions[second])
    b1, b2 = directions[first], directions[second]
    determinant = 1.0 - cosine**2
    usable = determinant > 1e-12
    safe = np.where(usable, determinant, 1.0)
    d1 = LED_SPACING * (b1[:, 2] - cosine * b2[:, 2]) / safe
    d2 = LED_SPACING * (cosine * b1[:, 2] - b2[:, 2]) / safe
    mismatch = np.linalg.norm(
        d1[:, None] * b1 - d2[:, None] * b2 - np.array([0.0, 0.0, LED_SPACING]), axis=1
    )
    bright = np.maximum(fluxes[first], fluxes[second])
    dim = np.minimum(fluxes[first], fluxes[second])
    fits = (
        usable
        & (d1 > 0)
        & (d2 > 0)
        & (mismatch <= tolerance * (d1 + d2) / 2)
        & (bright <= flux_ratio * dim)
    )
    keep = np.flatnonzero(fits)
    middles = (d1[keep, None] * b1[keep] + d2[keep, None] * b2[keep]) / 2
    angle = mismatch[keep] / ((d1[keep] + d2[keep]) / 2)
    return first[keep], second[keep], middles, angle


def _explained(
    origin: FloatArray, directions: FloatArray, middles: FloatArray, depth: float, tolerance: float
) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which rays (M,) each of C robots, whose LED pairs have their midpoints at ``middles``
    (C, 3), accounts for — its front LED (somewhere on the level circle of one spacing around
    the upper LED, its heading unknown) and the surface's mirror images of its LEDs (the
    surface lies ``depth`` above the camera's level) — and which of them are the mirror
    images of the pair: two (C, M) masks."""
    half = np.array([0.0, 0.0, LED_SPACING / 2])
    upper, lower = middles - half, middles + half
    flip = np.array([1.0, 1.0, -1.0])
    shift = np.array([0.0, 0.0, -2.0 * depth])
    mirror_upper, mirror_lower = upper * flip + shift, lower * flip + shift
    angle = np.linspace(0.0, 2.0 * np.pi, _CIRCLE_POINTS, endpoint=False)
    circle = LED_SPACING * np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1)
    points = np.concatenate(
        [
            mirror_upper[:, None, :],
            mirror_lower[:, None, :],
            upper[:, None, :] + circle,
            mirror_upper[:, None, :] + circle,
        ],
        axis=1,
    )
    offset = points - origin  # (C, P, 3)
    length_squared = np.square(offset).sum(axis=2)  # (C, P)
    along = np.maximum(offset @ directions.T, 0.0)  # (C, P, M)
    # A point's distance from a ray: Pythagoras on its offset and its length along the ray.
    miss_squared = length_squared[:, :, None] - np.square(along)
    reach = tolerance * np.sqrt(length_squared) + _EXPLAIN_SLACK
    near = miss_squared <= np.square(reach)[:, :, None]
    explained: NDArray[np.bool_] = near.any(axis=1)
    mirrored: NDArray[np.bool_] = near[:, :2, :].any(axis=1)
    return explained, mirrored


class FrameUnusable(RuntimeError):
    """A camera image that cannot be LEDs (glare, sensor noise): the driver skips the period."""


def perceive_leds(
    images: dict[CameraSide, NDArray[np.uint8]],
    *,
    depth: float,
    fisheye: Fisheye,
    vision: LedVision,
) -> FloatArray:
    """The neighbours a BlueBot sees in its camera images.

    Args:
        images: the left and right image, each (H, W, 3) RGB, 0–255.
        depth: the fish's depth from its pressure sensor, m.
        fisheye: the cameras' projection.
        vision: the pipeline's settings.

    Returns:
        (K, 3) body-frame neighbour positions (x forward, y right, z down), m, near to far.

    Raises:
        FrameUnusable: an image holds more than ``vision.max_blobs`` lit spots.
    """
    estimates: list[FloatArray] = []
    for side, image in images.items():
        blobs = find_blobs(
            image[:, :, 2], threshold=vision.threshold, saddle_ratio=vision.saddle_ratio
        )
        spots = blobs.centroids.shape[0]
        if spots > vision.max_blobs:
            raise FrameUnusable(
                f"the {side} camera's image has {spots} lit spots, more than LEDs make "
                f"({vision.max_blobs}): glare or sensor noise"
            )
        if spots < 2:
            estimates.append(np.zeros((0, 3)))
            continue
        rays = fisheye.pixel_to_ray(blobs.centroids) @ camera_to_body(side).T
        estimates.append(
            pair_leds(camera_position(side), rays, blobs.fluxes, depth=depth, vision=vision)
        )
    merged = _merge_cameras(estimates, vision.merge_distance)
    order = np.argsort(np.linalg.norm(merged, axis=1), kind="stable")
    result: FloatArray = merged[order]
    return result


def _merge_cameras(estimates: list[FloatArray], fraction: float) -> FloatArray:
    """One neighbour for each one both cameras saw (the mean of the two estimates), as two
    frames' sightings are merged (:func:`~fishswarm.bluebot.flashes.merge_frames`)."""
    if len(estimates) != 2:
        return np.concatenate([e.reshape(-1, 3) for e in estimates] or [np.zeros((0, 3))])
    merged, _ = merge_frames(estimates[0], estimates[1], fraction=fraction)
    return merged
