"""The BlueBot's and the tank's constants, with the values of SPEC.md §1.

One place for every robot number. Derived quantities (areas, inertia) are properties so
that changing a dimension keeps them consistent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

BODY_LENGTH = 0.13
"""Body length used by behaviours and the homing controller, m (SPEC §1.3)."""
VISUAL_RANGE = 3.0
"""How far a BlueBot sees its neighbours by default, m (SPEC §1.2)."""
BLIND_WIDTH = 0.05
"""Width of the blind strip behind a BlueBot's body, m (SPEC §1.2)."""
SPHERE_RADIUS = 0.065
"""Radius of the sphere a BlueBot blocks the view with, m (SPEC §1.2)."""


@dataclass(frozen=True)
class BlueBot:
    """Physical parameters of one BlueBot (SPEC.md §1.1).

    Attributes are SI: forces in N, lengths in m, density in kg/m³, mass in kg, angles in rad.
    The paper's model is the default; the study's code (SPEC §8) differs in three ways, each
    a switch here:

    - ``euler_step`` 0.1 s instead of 0.01 s;
    - ``speed_dependent_drag``: yaw drag coefficient ``drag_yaw·(1 + 9|v_x|/v_ref)``, lateral
      ``drag_y·(1 + 4|v_x|/v_ref)``, and ``drag_x_backward`` when v_x ≤ 0, with v_ref =
      ``speed_reference``;
    - ``yaw_before_update``: yaw is advanced with the yaw rate from before the substep's
      update (the paper's order uses the updated rate, as the velocities do).
    """

    caudal_force: float = 0.020
    dorsal_force: float = 0.020
    pectoral_force: float = 0.006
    pectoral_angle: float = math.pi / 6
    pectoral_arm: float = 0.055
    buoyancy: float = 0.010
    water_density: float = 998.0
    length: float = 0.150
    width: float = 0.050
    height: float = 0.080
    mass: float = 0.5
    drag_x: float = 0.5
    drag_y: float = 2.1
    drag_z: float = 0.7
    drag_yaw: float = 1.0
    euler_step: float = 0.01
    speed_dependent_drag: bool = False
    yaw_before_update: bool = False
    drag_x_backward: float = 1.0
    speed_reference: float = 0.16

    @property
    def area_x(self) -> float:
        """Frontal area A_x = π/4·h·w, m²."""
        return math.pi / 4 * self.height * self.width

    @property
    def area_y(self) -> float:
        """Lateral area A_y = π/4·l·h + 2·0.00075 (pectoral fins), m²."""
        return math.pi / 4 * self.length * self.height + 2 * 0.00075

    @property
    def area_z(self) -> float:
        """Top area A_z = π/4·l·w, m²."""
        return math.pi / 4 * self.length * self.width

    @property
    def area_yaw(self) -> float:
        """Area for yaw drag, A_φ = A_y, m²."""
        return self.area_y

    @property
    def inertia(self) -> float:
        """Yaw moment of inertia I = m/5·(l² + h²)/4, kg·m²."""
        return self.mass / 5 * (self.length**2 + self.height**2) / 4

    def terminal_speed(self) -> float:
        """Forward speed at full caudal where thrust equals drag, m/s (≈ 0.16)."""
        return math.sqrt(self.caudal_force / (0.5 * self.water_density * self.drag_x * self.area_x))


FIN_FREQUENCIES = ((1.0, 3.0), (6.0, 6.0), (1.0, 10.0), (1.0, 10.0))
"""The beat frequency of each fin (caudal, dorsal, pectoral left, pectoral right) from the
smallest gain above 0 to gain 1, Hz (SPEC §6: caudal about 1–3 Hz, dorsal about 6 Hz,
pectorals about 1–10 Hz); gain 0 is off."""


