"""The BlueBot's two fisheye cameras: one camera port, a multiplexer switched by a GPIO line.

The robot's cameras share the Pi's single camera connector through a multiplexer whose select
line is the SoC's GPIO 40 (the line the Pi's camera LED used; blueswarm's ``lib_camera.py``
sets it before each capture). gpiozero only addresses header pins and refuses GPIO 40, so
the line is driven through lgpio, the library gpiozero itself uses on Raspberry Pi OS.
Frames come from picamera2 (Raspberry Pi OS's ``python3-picamera2``, reached through the
venv's system site packages) streaming video at the robot's 256 × 192 and 60 fps, automatic
white balance off with gains (1, 1), as SPEC §6 has it: its ``RGB888`` format lays pixels out
as blue, green, red, so each frame is flipped to the RGB the LED pipeline expects. After the
multiplexer switches cameras the frames already in flight are dropped, and a frame that
does not come within a second raises ``TimeoutError`` (the driver skips the period). Both
libraries are imported only when the cameras are opened.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.parameters import (
    CAMERA_CAPTURE_TIMEOUT,
    CAMERA_COLOUR_GAINS,
    CAMERA_FRAME_RATE,
    CAMERA_RESOLUTION,
    CAMERA_SWITCH_FRAMES,
    Wiring,
)
from fishswarm.bluebot.ports import CameraSide

Select = Callable[[bool], None]
"""Sets the multiplexer's select line high (True) or low."""


class PiCameras:
    """Both cameras through picamera2. Implements the ``Camera`` port.

    Args:
        wiring: the select line and which level picks the right camera.
        resolution: (width, height) of the frames, px.
        camera: a started-or-not picamera2 ``Picamera2`` (None: open the Pi's camera).
        select: drives the select line (None: GPIO ``wiring.camera_select_pin`` via lgpio).
    """

    def __init__(
        self,
        *,
        wiring: Wiring = Wiring(),
        resolution: tuple[int, int] = CAMERA_RESOLUTION,
        camera: Any = None,
        select: Select | None = None,
    ) -> None:
        self._wiring = wiring
        self._release_select: Callable[[], None] = lambda: None
        if select is None:
            select, self._release_select = _lgpio_line(wiring.camera_select_pin)
        self._select = select
        try:
            if camera is None:
                camera = _open_picamera2()
            config = camera.create_video_configuration(
                main={"size": tuple(resolution), "format": "RGB888"},
                controls={
                    "FrameRate": CAMERA_FRAME_RATE,
                    "AwbEnable": False,
                    "ColourGains": CAMERA_COLOUR_GAINS,
                },
            )
            camera.configure(config)
            camera.start()
        except BaseException:
            self._release_select()
            raise
        self._camera = camera
        self._resolution = resolution
        self._level: bool | None = None
        """The select line's level now (None: not driven yet)."""

    def capture(self, side: CameraSide) -> NDArray[np.uint8]:
        """One frame of the camera on ``side``: (height, width, 3) RGB."""
        return self.capture_frames(side, 1)[0]

    def capture_frames(self, side: CameraSide, count: int) -> list[NDArray[np.uint8]]:
        """``count`` consecutive frames of the camera on ``side``: the stream's next ones
        after the switch (if any), taken back to back, so one frame period apart as long as
        each is fetched before the next is exposed."""
        level = (side == "right") == self._wiring.camera_right_level
        if level != self._level:
            self._select(level)
            self._level = level
            for _ in range(CAMERA_SWITCH_FRAMES):
                self._camera.capture_array("main", wait=CAMERA_CAPTURE_TIMEOUT)
        taken = [
            self._camera.capture_array("main", wait=CAMERA_CAPTURE_TIMEOUT) for _ in range(count)
        ]
        return [self._rgb(frame) for frame in taken]

    def _rgb(self, captured: object) -> NDArray[np.uint8]:
        """A captured frame as (height, width, 3) RGB, checked."""
        frame = np.asarray(captured)
        width, height = self._resolution
        if frame.shape[:2] != (height, width) or frame.shape[2] < 3:
            raise RuntimeError(
                f"the camera gave a {frame.shape} frame, expected ({height}, {width}, 3)"
            )
        rgb: NDArray[np.uint8] = np.ascontiguousarray(frame[:, :, 2::-1], dtype=np.uint8)
        return rgb

    def close(self) -> None:
        """Stop and release the camera and the select line."""
        try:
            self._camera.stop()
            self._camera.close()
        finally:
            self._release_select()


def _open_picamera2() -> Any:
    try:
        from picamera2 import Picamera2
    except ImportError as error:
        raise ImportError(
            "the cameras need picamera2: on Raspberry Pi OS, apt install python3-picamera2 "
            "and make the venv with --system-site-packages"
        ) from error
    return Picamera2()


def _lgpio_line(pin: int) -> tuple[Select, Callable[[], None]]:
    """An output line on the Pi's GPIO chip 0 and how to release it."""
    try:
        import lgpio
    except ImportError as error:
        raise ImportError(
            "the camera switch needs lgpio: on Raspberry Pi OS, apt install python3-lgpio"
        ) from error
    # lgpio raises its own error type (not an OSError): said as a RuntimeError, which the
    # robot reports as hardware it could not open, with the chip closed again.
    try:
        chip = lgpio.gpiochip_open(0)
    except lgpio.error as error:
        raise RuntimeError(f"cannot open GPIO chip 0 for the camera switch: {error}") from error
    try:
        lgpio.gpio_claim_output(chip, pin, 0)
    except lgpio.error as error:
        lgpio.gpiochip_close(chip)
        raise RuntimeError(f"cannot claim GPIO {pin} for the camera switch: {error}") from error

    def select(level: bool) -> None:
        lgpio.gpio_write(chip, pin, int(level))

    def release() -> None:
        lgpio.gpio_free(chip, pin)
        lgpio.gpiochip_close(chip)

    return select, release
