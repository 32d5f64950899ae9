"""Simulated fish seeing through their cameras: rendered images read by the robot's pipeline.

With ``vision_model = "camera"`` every fish's two camera images are rendered from the tank
(:func:`~fishswarm.sim.camera.render_views`) and its neighbours are what the BlueBot's own
LED pipeline (:func:`~fishswarm.bluebot.leds.perceive_leds`) finds in them — with the robot's
misses, false pairs and range errors instead of the geometric model's exact positions.
:func:`score_sight` compares the two, for the detection statistics a run reports.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import pad_rows
from fishswarm.bluebot.dynamics import rotate_to_tank
from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.leds import FrameUnusable, LedVision, perceive_leds
from fishswarm.bluebot.parameters import BlueBot
from fishswarm.bluebot.vision import Perceived
from fishswarm.sim.camera import Optics, render_views

FloatArray = NDArray[np.float64]

MATCH_FRACTION = 0.3
"""A detection is of the nearest fish when it lies within this fraction of that fish's range
(and at least 0.05 m) of it; otherwise it is a false detection."""


@dataclass(frozen=True)
class Cameras:
    """The simulated cameras and the pipeline that reads them.

    Attributes:
        fisheye: the cameras' projection.
        optics: LEDs and water.
        leds: the LED pipeline's settings.
        robot: the bodies that hide LEDs.
    """

    fisheye: Fisheye = field(default_factory=Fisheye)
    optics: Optics = field(default_factory=Optics)
    leds: LedVision = field(default_factory=LedVision)
    robot: BlueBot = field(default_factory=BlueBot)


def perceive_through_cameras(
    position: FloatArray,
    yaw: FloatArray,
    *,
    cameras: Cameras,
    rngs: Sequence[np.random.Generator],
) -> Perceived:
    """What every fish finds in its own two rendered camera images.

    Args:
        position: (N, 3) tank-frame positions, m (z down, surface at 0).
        yaw: (N,) yaws, rad.
        cameras: cameras, optics and pipeline.
        rngs: one generator per fish for its sensor noise (fish i's images draw only on
            ``rngs[i]``, so they do not depend on the other fish's draws).

    Returns:
        Each fish's detections, near to far, in its body frame; ``index`` names the fish a
        detection is of (−1 for a false detection and in padding).
    """
    count = position.shape[0]
    if len(rngs) != count:
        raise ValueError(f"camera vision needs one random generator per fish, got {len(rngs)}")
    found: list[FloatArray] = []
    for viewer in range(count):
        images = render_views(
            position,
            yaw,
            viewer,
            fisheye=cameras.fisheye,
            optics=cameras.optics,
            robot=cameras.robot,
            rng=rngs[viewer],
        )
        try:
            seen = perceive_leds(
                images,
                depth=float(position[viewer, 2]),
                fisheye=cameras.fisheye,
                vision=cameras.leds,
            )
        except FrameUnusable:
            # More lit spots than LEDs make (a school packed in front of the cameras): a
            # robot would skip the period; the simulated fish sees nothing this tick.
            seen = np.zeros((0, 3))
        found.append(seen)
    counts = np.array([rows.shape[0] for rows in found], dtype=np.int64)
    neighbors, mask = pad_rows(counts, np.concatenate(found or [np.zeros((0, 3))]).reshape(-1, 3))
    index = _match(position, yaw, neighbors, mask)
    return Perceived(neighbors, mask, index)


def _match(
    position: FloatArray, yaw: FloatArray, neighbors: FloatArray, mask: NDArray[np.bool_]
) -> NDArray[np.intp]:
    """(N, K) the fish each detection is of: the nearest other fish to it, when near enough."""
    count, width = mask.shape
    tank = rotate_to_tank(neighbors.reshape(-1, 3), np.repeat(yaw, width)).reshape(count, width, 3)
    tank += position[:, None, :]
    gap = np.linalg.norm(tank[:, :, None, :] - position[None, None, :, :], axis=3)  # (N, K, N)
    own = np.arange(position.shape[0])
    gap[own, :, own] = np.inf
    nearest = np.argmin(gap, axis=2) if gap.shape[2] > 1 else np.zeros(mask.shape, dtype=np.intp)
    true_range = np.linalg.norm(position[nearest] - position[:, None, :], axis=2)
    reach = np.maximum(0.05, MATCH_FRACTION * true_range)
    close = np.take_along_axis(gap, nearest[..., None], axis=2)[..., 0] <= reach
    index: NDArray[np.intp] = np.where(mask & close, nearest, -1).astype(np.intp)
    return index


@dataclass(frozen=True)
class SightCounts:
    """How camera vision compared with the geometric model, summed over fish and ticks.

    Attributes:
        visible: neighbours the geometric model says a fish sees.
        found: of those, the ones its cameras detected.
        detected: detections of any kind.
        false: detections of no fish (LEDs of different robots paired, a range far off).
        range_error: the sum over detections of real fish of |range error| / range.
    """

    visible: int = 0
    found: int = 0
    detected: int = 0
    false: int = 0
    range_error: float = 0.0

    def __add__(self, other: SightCounts) -> SightCounts:
        return SightCounts(
            self.visible + other.visible,
            self.found + other.found,
            self.detected + other.detected,
            self.false + other.false,
            self.range_error + other.range_error,
        )

    def summary(self) -> dict[str, float | int | None]:
        """Counts and rates, for a run's summary (rates None when there is nothing to rate)."""
        real = self.detected - self.false
        return {
            "visible": self.visible,
            "found": self.found,
            "detected": self.detected,
            "false": self.false,
            "recall": self.found / self.visible if self.visible else None,
            "false_rate": self.false / self.detected if self.detected else None,
            "mean_range_error": self.range_error / real if real else None,
        }


def score_sight(camera: Perceived, truth: Perceived, position: FloatArray) -> SightCounts:
    """Compare camera detections with the geometric model's neighbours, for one instant.

    Args:
        camera: what :func:`perceive_through_cameras` found.
        truth: what :func:`~fishswarm.bluebot.vision.perceive` (no noise) says is visible.
        position: (N, 3) the fish's tank-frame positions, m.
    """
    count = position.shape[0]
    found = 0
    for viewer in range(count):
        visible = truth.index[viewer, truth.mask[viewer]]
        detected = camera.index[viewer, camera.mask[viewer]]
        found += int(np.isin(visible, detected).sum())
    real = camera.mask & (camera.index >= 0)
    viewer_of = np.broadcast_to(np.arange(count)[:, None], camera.mask.shape)
    true_range = np.linalg.norm(position[camera.index[real]] - position[viewer_of[real]], axis=1)
    measured = np.linalg.norm(camera.neighbors[real], axis=1)
    return SightCounts(
        visible=int(truth.mask.sum()),
        found=found,
        detected=int(camera.mask.sum()),
        false=int((camera.mask & (camera.index < 0)).sum()),
        range_error=float(np.sum(np.abs(measured - true_range) / true_range)),
    )
