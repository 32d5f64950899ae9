"""A mock robot's sensors, fed by the world's snapshots: fresh for longer than the period at
which a realtime world sends them, stale once the link has been quiet for longer."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.actors.driver import SensorUnavailable
from fishswarm.actors.mock_robot import (
    STALE_AFTER,
    BodyFins,
    SnapshotCamera,
    SnapshotDepth,
    WorldFeed,
    stale_after,
)
from fishswarm.bluebot.ports import CameraSide
from fishswarm.protocols.messages import DARK, FLASHING, STEADY, Snapshot


class Clock:
    """Wall-clock time the test sets, s."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def snapshot(tick: int) -> Snapshot:
    one = np.zeros(1)
    return Snapshot(
        tick, float(tick), np.array([3]), np.array([[0.9, 0.9, 0.5]]), np.zeros((1, 3)), one,
        np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), one,
    )  # fmt: skip


@pytest.mark.parametrize("period", [0.2, 1.0, 2.0])
@pytest.mark.parametrize("phase", [0.1, 0.5, 0.95])
def test_a_driver_reading_at_any_phase_of_the_period_gets_every_snapshot(
    period: float, phase: float
) -> None:
    # The world sends a snapshot at every k·period; the driver reads at k·period + phase.
    clock = Clock()
    feed = WorldFeed(3, stale_after=stale_after(period), clock=clock)
    depth = SnapshotDepth(feed)
    readings = 0
    for tick in range(10):
        clock.now = tick * period
        feed.take(snapshot(tick))
        clock.now = (tick + phase) * period
        assert depth.read_depth() == pytest.approx(0.5)
        readings += 1
    assert readings == 10


def test_a_snapshot_goes_stale_when_the_link_is_quiet_for_longer() -> None:
    assert stale_after(0.2) == STALE_AFTER  # short periods keep the floor
    assert stale_after(1.0) == pytest.approx(1.5)
    clock = Clock()
    feed = WorldFeed(3, stale_after=stale_after(1.0), clock=clock)
    feed.take(snapshot(0))
    clock.now = 1.4
    assert SnapshotDepth(feed).read_depth() == pytest.approx(0.5)
    clock.now = 1.6  # the next snapshot, due at 1 s, never came
    with pytest.raises(SensorUnavailable, match=r"1\.6 s old"):
        SnapshotDepth(feed).read_depth()


def test_the_mock_robots_sensors_keep_snapshots_for_its_period() -> None:
    from fishswarm.actors.mock_robot import open_mock_hardware
    from fishswarm.protocols.keys import KeySpace

    with open_mock_hardware(3, KeySpace(), control_period=1.0) as (hardware, _):
        assert isinstance(hardware.depth, SnapshotDepth)
        assert hardware.depth.feed.stale_after == pytest.approx(1.5)


class RecordingFins:
    """Fins that note what they were told."""

    def __init__(self) -> None:
        self.told: list[str] = []

    def set_gains(self, gains: np.ndarray) -> None:
        self.told.append(f"gains {np.asarray(gains).tolist()}")

    def stop(self) -> None:
        self.told.append("stop")

    def close(self) -> None:
        self.told.append("close")


def test_a_stopped_mock_robot_tells_its_simulated_body_its_fins_are_off() -> None:
    # The body answers the world with the gains it holds: a stop must zero them, or the
    # simulated robot would swim on while its pins are still.
    pins = RecordingFins()
    fins = BodyFins(pins)
    fins.set_gains(np.array([1.0, 0.0, 0.5, 0.0]))
    assert fins.gains.tolist() == [1.0, 0.0, 0.5, 0.0]
    fins.stop()
    assert fins.gains.tolist() == [0.0, 0.0, 0.0, 0.0]
    assert pins.told == ["gains [1.0, 0.0, 0.5, 0.0]", "stop"]


def test_the_body_holds_gains_clipped_to_what_fins_can_do() -> None:
    fins = BodyFins(RecordingFins())
    fins.set_gains(np.array([1.5, -0.2, 0.5, 0.0]))
    assert fins.gains.tolist() == [1.0, 0.0, 0.5, 0.0]


