"""A BlueBot on a laptop: the driver's ports on gpiozero's mock pins, and its cameras and depth
sensor fed from a simulated world over Zenoh.

A mock robot is a fish of a running simulated world. Its body lives in that world: the
:class:`MockBody` answers the world's perceptions for it with the gains its fins hold now
(so the world moves it as its fins beat) and keeps the world's latest snapshot, from which
:class:`SnapshotCamera` renders both camera images (:func:`~fishswarm.sim.camera.
render_views`) and :class:`SnapshotDepth` reads its depth. A robot whose LEDs flash (its
formation flag by light) says so in its commands, as one whose LEDs are off does; the
world tells every fish's LEDs in its snapshots, and the cameras show a flashing robot's LEDs
lit or dark as the capture's time falls in its flash period, and a dark robot's not at all.
What the robot perceives comes over its link, as a real robot's light comes through the
water: cut the link and the frames go stale, the driver stops perceiving, and its failsafe
stops the fins.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trio
from numpy.typing import NDArray

from fishswarm.actors.bus import Bus, open_subscriber, open_token
from fishswarm.actors.driver import Hardware, HardwareError, SensorUnavailable
from fishswarm.actors.inbox import open_subscription
from fishswarm.actors.intake import Intake
from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.flashes import lit_at
from fishswarm.bluebot.gpio import GpioFins, GpioLeds
from fishswarm.bluebot.parameters import CAMERA_FRAME_RATE, BlueBot
from fishswarm.bluebot.ports import CameraSide, Fins
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import DARK, FLASHING, Command, Perception, Snapshot
from fishswarm.sim.camera import Optics, render_views

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

STALE_AFTER = 0.6
"""A snapshot older than this (wall-clock s) gives no camera frame or depth reading, or than
:data:`STALE_PERIODS` control periods when that is longer."""
GOLDEN_FRACTION = (math.sqrt(5) - 1) / 2
"""Where each flashing robot's period starts, as a fraction of it: fish id times this, modulo
1 — spread out, and the same in every robot's cameras."""
STALE_PERIODS = 1.5
"""A realtime world sends one snapshot a control period, and the driver reads at its own
phase in the period: a snapshot must stay fresh for more than a period, or a driver whose
phase falls late would never see one."""


def stale_after(control_period: float) -> float:
    """How old a snapshot may get before the mock robot's sensors give nothing, s."""
    return max(STALE_AFTER, STALE_PERIODS * control_period)


