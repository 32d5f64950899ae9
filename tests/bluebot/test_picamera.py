"""Both cameras through one picamera2 port and the multiplexer's select line, with frames
rendered from the simulator served in picamera2's RGB888 (blue, green, red) layout."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.leds import LedVision, perceive_leds
from fishswarm.bluebot.parameters import BlueBot, Wiring
from fishswarm.bluebot.picamera import PiCameras
from fishswarm.bluebot.ports import CameraSide
from fishswarm.sim.camera import Optics, render_views

POSITION = np.array([[0.8, 0.8, 0.5], [1.0, 1.5, 0.45]])
YAW = np.array([0.0, 0.5])
IMAGES = render_views(
    POSITION,
    YAW,
    0,
    fisheye=Fisheye(),
    optics=Optics(),
    robot=BlueBot(),
    rng=np.random.default_rng(0),
)


class MuxedCamera:
    """Picamera2's calls as the driver makes them, behind a two-way multiplexer."""

    def __init__(self) -> None:
        self.line = False
        self.calls: list[Any] = []

    def select(self, level: bool) -> None:
        self.line = level
        self.calls.append(("select", level))

    def create_still_configuration(self, main: dict[str, Any]) -> dict[str, Any]:
        return {"main": main}

    def configure(self, config: dict[str, Any]) -> None:
        self.calls.append(("configure", config))

    def start(self) -> None:
        self.calls.append("start")

    def capture_array(self, stream: str) -> np.ndarray:
        side: CameraSide = "right" if self.line else "left"
        return IMAGES[side][:, :, ::-1].copy()  # RGB888 is laid out B, G, R

    def stop(self) -> None:
        self.calls.append("stop")

    def close(self) -> None:
        self.calls.append("close")


def test_each_side_selects_its_camera_and_frames_come_back_rgb() -> None:
    device = MuxedCamera()
    cameras = PiCameras(camera=device, select=device.select)
    assert device.calls[:2] == [
        ("configure", {"main": {"size": (256, 192), "format": "RGB888"}}),
        "start",
    ]
    right, left = cameras.capture("right"), cameras.capture("left")
    assert device.calls[2:] == [("select", True), ("select", False)]
    np.testing.assert_array_equal(right, IMAGES["right"])
    np.testing.assert_array_equal(left, IMAGES["left"])
    # The pipeline finds the neighbour in what the port returns.
    found = perceive_leds(
        {"left": left, "right": right}, depth=0.5, fisheye=Fisheye(), vision=LedVision()
    )
    assert found.shape == (1, 3)
    np.testing.assert_allclose(
        np.linalg.norm(found[0]), np.linalg.norm(POSITION[1] - POSITION[0]), rtol=0.02
    )
    cameras.close()
    assert device.calls[-2:] == ["stop", "close"]


def test_a_robot_wired_the_other_way_round_selects_the_other_level() -> None:
    device = MuxedCamera()
    cameras = PiCameras(
        camera=device, select=device.select, wiring=Wiring(camera_right_level=False)
    )
    cameras.capture("right")
    assert device.calls[-1] == ("select", False)


def test_a_frame_of_the_wrong_size_is_an_error() -> None:
    device = MuxedCamera()
    cameras = PiCameras(camera=device, select=device.select, resolution=(320, 240))
    with pytest.raises(RuntimeError, match=r"expected \(240, 320, 3\)"):
        cameras.capture("left")
