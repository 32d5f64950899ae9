"""Neighbours from LED blobs: what a BlueBot sees of the others in its two camera images.

SPEC §6. Each robot carries a vertical pair of blue LEDs 0.086 m apart; seen from a camera,
the pair's two rays and that known spacing fix the range. The pipeline, per image:

1. threshold the blue channel and split the lit pixels into blobs — each pixel climbs to
   the brightest pixel it can reach, and two peaks stay apart only where the light between
   them dips well below the fainter one (two LEDs far away lie a few pixels apart);
2. blob centroids → unit rays through the fisheye model → the body frame;
3. from the lowest blob up, pair each blob with the nearest blob above it whose ray is
   consistent with a vertical pair (the least-squares mismatch of the two rays, as an angle,
   within tolerance); the pair's midpoint is the neighbour;
4. reject pairs whose midpoint would put the upper LED out of the water — mirror images in
   the surface, which appear above the real LEDs — and pairs beyond the visual range;

then the two cameras' neighbours are merged (a neighbour ahead is seen by both) and sorted
near to far. Output: body-frame positions relative to the body centre, as the world's
geometric vision gives. Pure numpy: this runs on the robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.fisheye import Fisheye, camera_position, camera_to_body
from fishswarm.bluebot.parameters import LED_SPACING
from fishswarm.bluebot.ports import CameraSide

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_CIRCLE_POINTS = 36
_EXPLAIN_SLACK = 0.01  # m: the chord between circle points, and the LEDs' size
_OFFSETS = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1))


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

    def __post_init__(self) -> None:
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


@dataclass(frozen=True)
class Blobs:
    """Bright blobs in one image.

    Attributes:
        centroids: (M, 2) brightness-weighted (row, column), px.
        peaks: (M,) the brightest value in each blob.
        sizes: (M,) pixels in each blob.
        fluxes: (M,) the sum of each blob's values.
    """

    centroids: FloatArray
    peaks: FloatArray
    sizes: IntArray
    fluxes: FloatArray


def find_blobs(blue: NDArray[np.uint8], *, threshold: int, saddle_ratio: float) -> Blobs:
    """The bright blobs of one colour channel.

    Args:
        blue: (H, W) the channel, 0–255.
        threshold: pixels above this value are lit.
        saddle_ratio: peaks joined by light at or above this fraction of the fainter one are
            one blob.
    """
    height, width = blue.shape
    rows, columns = np.nonzero(blue > threshold)
    count = rows.size
    if count == 0:
        return Blobs(np.zeros((0, 2)), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0))
    value = blue[rows, columns].astype(np.int64)
    where = np.full((height + 2, width + 2), -1, dtype=np.int64)
    where[rows + 1, columns + 1] = np.arange(count)
    # Neighbour k of every lit pixel (−1 where unlit), 8-connected, self included.
    neighbours = np.stack([where[rows + 1 + dr, columns + 1 + dc] for dr, dc in _OFFSETS], axis=1)
    # Climb: each pixel points to its brightest lit neighbour; ties go to the larger flat
    # index, so a saturated plateau drains to one pixel.
    key = value * (height * width) + rows * width + columns
    neighbour_key = np.where(neighbours >= 0, key[np.maximum(neighbours, 0)], -1)
    pointer = neighbours[np.arange(count), np.argmax(neighbour_key, axis=1)]
    while True:
        jumped = pointer[pointer]
        if np.array_equal(jumped, pointer):
            break
        pointer = jumped
    peaks, label = np.unique(pointer, return_inverse=True)
    label = _merge_shallow_saddles(neighbours, label, value, value[peaks], saddle_ratio)
    _, label = np.unique(label, return_inverse=True)
    blobs = int(label.max()) + 1
    weight = value.astype(np.float64)
    total = np.bincount(label, weight, blobs)
    centroids = (
        np.stack(
            [np.bincount(label, weight * rows, blobs), np.bincount(label, weight * columns, blobs)],
            axis=1,
        )
        / total[:, None]
    )
    brightest = np.zeros(blobs)
    np.maximum.at(brightest, label, weight)
    sizes = np.bincount(label, minlength=blobs).astype(np.int64)
    return Blobs(centroids, brightest, sizes, total.astype(np.float64))


def _merge_shallow_saddles(
    neighbours: IntArray, label: IntArray, value: IntArray, peak: IntArray, ratio: float
) -> IntArray:
    """Join regions whose peaks are separated by light at or above ``ratio`` × the fainter."""
    here = np.repeat(np.arange(label.size), neighbours.shape[1])
    there = neighbours.ravel()
    touching = (there >= 0) & (label[here] != label[np.maximum(there, 0)])
    if not touching.any():
        return label
    a, b = label[here[touching]], label[there[touching]]
    saddle = np.minimum(value[here[touching]], value[there[touching]])
    parent = list(range(peak.size))

    def root(node: int) -> int:
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    # Highest saddles first, so each merge compares against the peaks as they stand.
    for index in np.argsort(-saddle, kind="stable"):
        first, second = root(int(a[index])), root(int(b[index]))
        if first != second and saddle[index] >= ratio * min(peak[first], peak[second]):
            brighter, fainter = (first, second) if peak[first] >= peak[second] else (second, first)
            parent[fainter] = brighter
    return np.array([root(int(node)) for node in label], dtype=np.int64)


def pair_leds(
    origin: FloatArray,
    directions: FloatArray,
    fluxes: FloatArray,
    *,
    depth: float,
    vision: LedVision,
) -> FloatArray:
    """Neighbours from the rays of one camera's blobs.

    Every two blobs, one above the other, that fit a vertical LED pair are candidates; they
    are taken closest first (the angle between their rays), as a robot's own two LEDs lie
    closer together in the image than either does to its mirror image or to another robot's
    LEDs in line with it. A pair whose midpoint is in the water and within range is a
    neighbour, and then also explains the blobs it accounts for — its front LED (level with
    the upper one, one spacing away) and the mirror images of its LEDs in the surface — so
    that those are not paired again; a pair out of the water (a mirror image) or out of range
    just uses up its two blobs.

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
    lower, upper, middles = _candidate_pairs(directions, fluxes, tolerance, vision.flux_ratio)
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
    # then the closest pairs.
    support = mirrored.sum(axis=1)
    taken = np.zeros(directions.shape[0], dtype=bool)
    found: list[FloatArray] = []
    for index in np.argsort(-support, kind="stable"):
        first, second = int(lower[index]), int(upper[index])
        if taken[first] or taken[second]:
            continue
        taken[first] = taken[second] = True
        found.append(middles[index])
        taken |= explains[index]
    return np.array(found).reshape(-1, 3)


