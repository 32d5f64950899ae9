"""The BlueBot's fisheye cameras: pixels to rays and back, and where the cameras sit.

A :class:`Fisheye` is one camera's calibration (Scaramuzza's polynomial model, see
:class:`~fishswarm.bluebot.parameters.FisheyeCalibration`) scaled to the images the robot
captures. :func:`camera_to_body` and :func:`camera_position` place the left and right camera
on the body. Pixels are (row, column) with the origin at the centre of the top-left pixel;
camera-frame rays are (down the rows, along the columns, along the optical axis) and unit
length. Pure numpy: this runs on the robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import (
    CAMERA_AXIS_DEG,
    CAMERA_OFFSET,
    CAMERA_RESOLUTION,
    FisheyeCalibration,
)
from fishswarm.bluebot.ports import CameraSide

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_TABLE_SIZE = 4096


@dataclass(frozen=True)
class Fisheye:
    """A fisheye camera's projection at the resolution the robot captures.

    Attributes:
        calibration: the full-resolution calibration.
        width, height: the captured image's size, px.
    """

    calibration: FisheyeCalibration = field(default_factory=FisheyeCalibration)
    width: int = CAMERA_RESOLUTION[0]
    height: int = CAMERA_RESOLUTION[1]
    _table: tuple[FloatArray, FloatArray] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"image size must be positive, got {self.width}×{self.height}")
        if not 0 < self.calibration.half_angle_deg < 180:
            raise ValueError("the lens's half angle must lie in (0, 180) degrees")
        # The angle from the axis grows with ρ over the lens; a table of it (cut where it
        # stops growing or passes the lens edge) starts the inversion of ray → pixel.
        rho = np.linspace(0.0, 2.0 * self.calibration.full_width, _TABLE_SIZE)
        angle = np.arctan2(rho, -self._f(rho))
        rising = np.flatnonzero(np.diff(angle) <= 0)
        end = int(rising[0]) + 1 if rising.size else rho.size
        edge = math.radians(self.calibration.half_angle_deg)
        if angle[end - 1] < edge:
            raise ValueError("the calibration polynomial does not reach the lens's half angle")
        object.__setattr__(self, "_table", (angle[:end], rho[:end]))

    @property
    def scale(self) -> float:
        """Full-resolution pixels per captured pixel."""
        return self.calibration.full_width / self.width

    @property
    def pixels_per_radian(self) -> float:
        """Captured pixels per radian off the optical axis, near the axis (−a0 / scale)."""
        return -self.calibration.polynomial[0] / self.scale

    def _f(self, rho: FloatArray) -> FloatArray:
        value = np.polynomial.polynomial.polyval(rho, self.calibration.polynomial)
        return np.asarray(value, dtype=np.float64)

    def _df(self, rho: FloatArray) -> FloatArray:
        coefficients = np.polynomial.polynomial.polyder(self.calibration.polynomial)
        value = np.polynomial.polynomial.polyval(rho, coefficients)
        return np.asarray(value, dtype=np.float64)

    def pixel_to_ray(self, pixels: FloatArray) -> FloatArray:
        """Unit rays in the camera frame through image points.

        Args:
            pixels: (N, 2) (row, column) in the captured image, px (sub-pixel allowed).

        Returns:
            (N, 3) unit rays (down the rows, along the columns, along the optical axis).
        """
        c, d, e = self.calibration.affine
        stretched = np.asarray(pixels, dtype=np.float64) * self.scale - self.calibration.center
        # q = A⁻¹ (p − centre) with A = [[c, d], [e, 1]].
        determinant = c - d * e
        row = (stretched[:, 0] - d * stretched[:, 1]) / determinant
        column = (c * stretched[:, 1] - e * stretched[:, 0]) / determinant
        rho = np.hypot(row, column)
        rays = np.stack([row, column, -self._f(rho)], axis=1)
        normalised: FloatArray = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        return normalised

    def ray_to_pixel(self, rays: FloatArray) -> tuple[FloatArray, BoolArray]:
        """Where rays in the camera frame meet the image.

        Args:
            rays: (N, 3) directions in the camera frame (any length > 0).

        Returns:
            (N, 2) (row, column) in the captured image, px, and (N,) whether each ray passes
            through the lens (within its half angle) and lands inside the image.
        """
        rays = np.asarray(rays, dtype=np.float64)
        planar = np.hypot(rays[:, 0], rays[:, 1])
        angle = np.arctan2(planar, rays[:, 2])
        angles, rhos = self._table
        rho = np.interp(angle, angles, rhos)
        # Newton on g(ρ) = ρ·axial + planar·f(ρ) = 0, whose root is the table's guess refined.
        axial = rays[:, 2]
        for _ in range(3):
            g = rho * axial + planar * self._f(rho)
            slope = axial + planar * self._df(rho)
            safe = np.abs(slope) > 1e-12
            rho = np.where(safe, rho - np.divide(g, slope, out=np.zeros_like(g), where=safe), rho)
        with np.errstate(invalid="ignore", divide="ignore"):
            row_part = np.where(planar > 0, rays[:, 0] / planar, 0.0)
            column_part = np.where(planar > 0, rays[:, 1] / planar, 0.0)
        row, column = rho * row_part, rho * column_part
        c, d, e = self.calibration.affine
        full = np.stack([c * row + d * column, e * row + column], axis=1) + self.calibration.center
        pixels: FloatArray = full / self.scale
        inside = (
            (angle <= math.radians(self.calibration.half_angle_deg))
            & (pixels[:, 0] >= -0.5)
            & (pixels[:, 0] < self.height - 0.5)
            & (pixels[:, 1] >= -0.5)
            & (pixels[:, 1] < self.width - 0.5)
            & np.isfinite(planar)
        )
        return pixels, inside


def camera_to_body(side: CameraSide) -> FloatArray:
    """(3, 3) the matrix that turns camera-frame rays of the camera on ``side`` into the body
    frame (x forward, y right, z down): image rows point down, the optical axis points
    sideways 10° ahead of the beam, and columns run from front to back on the right camera
    (back to front on the left), as the cameras are mounted."""
    sign = 1.0 if side == "right" else -1.0
    axis_angle = math.radians(CAMERA_AXIS_DEG)
    axis = np.array([math.cos(axis_angle), sign * math.sin(axis_angle), 0.0])
    down = np.array([0.0, 0.0, 1.0])
    columns = np.cross(down, axis)
    matrix: FloatArray = np.stack([down, columns, axis], axis=1)
    return matrix


def camera_position(side: CameraSide) -> FloatArray:
    """(3,) where the camera on ``side`` sits in the body frame, m."""
    x, y, z = CAMERA_OFFSET
    return np.array([x, y if side == "right" else -y, z])