def test_the_mock_camera_renders_once_per_snapshot_and_again_for_the_next() -> None:
    """Both sides come from one rendering of a snapshot (the driver reads them one after
    the other); the next snapshot, with the neighbour moved, gives new images."""
    from fishswarm.actors.mock_robot import SnapshotCamera

    def pair(tick: int, neighbour_x: float) -> Snapshot:
        two = np.zeros(2)
        return Snapshot(
            tick, float(tick), np.array([3, 4]),
            np.array([[0.9, 0.9, 0.5], [neighbour_x, 0.9, 0.5]]), np.zeros((2, 3)), two,
            np.zeros(2, dtype=np.int64), np.zeros(2, dtype=np.int64), np.ones(2),
        )  # fmt: skip

    clock = Clock()
    feed = WorldFeed(3, clock=clock)
    camera = SnapshotCamera(feed)
    feed.take(pair(0, 1.3))
    first = camera.capture("right")
    assert camera.capture("right") is first
    feed.take(pair(1, 1.6))
    moved = camera.capture("right")
    assert moved is not first and not np.array_equal(moved, first)
    assert camera.capture("right") is moved


def test_the_mock_camera_shows_a_flashing_robot_lit_half_of_each_flash_period() -> None:
    """A robot the snapshot tells flashing is lit when a frame's time falls in the first
    half of its flash period (from a phase fixed by its id) and dark in the second; a dark
    robot is never seen; the others shine all the time. A burst's frames are a frame period
    apart. Each set of lit LEDs is rendered once per snapshot."""
    from fishswarm.actors.mock_robot import GOLDEN_FRACTION
    from fishswarm.bluebot.flashes import FRAME_GAP, FRAMES_APART
    from fishswarm.bluebot.leds import LedVision, perceive_leds
    from fishswarm.bluebot.ports import CAMERA_SIDES

    # The viewer 3 facing +x; 4 ahead, 5 to its right and 6 to its left, all 0.6 m away.
    ids = np.array([3, 4, 5, 6])
    position = np.array([[0.9, 0.9, 0.5], [1.5, 0.9, 0.5], [0.9, 1.5, 0.5], [0.9, 0.3, 0.5]])
    clock, camera = still_camera(ids, position, [STEADY, STEADY, FLASHING, DARK])
    period = 2 * FRAME_GAP
    start = (5 * GOLDEN_FRACTION) % 1.0 * period  # robot 5's period starts here

    def seen(images: dict[CameraSide, np.ndarray]) -> int:
        found = perceive_leds(images, depth=0.5, fisheye=camera.fisheye, vision=LedVision())
        return int(found.shape[0])

    def seen_at(time: float) -> int:
        clock.now = time
        return seen({side: camera.capture(side) for side in CAMERA_SIDES})

    assert seen_at(start + 0.1 * period) == 2  # lit: robots 4 and 5 (6 is dark)
    assert seen_at(start + 0.6 * period) == 1  # dark: only robot 4
    assert seen_at(start + 1.2 * period) == 2
    lit_again = camera.capture("right")
    clock.now = start + 2.3 * period
    assert camera.capture("right") is lit_again  # the same LEDs lit: not rendered again
    # A burst from early in the lit half: its first frame shows robot 5, the frame two
    # frame periods (half a flash period) later does not.
    clock.now = start + 0.05 * period
    burst = {side: camera.capture_frames(side, FRAMES_APART + 1) for side in CAMERA_SIDES}
    assert seen({side: frames[0] for side, frames in burst.items()}) == 2
    assert seen({side: frames[-1] for side, frames in burst.items()}) == 1