def _candidate_pairs(
    directions: FloatArray, fluxes: FloatArray, tolerance: float, flux_ratio: float
) -> tuple[NDArray[np.intp], NDArray[np.intp], FloatArray]:
    """Blob pairs (lower, upper) that fit a vertical LED pair, closest first, with the pair's
    midpoint relative to the camera.

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
    gap = np.arccos(np.clip(cosine, -1.0, 1.0))
    order = np.flatnonzero(fits)[np.argsort(gap[fits], kind="stable")]
    middles = (d1[order, None] * b1[order] + d2[order, None] * b2[order]) / 2
    return first[order], second[order], middles


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
    """
    estimates: list[FloatArray] = []
    for side, image in images.items():
        blobs = find_blobs(
            image[:, :, 2], threshold=vision.threshold, saddle_ratio=vision.saddle_ratio
        )
        if blobs.centroids.shape[0] < 2:
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
    """One neighbour for each one both cameras saw (the mean of the two estimates)."""
    if len(estimates) != 2 or estimates[0].size == 0 or estimates[1].size == 0:
        return np.concatenate([e.reshape(-1, 3) for e in estimates] or [np.zeros((0, 3))])
    first, second = estimates
    gap = np.linalg.norm(first[:, None, :] - second[None, :, :], axis=2)
    reach = np.maximum(0.05, fraction * np.linalg.norm(first, axis=1))[:, None]
    kept_second = np.ones(second.shape[0], dtype=bool)
    merged = first.copy()
    for row in range(first.shape[0]):
        candidates = np.flatnonzero((gap[row] <= reach[row, 0]) & kept_second)
        if candidates.size:
            partner = int(candidates[np.argmin(gap[row, candidates])])
            merged[row] = (first[row] + second[partner]) / 2
            kept_second[partner] = False
    return np.concatenate([merged, second[kept_second]])