def fin_frequencies(fins: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B, 4) the beat frequency each fin runs at for gains (B, 4) in [0, 1], Hz: linear from
    the low to the high frequency of :data:`FIN_FREQUENCIES`, 0 for a gain of 0."""
    low, high = np.array(FIN_FREQUENCIES).T
    gains = np.clip(fins, 0.0, 1.0)
    frequency: NDArray[np.float64] = np.where(gains > 0.0, low + (high - low) * gains, 0.0)
    return frequency


def effort_rate(fins: NDArray[np.float64]) -> NDArray[np.float64]:
    """(B,) how fast fish with fin gains (B, 4) spend effort: the sum over fins of gain
    times beat frequency (:func:`fin_frequencies`), gain-weighted fin beats per second — a
    proxy of the energy the electromagnetic fins draw (SPEC §6)."""
    beats = np.clip(fins, 0.0, 1.0) * fin_frequencies(fins)
    # Column by column, in the order a sum over the row adds them, + 0.0 as the sum's start
    # would (a row of −0.0 sums to +0.0): the same bits, but numpy reduces a short axis
    # slowly (0.72 → 0.55 ms at 10 000 fish, twice a tick).
    rate: NDArray[np.float64] = beats[:, 0] + beats[:, 1] + beats[:, 2] + beats[:, 3] + 0.0
    return rate


@dataclass(frozen=True)
class Tank:
    """The tank: a box with its origin at a corner, z down (SPEC.md preamble).

    Attributes:
        size: (x, y, z) extent, m.
    """

    size: tuple[float, float, float] = (1.78, 1.78, 1.17)

    def __post_init__(self) -> None:
        if len(self.size) != 3 or not all(s > 0 and math.isfinite(s) for s in self.size):
            raise ValueError(f"tank size must be three positive lengths, got {self.size}")

    @property
    def center(self) -> NDArray[np.float64]:
        """Centre of the tank, m."""
        return np.asarray(self.size, dtype=np.float64) / 2

    @property
    def diagonal(self) -> float:
        """Horizontal diagonal, m (2.517 for the study's tank)."""
        return math.hypot(self.size[0], self.size[1])

    @classmethod
    def scaled_for(cls, fish: int, reference_fish: int = 25) -> Tank:
        """A tank whose horizontal area grows with the swarm so that density stays as with
        ``reference_fish`` fish in the study's tank."""
        base = cls()
        factor = math.sqrt(max(fish, reference_fish) / reference_fish)
        return cls((base.size[0] * factor, base.size[1] * factor, base.size[2]))


@dataclass(frozen=True)
class Wiring:
    """Where a BlueBot's parts are connected on its Raspberry Pi (SPEC §6, from the robot
    code of the public ``fberlinger/blueswarm`` repository).

    Attributes:
        fin_pins: the H-bridge pin pair of each fin (caudal, dorsal, pectoral left, pectoral
            right), BCM numbers.
        led_pin: the switch of all three LEDs, BCM.
        camera_select_pin: the pin that switches the multiplexer between the two fisheye
            cameras, BCM (the SoC's GPIO 40).
        camera_right_level: the select pin's level for the right camera (one robot of the
            study, BB01, was wired the other way round).
        depth_bus: the I²C bus of the pressure sensor.
        depth_address: the pressure sensor's I²C address.
    """

    fin_pins: tuple[tuple[int, int], ...] = ((20, 21), (19, 26), (18, 23), (4, 17))
    led_pin: int = 13
    camera_select_pin: int = 40
    camera_right_level: bool = True
    depth_bus: int = 1
    depth_address: int = 0x77


CAMERA_RESOLUTION = (256, 192)
"""Width and height of the images the robot's camera captures, pixels (SPEC §6)."""
CAMERA_FRAME_RATE = 60.0
"""Frames per second the camera streams at, Hz (SPEC §6)."""
CAMERA_COLOUR_GAINS = (1.0, 1.0)
"""Red and blue gains with automatic white balance off (SPEC §6): the LED pipeline's blue
threshold and its brightness-for-range check assume colours that do not drift."""
CAMERA_CAPTURE_TIMEOUT = 1.0
"""Longest wait for one frame, s (60 frames come in a second): a camera that stalls raises
``TimeoutError`` (picamera2's ``wait`` given in seconds) and the driver skips the period,
rather than its sensing waiting for ever."""
CAMERA_SWITCH_FRAMES = 2
"""Frames dropped after the multiplexer switches cameras: the frames already in flight were
exposed, at least in part, through the other camera (SPEC §6: expect dropped frames after a
switch). At 60 fps this costs 33 ms."""
LED_SPACING = 0.086
"""Distance between a BlueBot's two rear LEDs (one above the other) and from the upper one to
the front LED along the heading, m (SPEC §6)."""
LED_FLASH_FREQUENCY = 15.0
"""The rate at which the research code flashed the LEDs as a signal, Hz (SPEC §6)."""
GRAVITY = 9.81
"""Gravitational acceleration, m/s² (for depth from pressure)."""


@dataclass(frozen=True)
class FisheyeCalibration:
    """The BlueBot camera's calibration in Scaramuzza's omnidirectional polynomial model
    (OCamCalib), made at the sensor's full resolution (values from the robot code of the
    public ``fberlinger/blueswarm`` repository, ``fishfood/lib_utils.py``).

    A point on the sensor at (row, column) ``p`` comes from the sensor-plane point
    ``q = A⁻¹ (p − center)`` with ``A = [[c, d], [e, 1]]``; the ray through it is
    ``(q_row, q_column, −f(ρ))`` with ``ρ = |q|`` and ``f(ρ) = a0 + a1 ρ + a2 ρ² + …``.

    Attributes:
        center: the image centre (row, column) at full resolution, px.
        affine: (c, d, e) of the stretch matrix A.
        polynomial: a0, a1, … of f(ρ), ascending powers, px.
        full_width: width of the calibration images, px (the images the robot captures are
            scaled down from them by ``full_width / CAMERA_RESOLUTION[0]``).
        half_angle_deg: the widest angle from the optical axis that reaches the sensor, deg
            (our model's lens edge: at 100° the two cameras' fields meet in a blind strip
            behind the body as wide as the cameras are apart).
    """

    center: tuple[float, float] = (989.0661037168528, 1240.887736413883)
    affine: tuple[float, float, float] = (
        1.000095457005999,
        1.348821585691861e-04,
        -2.766447240107194e-05,
    )
    polynomial: tuple[float, ...] = (
        -550.6324725325824,
        0.0,
        4.199699653e-04,
        -3.65763e-08,
        2.906e-10,
    )
    full_width: int = 2592
    half_angle_deg: float = 100.0


CAMERA_AXIS_DEG = 80.0
"""Azimuth of the right camera's optical axis from the heading, deg: the cameras look sideways,
turned 10° towards the front (the left camera at −80°; blueswarm ``U_CAM_ALPHA``)."""
CAMERA_OFFSET = (0.025, 0.020, 0.0)
"""Where the right camera sits in the body frame, m (the left one at y = −0.020; blueswarm
``U_CAM_DX``, ``U_CAM_DY``)."""
LED_POSITIONS = (
    (0.0, 0.0, -LED_SPACING / 2),
    (0.0, 0.0, LED_SPACING / 2),
    (LED_SPACING, 0.0, -LED_SPACING / 2),
)
"""Where a BlueBot's three LEDs sit in its body frame, m: LED1 and LED2 one above the other
on the robot's vertical axis (the pair whose midpoint the study's perception, and ours, takes
as the robot's position), LED3 ahead of LED1 at the nose (SPEC §6). They sit proud of the
hull: a robot's own body does not hide them, other robots' bodies do."""