class WorldFeed:
    """The world's latest snapshot, as it arrives (from any thread).

    Args:
        robot_id: the robot's fish id.
        stale_after: a snapshot older than this gives nothing, s.
        clock: wall-clock time, s.
    """

    def __init__(
        self,
        robot_id: int,
        *,
        stale_after: float = STALE_AFTER,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.robot_id = robot_id
        self.stale_after = stale_after
        self._clock = clock
        self._latest: tuple[float, Snapshot] | None = None

    def take(self, snapshot: Snapshot) -> None:
        """A new snapshot arrived."""
        self._latest = (self._clock(), snapshot)

    def current(self) -> tuple[Snapshot, int]:
        """The latest snapshot and the robot's row in it.

        Raises:
            SensorUnavailable: no snapshot yet, too old, or the robot not in the world.
        """
        latest = self._latest
        if latest is None:
            raise SensorUnavailable("no world snapshot yet")
        arrived, snapshot = latest
        if self._clock() - arrived > self.stale_after:
            raise SensorUnavailable(
                f"the world's last snapshot is {self._clock() - arrived:.1f} s old"
            )
        rows = np.flatnonzero(snapshot.ids == self.robot_id)
        if rows.size == 0:
            raise SensorUnavailable(f"fish {self.robot_id} is not in the world (yet)")
        return snapshot, int(rows[0])


@dataclass
class SnapshotCamera:
    """Both fisheye cameras, rendered from the world's latest snapshot. Implements ``Camera``.

    Images are rendered both sides together, with seeded sensor noise: once per snapshot,
    and once more for each other set of lit LEDs when robots flash theirs.
    """

    feed: WorldFeed
    fisheye: Fisheye = field(default_factory=Fisheye)
    optics: Optics = field(default_factory=Optics)
    robot: BlueBot = field(default_factory=BlueBot)
    seed: int = 0
    clock: Callable[[], float] = time.monotonic
    """The time of a capture, s: when flashing LEDs are lit or dark."""

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng([self.seed, self.feed.robot_id])
        self._lock = threading.Lock()
        self._tick = -1
        self._rendered: dict[bytes, dict[CameraSide, NDArray[np.uint8]]] = {}
        """This tick's images, by which LEDs are lit."""

    def capture(self, side: CameraSide) -> NDArray[np.uint8]:
        """One camera's image of the world as the latest snapshot has it, now."""
        return self.capture_frames(side, 1)[0]

    def capture_frames(self, side: CameraSide, count: int) -> list[NDArray[np.uint8]]:
        """``count`` images of one camera, a frame period (1/60 s) apart from now: the
        latest snapshot's fish, the flashing ones lit or dark at each frame's time."""
        snapshot, row = self.feed.current()
        now = self.clock()
        return [
            self._image(snapshot, row, side, now + frame / CAMERA_FRAME_RATE)
            for frame in range(count)
        ]

    def _image(
        self, snapshot: Snapshot, row: int, side: CameraSide, time: float
    ) -> NDArray[np.uint8]:
        lit = self._lit(snapshot, time)
        shining = lit.tobytes()
        with self._lock:
            if self._tick != snapshot.tick:
                self._tick, self._rendered = snapshot.tick, {}
            images = self._rendered.get(shining)
            if images is None:
                images = self._rendered[shining] = render_views(
                    np.asarray(snapshot.position),
                    np.asarray(snapshot.yaw),
                    row,
                    fisheye=self.fisheye,
                    optics=self.optics,
                    robot=self.robot,
                    rng=self._rng,
                    lit=lit,
                )
            return images[side]

    @staticmethod
    def _lit(snapshot: Snapshot, now: float) -> BoolArray:
        """Whose LEDs shine at ``now``: all but the dark ones and the flashing ones in the
        dark half of their period."""
        if snapshot.lights is None:
            return np.ones(snapshot.ids.size, dtype=np.bool_)
        lit: BoolArray = snapshot.lights != DARK
        flashing = np.flatnonzero(snapshot.lights == FLASHING)
        if flashing.size:
            phase = np.mod(snapshot.ids[flashing] * GOLDEN_FRACTION, 1.0)
            lit[flashing] = lit_at(now, phase)
        return lit

    def close(self) -> None:
        """Nothing to release."""


@dataclass
class SnapshotDepth:
    """The robot's depth as the world's latest snapshot has it. Implements ``DepthSensor``."""

    feed: WorldFeed

    def read_depth(self) -> float:
        snapshot, row = self.feed.current()
        return float(snapshot.position[row, 2])

    def close(self) -> None:
        """Nothing to release."""


class BodyFins:
    """Fins that also tell the simulated body what they hold. Implements ``Fins``.

    Args:
        fins: the real port (gpiozero's mock pins on a laptop).
    """

    def __init__(self, fins: Fins) -> None:
        self._fins = fins
        self.gains = np.zeros(4)

    @property
    def frequencies(self) -> tuple[float, ...]:
        """The frequency each fin's pins beat at now, Hz (as the pins, not the body, have it)."""
        return tuple(getattr(self._fins, "frequencies", ()))

    def set_gains(self, gains: NDArray[np.float64]) -> None:
        self._fins.set_gains(gains)
        self.gains = np.clip(np.asarray(gains, dtype=np.float64), 0.0, 1.0).copy()

    def stop(self) -> None:
        self._fins.stop()
        self.gains = np.zeros(4)

    def close(self) -> None:
        self.stop()
        self._fins.close()


class MockBody:
    """The mock robot's body in the simulated world: answers the world's perceptions for it
    with its fins' gains and keeps the world's snapshots for its camera and depth sensor.

    Args:
        robot_id: the robot's fish id.
        keys: the swarm's key space.
        fins: the robot's fins.
        leds: the robot's LEDs.
        feed: where snapshots go.
    """

    def __init__(
        self, robot_id: int, keys: KeySpace, fins: BodyFins, leds: GpioLeds, feed: WorldFeed
    ) -> None:
        self.robot_id = robot_id
        self.keys = keys
        self.fins = fins
        self.leds = leds
        self.feed = feed
        self.intake = Intake(f"mock body {robot_id}")

    async def run(
        self, remote: Bus, *, task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED
    ) -> None:
        """Serve until cancelled; ready once subscribed and alive as a fish of the world."""
        keys = self.keys
        async with contextlib.AsyncExitStack() as stack:
            await stack.enter_async_context(
                open_subscriber(remote, keys.snapshot, self._take_snapshot)
            )
            perceptions = await stack.enter_async_context(
                open_subscription(remote, keys.perception(self.robot_id))
            )
            await stack.enter_async_context(open_token(remote, keys.alive("fish", self.robot_id)))
            task_status.started()
            async for key, payload in perceptions:
                perception = self.intake.decode_addressed(
                    key, payload, Perception, field="fish_id", owner=self.robot_id
                )
                if perception is None:
                    continue
                flashing = self.leds.flash_frequency > 0
                answer = Command(
                    self.robot_id,
                    perception.tick,
                    self.fins.gains,
                    flashing or self.leds.lit,
                    flashing=True if flashing else None,
                )
                remote.put(keys.command(self.robot_id), encode(answer))

    def _take_snapshot(self, key: str, payload: bytes) -> None:
        snapshot = self.intake.decode(key, payload, Snapshot)
        if snapshot is not None:
            self.feed.take(snapshot)


@contextlib.contextmanager
def open_mock_hardware(
    robot_id: int,
    keys: KeySpace,
    *,
    control_period: float = 1.0,
    seed: int = 0,
    pin_factory: Any = None,
) -> Iterator[tuple[Hardware, MockBody]]:
    """A mock robot's ports and its body in the simulated world (ports released on exit).

    Args:
        robot_id: the robot's fish id.
        keys: the swarm's key space.
        control_period: the robot's control period, s (the world's, which sends a snapshot
            each period): how long a snapshot stays fresh follows from it.
        seed: the seed of its cameras' sensor noise.
        pin_factory: gpiozero's pin factory (None: a fresh ``MockFactory``).

    Raises:
        HardwareError: gpiozero is not installed (no pin factory given).
    """
    if pin_factory is None:
        try:
            from gpiozero.pins.mock import MockFactory
        except ImportError as error:
            raise HardwareError(
                "a mock robot runs on gpiozero's mock pins: pip install -e '.[robot]'"
            ) from error
        pin_factory = MockFactory()
    feed = WorldFeed(robot_id, stale_after=stale_after(control_period))
    fins = BodyFins(GpioFins(pin_factory=pin_factory))
    try:
        leds = GpioLeds(pin_factory=pin_factory)
    except BaseException:
        fins.close()
        raise
    hardware = Hardware(fins, leds, SnapshotCamera(feed, seed=seed), SnapshotDepth(feed))
    try:
        yield hardware, MockBody(robot_id, keys, fins, leds, feed)
    finally:
        hardware.close()
