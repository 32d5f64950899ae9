"""The BlueBot's hardware ports: what the robot driver needs of fins, LEDs, camera and depth
sensor, as small protocols.

Each port has a hardware implementation (``bluebot.gpio``, ``bluebot.pressure``, the camera
module; their libraries imported only when one is opened, from the ``robot`` extra) and a
simulated one for tests and for mock robots. The driver reads the sensors and writes the
actuators through these ports only, as a ros2_control hardware interface would: nothing
above them knows which is which.
"""

from __future__ import annotations

from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray

CameraSide = Literal["left", "right"]
CAMERA_SIDES: tuple[CameraSide, CameraSide] = ("left", "right")
"""Both cameras, left first."""


class Fins(Protocol):
    """The four fins (caudal, dorsal, pectoral left, pectoral right)."""

    def set_gains(self, gains: NDArray[np.float64]) -> None:
        """Beat each fin at the frequency its gain in [0, 1] maps to (0: off); (4,)."""
        ...

    def stop(self) -> None:
        """All fins off, at once."""
        ...

    def close(self) -> None:
        """Stop the fins and release their pins."""
        ...


class Leds(Protocol):
    """The three LEDs, on one switch."""

    def set_lit(self, lit: bool) -> None:
        """Switch the LEDs on or off (a flashing stops)."""
        ...

    def set_flashing(self, frequency: float) -> None:
        """Flash the LEDs at ``frequency`` Hz, lit for the first half of each period, until
        the next call of either method."""
        ...

    def close(self) -> None:
        """Switch the LEDs off and release their pin."""
        ...


class Camera(Protocol):
    """The two fisheye cameras behind one multiplexer."""

    def capture(self, side: CameraSide) -> NDArray[np.uint8]:
        """One image of the camera on ``side``: (height, width, 3) RGB."""
        ...

    def capture_frames(self, side: CameraSide, count: int) -> list[NDArray[np.uint8]]:
        """``count`` consecutive frames of the camera on ``side``, one frame period apart
        (1/60 s), each (height, width, 3) RGB."""
        ...

    def close(self) -> None:
        """Release the camera."""
        ...


class DepthSensor(Protocol):
    """The pressure sensor, read as depth below the surface."""

    def read_depth(self) -> float:
        """Depth below the water surface, m (positive down)."""
        ...

    def close(self) -> None:
        """Release the sensor's bus."""
        ...