def test_a_mock_robots_commands_say_its_leds_flash_only_while_they_do() -> None:
    """The body answers each of the world's perceptions with a command that tells the
    world its LEDs: flashing while gpiozero blinks them (lit, whatever half of the period
    the pin is in), steady or dark otherwise (the world's snapshots tell other robots'
    cameras)."""
    import trio

    from fishswarm.actors.bus import MemoryBus
    from fishswarm.actors.mock_robot import open_mock_hardware
    from fishswarm.protocols.codec import decode, encode
    from fishswarm.protocols.keys import KeySpace
    from fishswarm.protocols.messages import Command, Perception
    from tests.conftest import run_mock, subscription

    keys = KeySpace()
    told: list[tuple[bool, bool | None]] = []
    with open_mock_hardware(7, keys) as (hardware, body):

        async def main() -> None:
            bus = MemoryBus()
            async with (
                subscription(bus, keys.command(7)) as commands,
                trio.open_nursery() as nursery,
            ):
                await nursery.start(body.run, bus)
                for tick, show in enumerate(("steady", "flashing", "dark", "flashing", "steady")):
                    if show == "flashing":
                        hardware.leds.set_flashing(15.0)
                    else:
                        hardware.leds.set_lit(show == "steady")
                    perception = Perception(7, tick, 0.0, 0.5, np.zeros((0, 3)), np.zeros((0, 3)))
                    bus.put(keys.perception(7), encode(perception))
                    command = decode((await commands.receive())[1], Command)
                    told.append((command.led, command.flashing))
                nursery.cancel_scope.cancel()

        run_mock(main)
    steady, flashing, dark = (True, None), (True, True), (False, None)
    assert told == [steady, flashing, dark, flashing, steady]


def test_the_mock_camera_flashes_robots_each_from_a_phase_of_its_own() -> None:
    """Flashing robots are not in step: each one's flash period starts at its id times the
    golden fraction (mod 1) of the period, the same in every robot's cameras. Robots 4 and
    5, both flashing, both 0.6 m ahead of the viewer 3, one to each side: in the lit half of
    robot 5's period robot 4 (whose period starts 0.38 of one later) is dark."""
    from fishswarm.actors.mock_robot import GOLDEN_FRACTION
    from fishswarm.bluebot.flashes import FRAME_GAP
    from fishswarm.bluebot.leds import LedVision, perceive_leds
    from fishswarm.bluebot.ports import CAMERA_SIDES

    ids = np.array([3, 4, 5])
    position = np.array([[0.9, 0.9, 0.5], [1.4, 1.25, 0.5], [1.4, 0.55, 0.5]])
    clock, camera = still_camera(ids, position, [STEADY, FLASHING, FLASHING])
    period = 2 * FRAME_GAP
    phase = {fish: (fish * GOLDEN_FRACTION) % 1.0 for fish in (4, 5)}
    assert phase[4] - phase[5] == pytest.approx(0.382, abs=1e-3)

    def seen_at(cycles: float) -> np.ndarray:
        clock.now = cycles * period
        images = {side: camera.capture(side) for side in CAMERA_SIDES}
        return perceive_leds(images, depth=0.5, fisheye=camera.fisheye, vision=LedVision())

    # Early in robot 5's lit half (robot 4 still in its dark half): robot 5 alone, to the
    # viewer's right (negative y in its body frame).
    alone = seen_at(phase[5] + 0.05)
    assert alone.shape[0] == 1 and alone[0, 1] < 0
    # Early in robot 4's lit half (robot 5 still lit too): both.
    assert seen_at(phase[4] + 0.05).shape[0] == 2
    # Robot 5 dark, robot 4 lit: robot 4 alone, to the left.
    left = seen_at(phase[5] + 0.55)
    assert left.shape[0] == 1 and left[0, 1] > 0


def still_camera(
    ids: np.ndarray, position: np.ndarray, lights: list[int]
) -> tuple[Clock, SnapshotCamera]:
    """Robot ``ids[0]``'s mock cameras on a snapshot of fish at ``position`` (all at rest),
    their LEDs as ``lights`` say, and the clock that times each frame."""
    count = ids.size
    snapshot = Snapshot(
        0, 0.0, ids, position, np.zeros((count, 3)), np.zeros(count),
        np.zeros(count, dtype=np.int64), np.zeros(count, dtype=np.int64), np.zeros(count),
        lights=np.array(lights),
    )  # fmt: skip
    clock = Clock()
    feed = WorldFeed(int(ids[0]), clock=clock)
    camera = SnapshotCamera(feed, clock=clock)
    feed.take(snapshot)
    return clock, camera
