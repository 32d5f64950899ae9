"""Both cameras through one picamera2 port and the multiplexer's select line, with frames
rendered from the simulator served in picamera2's RGB888 (blue, green, red) layout."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.leds import LedVision, perceive_leds
from fishswarm.bluebot.parameters import CAMERA_SWITCH_FRAMES, BlueBot, Wiring
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
    """Picamera2's calls as the driver makes them, behind a two-way multiplexer whose
    switch the stream shows ``in_flight`` frames late (frames already exposed)."""

    def __init__(self, in_flight: int = CAMERA_SWITCH_FRAMES) -> None:
        self.line = False
        self.showing: CameraSide = "left"
        self.late = 0
        self.in_flight = in_flight
        self.frames = 0
        self.waits: set[float | None] = set()
        self.calls: list[Any] = []

    def select(self, level: bool) -> None:
        if level != self.line:
            self.late = self.in_flight
        self.line = level
        self.calls.append(("select", level))

    def create_video_configuration(
        self, main: dict[str, Any], controls: dict[str, Any]
    ) -> dict[str, Any]:
        return {"main": main, "controls": controls}

    def configure(self, config: dict[str, Any]) -> None:
        self.calls.append(("configure", config))

    def start(self) -> None:
        self.calls.append("start")

    def capture_array(self, stream: str, wait: float | None = None) -> np.ndarray:
        self.waits.add(wait)
        self.frames += 1
        if self.late:
            self.late -= 1
        else:
            self.showing = "right" if self.line else "left"
        return IMAGES[self.showing][:, :, ::-1].copy()  # RGB888 is laid out B, G, R

    def stop(self) -> None:
        self.calls.append("stop")

    def close(self) -> None:
        self.calls.append("close")


def test_each_side_selects_its_camera_and_frames_come_back_rgb() -> None:
    device = MuxedCamera()
    cameras = PiCameras(camera=device, select=device.select)
    # Video at 60 fps, white balance fixed (SPEC §6).
    controls = {"FrameRate": 60.0, "AwbEnable": False, "ColourGains": (1.0, 1.0)}
    assert device.calls[:2] == [
        ("configure", {"main": {"size": (256, 192), "format": "RGB888"}, "controls": controls}),
        "start",
    ]
    right, left = cameras.capture("right"), cameras.capture("left")
    assert device.calls[2:] == [("select", True), ("select", False)]
    # Each switch dropped the frames in flight, which still showed the other camera; every
    # frame was waited for at most a second.
    assert device.frames == 2 * (CAMERA_SWITCH_FRAMES + 1)
    assert device.waits == {1.0}
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


def test_frames_of_one_camera_come_without_drops_until_it_switches() -> None:
    device = MuxedCamera()
    cameras = PiCameras(camera=device, select=device.select)
    for _ in range(3):
        np.testing.assert_array_equal(cameras.capture("right"), IMAGES["right"])
    assert device.frames == CAMERA_SWITCH_FRAMES + 3
    assert [call for call in device.calls if call[0] == "select"] == [("select", True)]


def test_without_the_drops_a_switch_would_return_the_other_cameras_frame() -> None:
    # The stand-in's lag is what the drops are for: a device with one more frame in flight
    # than the driver drops hands back the camera it switched away from.
    device = MuxedCamera(in_flight=CAMERA_SWITCH_FRAMES + 1)
    cameras = PiCameras(camera=device, select=device.select)
    np.testing.assert_array_equal(cameras.capture("right"), IMAGES["left"])


class FakeLgpio:
    """lgpio's calls the camera switch makes, with a line another process holds."""

    class error(Exception):  # noqa: N801 (lgpio's own name)
        pass

    def __init__(self) -> None:
        self.closed: list[int] = []

    def gpiochip_open(self, chip: int) -> int:
        return 7

    def gpio_claim_output(self, handle: int, pin: int, level: int) -> None:
        raise self.error("GPIO busy")

    def gpiochip_close(self, handle: int) -> None:
        self.closed.append(handle)


def test_a_camera_switch_line_that_cannot_be_claimed_is_a_clear_error(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import sys

    lgpio = FakeLgpio()
    monkeypatch.setitem(sys.modules, "lgpio", lgpio)
    with pytest.raises(RuntimeError, match="cannot claim GPIO 40 for the camera switch: GPIO busy"):
        PiCameras(camera=MuxedCamera())
    assert lgpio.closed == [7]  # the chip is not left open


class StalledCamera(MuxedCamera):
    """A camera that stops delivering frames: picamera2 raises after ``wait`` seconds."""

    def capture_array(self, stream: str, wait: float | None = None) -> np.ndarray:
        if wait is None:
            raise AssertionError("a capture without a timeout would wait for ever")
        raise TimeoutError(f"no frame within {wait} s")


def test_a_stalled_camera_is_a_sensor_failure_the_driver_skips() -> None:
    from fishswarm.actors.driver import SENSOR_ERRORS

    device = StalledCamera()
    cameras = PiCameras(camera=device, select=device.select)
    with pytest.raises(TimeoutError) as stalled:
        cameras.capture("left")
    assert isinstance(stalled.value, SENSOR_ERRORS)


def test_a_burst_is_one_cameras_next_frames_back_to_back_after_one_switch() -> None:
    """Both of a camera's frames for the flashes (``capture_frames``) come from one switch:
    the frames in flight dropped once, then ``count`` frames one after the other, each one
    frame period after the last; the other side then switches once more."""
    device = MuxedCamera()
    cameras = PiCameras(camera=device, select=device.select)
    right = cameras.capture_frames("right", 3)
    assert device.frames == CAMERA_SWITCH_FRAMES + 3 and len(right) == 3
    for frame in right:
        np.testing.assert_array_equal(frame, IMAGES["right"])
    left = cameras.capture_frames("left", 3)
    assert device.frames == 2 * (CAMERA_SWITCH_FRAMES + 3)
    np.testing.assert_array_equal(left[0], IMAGES["left"])
    assert [call for call in device.calls if call[0] == "select"] == [
        ("select", True),
        ("select", False),
    ]
