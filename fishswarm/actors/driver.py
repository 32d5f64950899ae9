"""The robot driver: a BlueBot's sensors and actuators as an actor beside its fish actor.

On a robot the driver and the unchanged fish actor share one process and talk over an
in-memory Bus (``local``): the driver reads both cameras and the depth sensor, runs the LED
pipeline (:func:`~fishswarm.bluebot.leds.perceive_leds`) and hands the fish a
:class:`Perception`; the fish answers with a :class:`Command`, which the driver writes to
fins and LEDs. Only what must leave the robot crosses the Zenoh link (``remote``): the
fish's broadcasts (but formation flags, which go by light) and deliveries, the robot's
status and liveliness token, and operators' orders. So the fins' safety never depends on Wi-Fi:

- **failsafe**: no command for ``command_timeout`` → fins off, whatever the network does;
- **link loss**: the fish swims on its own perception for at most ``link_timeout``, then the
  fins stop until the link returns;
- **operator's stop**: fins and LEDs off at once, commands ignored until ``resume``.

The driver also plays the channel's part for formation flags, by light
(:mod:`fishswarm.bluebot.flashes`): while its fish's flag says it holds its place, the LEDs
flash; and once its fish flags, each camera takes two frames half a flash period apart, and
each neighbour that flashes comes to the fish as a delivered flag, where the cameras see it.
"""

from __future__ import annotations

import contextlib
import logging
import math
import secrets
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeVar

import numpy as np
import trio
from numpy.typing import NDArray

from fishswarm import __version__
from fishswarm.actors.bus import Bus, Declared, open_alive_events, open_token
from fishswarm.actors.inbox import Inbox, open_subscription
from fishswarm.actors.intake import Intake
from fishswarm.behaviors.formation import flag_by_light
from fishswarm.bluebot.fisheye import Fisheye
from fishswarm.bluebot.flashes import FRAMES_APART, merge_frames
from fishswarm.bluebot.leds import LedVision, perceive_leds
from fishswarm.bluebot.parameters import LED_FLASH_FREQUENCY, fin_frequencies
from fishswarm.bluebot.ports import CAMERA_SIDES, Camera, CameraSide, DepthSensor, Fins, Leds
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import (
    Broadcast,
    Command,
    Delivery,
    FormationFlag,
    Message,
    Perception,
    RobotOrder,
    RobotStatus,
)

log = logging.getLogger(__name__)

M = TypeVar("M", bound=Message)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Look = tuple[float, FloatArray, BoolArray]
"""What the sensors give in one period: depth, m, (K, 3) body-frame neighbours, m, and (K,)
which of them flash their LEDs."""

LINK_TIMEOUT = 10.0
"""How long a robot that has lost its link to the base station swims on its own perception
before it stops its fins until the link returns, by default, s."""

CPU_TEMPERATURE = Path("/sys/class/thermal/thermal_zone0/temp")
"""Where Linux on a Raspberry Pi reports the SoC's temperature, in m°C."""


class HardwareError(RuntimeError):
    """The robot's hardware could not be opened (a library missing, a device not answering)."""


class SensorUnavailable(RuntimeError):
    """A camera frame or depth reading could not be had this period (the driver skips it)."""


SENSOR_ERRORS = (OSError, RuntimeError)
"""What a sensor's read may raise without ending the robot's run: a bus error (smbus2 raises
OSError, e.g. errno 121 when a device does not answer on I²C), a failed reading
(:class:`~fishswarm.bluebot.pressure.SensorError`), a bad or late camera frame, or
:class:`SensorUnavailable`. The driver skips the period; the fish's watchdog stops its fins
if no perception comes for long. Anything else is a defect and ends the run."""


@dataclass
class Hardware:
    """A robot's ports, whatever drives them (gpiozero and picamera2, or mocks).

    Attributes:
        fins, leds, camera, depth: the four ports the driver reads and writes.
    """

    fins: Fins
    leds: Leds
    camera: Camera
    depth: DepthSensor

    def close(self) -> None:
        """Fins off and every port released (each tried even if another fails)."""
        for port in (self.fins, self.leds, self.camera, self.depth):
            try:
                port.close()
            except Exception:  # release the others whatever one does
                log.exception("closing %s failed", type(port).__name__)


@dataclass(frozen=True)
class DriverSettings:
    """How a robot's driver runs.

    Attributes:
        robot_id: the robot, and its fish's id.
        behavior: the behaviour its fish actor runs (for the status).
        keys: the swarm's key space.
        control_period: time between perceptions, s.
        command_timeout: fins off when no command arrives for this long, s.
        link_timeout: with the link to the base station lost, the fish swims on its own
            perception for this long, then the fins stop until the link returns, s.
        status_period: time between status messages, s.
        leds: the LED pipeline's settings.
        fisheye: the cameras' projection.
    """

    robot_id: int
    behavior: str
    keys: KeySpace = KeySpace()
    control_period: float = 1.0
    command_timeout: float = 2.5
    link_timeout: float = LINK_TIMEOUT
    status_period: float = 0.5
    leds: LedVision = field(default_factory=LedVision)
    fisheye: Fisheye = field(default_factory=Fisheye)

    def __post_init__(self) -> None:
        if (
            isinstance(self.robot_id, bool)
            or not isinstance(self.robot_id, int)
            or self.robot_id < 0
        ):
            raise ValueError(
                f"robot_id must be a fish id, a whole number 0 or more, got {self.robot_id!r}"
            )
        for name in ("control_period", "command_timeout", "link_timeout", "status_period"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value}")
        if self.command_timeout <= self.control_period:
            raise ValueError(
                f"command_timeout ({self.command_timeout:g} s) must exceed the control period "
                f"({self.control_period:g} s), or the fins would stop between two commands"
            )


@dataclass(frozen=True)
class DriverStatistics:
    """Counters of a driver.

    Attributes:
        perceptions: perceptions handed to the fish.
        frames_missed: periods without a usable camera frame or depth reading.
        commands: commands written to fins and LEDs.
        failsafe_stops: times the fins stopped for lack of commands, or because the fish's
            own watchdog stopped them (no perception in time).
        link_losses: times the link to the base station went down.
        stranded_stops: times the fins stopped because the link stayed down too long.
        orders: operators' orders obeyed.
        deliveries: deliveries passed from the link to the fish.
        broadcasts: the fish's broadcasts passed to the link (all but its formation flags,
            which go by light).
        flags_seen: flashing neighbours handed to the fish as formation flags.
        rejected: messages rejected (malformed, misaddressed).
    """

    perceptions: int
    frames_missed: int
    commands: int
    failsafe_stops: int
    link_losses: int
    stranded_stops: int
    orders: int
    deliveries: int
    broadcasts: int
    flags_seen: int
    rejected: int


def cpu_temperature(path: Path = CPU_TEMPERATURE) -> float | None:
    """The SoC's temperature, °C, or None where the board does not report one."""
    try:
        return int(path.read_text().strip()) / 1000.0
    except (OSError, ValueError):
        return None


class Driver:
    """A robot's driver. ``await nursery.start(driver.run, local, remote)`` serves until
    cancelled, with the fins off and the LEDs dark when it ends.

    Args:
        settings: how it runs.
        hardware: the robot's ports.
        link_up: whether the Zenoh session reaches a router now (polled).
        run_blocking: how the blocking sensor reads and the LED pipeline are run (by default
            in a worker thread, so the failsafe keeps its time; tests under trio's MockClock
            run them inline, where a thread would let the mock clock jump meanwhile).
    """

    def __init__(
        self,
        settings: DriverSettings,
        hardware: Hardware,
        *,
        link_up: Callable[[], bool],
        run_blocking: Callable[[Callable[[], Look]], Awaitable[Look]] = trio.to_thread.run_sync,
    ) -> None:
        self.settings = settings
        self.hardware = hardware
        self._run_blocking = run_blocking
        self.state = "waiting"
        self._link_up = link_up
        self.link = True
        self._run_id = secrets.randbits(62)
        self._formation: str | None = None
        """The shape an operator's order told the fish to take (None: as configured)."""
        self._intake = Intake(f"driver {settings.robot_id}")
        self._failing: int | None = None
        """Periods without a reading since the last one (None: the last period had one)."""
        self._failure: str | None = None
        """The last sensor error logged, until a reading comes."""
        self._counts = dict.fromkeys(
            (
                "perceptions",
                "frames_missed",
                "commands",
                "failsafe_stops",
                "link_losses",
                "stranded_stops",
                "orders",
                "deliveries",
                "broadcasts",
                "flags_seen",
            ),
            0,
        )
        self._tick = 0
        self._started = 0.0
        self._last_command = -math.inf
        self._link_lost_at: float | None = None
        self._gains = np.zeros(4)
        self._depth = 0.0
        self._unannounced = 0
        self._own_flag: FormationFlag | None = None
        """The fish's formation flag of its last decision (None: it flags nothing)."""
        self._flagging = False
        """Whether the fish has flagged since the driver started: then neighbours may flash
        too (the robots of a tank run alike), and each camera takes two frames."""
        self._lit = False
        self._shown: tuple[bool, bool] | None = None
        """What the LEDs were last told: (lit, flashing)."""
        self._changed = trio.Event()

    def statistics(self) -> DriverStatistics:
        """The driver's counters so far."""
        return DriverStatistics(rejected=self._intake.rejected_total, **self._counts)

    def status(self) -> RobotStatus:
        """The robot's status now."""
        return RobotStatus(
            robot_id=self.settings.robot_id,
            version=__version__,
            behavior=self.settings.behavior,
            state=self.state,
            depth=self._depth,
            fin_frequencies=np.asarray(fin_frequencies(self._gains), dtype=np.float64),
            link=self.link,
            cpu_temperature=cpu_temperature(),
            uptime=max(0.0, trio.current_time() - self._started),
            perceptions=self._counts["perceptions"],
            commands=self._counts["commands"],
            failsafe_stops=self._counts["failsafe_stops"],
            formation=self._formation,
            flashing=True if self._shown == (True, True) else None,
            flags_seen=self._counts["flags_seen"] or None,
        )

    async def run(
        self,
        local: Bus,
        remote: Bus,
        *,
        task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
    ) -> None:
        """Drive the robot until cancelled; ready once subscribed and alive on the link."""
        keys, robot_id = self.settings.keys, self.settings.robot_id
        self._started = trio.current_time()
        try:
            async with contextlib.AsyncExitStack() as stack:
                commands, orders, broadcasts, deliveries, abouts = [
                    await stack.enter_async_context(open_subscription(bus, key))
                    for bus, key in (
                        (local, keys.command(robot_id)),
                        (remote, keys.robot_order),
                        # The bridge: the fish's broadcasts out (its formation flags go by
                        # light), deliveries to it in, and
                        # its vouching for itself out (a secured world admits only fish
                        # vouched for on their own about keys).
                        (local, keys.outbox(robot_id)),
                        (remote, keys.inbox(robot_id)),
                        (local, keys.about(robot_id)),
                    )
                ]
                worlds: Inbox[tuple[str, bool]] = Inbox()
                await stack.enter_async_context(
                    open_alive_events(
                        remote, keys.alive_all("world"), lambda k, up: worlds.push((k, up))
                    )
                )
                await stack.enter_async_context(open_token(remote, keys.alive("robot", robot_id)))
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(self._obey, commands)
                    nursery.start_soon(self._take_orders, orders)
                    nursery.start_soon(self._pass_deliveries, deliveries, local)
                    nursery.start_soon(self._pass_broadcasts, broadcasts, remote)
                    nursery.start_soon(self._pass_out, abouts, remote)
                    nursery.start_soon(self._show_worlds, worlds, local)
                    nursery.start_soon(self._guard)
                    nursery.start_soon(self._report, remote)
                    nursery.start_soon(self._sense, local)
                    task_status.started()
        finally:
            self.hardware.fins.stop()
            self.hardware.leds.set_lit(False)

    # Sensing ----------------------------------------------------------------------------

    async def _sense(self, local: Bus) -> None:
        """Every control period: both images and the depth → neighbours → a perception."""
        period = self.settings.control_period
        deadline = trio.current_time()
        while True:
            deadline += period
            if self.state not in ("stopped", "stranded"):
                try:
                    depth, neighbors, flashing = await self._run_blocking(self._look)
                except SENSOR_ERRORS as error:
                    if isinstance(error, NotImplementedError | RecursionError):
                        raise  # RuntimeErrors that are defects, not a sensor's failure
                    self._missed(error)
                else:
                    if self._failure is not None:
                        log.warning(
                            "robot %d: sensing again after %d periods without (%s)",
                            self.settings.robot_id, self._failing, self._failure,
                        )  # fmt: skip
                    self._failing = self._failure = None
                    self._depth = depth
                    self._perceive(local, depth, neighbors, flashing)
            # A slow frame does not pile up periods: the next starts from now.
            deadline = max(deadline, trio.current_time())
            await trio.sleep_until(deadline)

    def _missed(self, error: Exception) -> None:
        """A period without a usable reading: counted; a sensor's error logged when it
        starts and when it changes, not every period."""
        self._counts["frames_missed"] += 1
        self._failing = (self._failing or 0) + 1
        if isinstance(error, SensorUnavailable):
            log.debug("robot %d: %s", self.settings.robot_id, error)
            return
        failure = f"{type(error).__name__}: {error}"
        if failure != self._failure:
            self._failure = failure
            log.warning(
                "robot %d: a sensor failed (%s); this period is skipped, and the fish's "
                "fins stop if no reading comes for its perception timeout",
                self.settings.robot_id, failure,
            )  # fmt: skip

    def _look(self) -> Look:
        """Depth, neighbours and which of them flash, from the sensors (runs in a worker
        thread). Only robots whose fish flag flash theirs: only then does each camera take
        two frames, half a flash period apart, in which a flashing neighbour is lit once."""
        camera = self.hardware.camera
        depth = self.hardware.depth.read_depth()
        if not self._flagging:
            first = self._see({side: camera.capture(side) for side in CAMERA_SIDES}, depth)
            return depth, first, np.zeros(first.shape[0], dtype=np.bool_)
        # Both of a camera's frames before the multiplexer switches (a switch drops frames),
        # all four before the LED pipeline runs (it would hold up the next frame).
        frames = {side: camera.capture_frames(side, FRAMES_APART + 1) for side in CAMERA_SIDES}
        first = self._see({side: taken[0] for side, taken in frames.items()}, depth)
        second = self._see({side: taken[-1] for side, taken in frames.items()}, depth)
        neighbors, flashing = merge_frames(first, second)
        return depth, neighbors, flashing

    def _see(self, images: dict[CameraSide, NDArray[np.uint8]], depth: float) -> FloatArray:
        """The neighbours in one image of each camera."""
        return perceive_leds(
            images, depth=depth, fisheye=self.settings.fisheye, vision=self.settings.leds
        )

    def _perceive(
        self, local: Bus, depth: float, neighbors: FloatArray, flashing: BoolArray
    ) -> None:
        robot_id = self.settings.robot_id
        if self._own_flag is not None and flashing.any():
            # Each flashing neighbour, where it is seen, is a flag for this perception.
            values = flag_by_light(self._own_flag).values()
            flashers = neighbors[flashing]
            for position in flashers:
                flag = Delivery(robot_id, self._tick, "formation", values, position, self._run_id)
                local.put(self.settings.keys.inbox(robot_id), encode(flag))
            self._unannounced += len(flashers)
            self._counts["flags_seen"] += len(flashers)
        message = Perception(
            fish_id=self.settings.robot_id,
            tick=self._tick,
            time=max(0.0, trio.current_time() - self._started),
            depth=depth,
            neighbors=neighbors,
            landmarks=np.zeros((0, 3)),
            inbox_count=self._unannounced,
            run=self._run_id,
            formation=self._formation,
        )
        self._unannounced = 0
        self._tick += 1
        self._counts["perceptions"] += 1
        local.put(
            self.settings.keys.perception(self.settings.robot_id), encode(message, reuse=True)
        )

    # Acting -----------------------------------------------------------------------------

    async def _addressed(
        self, messages: Inbox[tuple[str, bytes]], expected: type[M], id_field: str
    ) -> AsyncIterator[tuple[str, bytes, M]]:
        """The fish's messages of type ``expected`` that name this robot in ``id_field``, as
        they come (others rejected and counted), with their key and payload."""
        robot_id = self.settings.robot_id
        async for key, payload in messages:
            message = self._intake.decode_addressed(
                key, payload, expected, field=id_field, owner=robot_id
            )
            if message is not None:
                yield key, payload, message

    async def _obey(self, commands: Inbox[tuple[str, bytes]]) -> None:
        """Write each command to fins and LEDs, unless stopped or stranded."""
        async for _, _, command in self._addressed(commands, Command, "fish_id"):
            if self.state in ("stopped", "stranded"):
                continue
            if command.watchdog:
                # Not a decision: the fish heard nothing of its world in time. The robot
                # stops (and says so) until the fish decides again.
                self._last_command = trio.current_time()
                if self.state != "failsafe":
                    self._stop("failsafe")
                    self._counts["failsafe_stops"] += 1
                    log.warning(
                        "robot %d: its fish stopped the fins (no perception in time: is the "
                        "world running, and the link up?)",
                        self.settings.robot_id,
                    )
                self._wake()
                continue
            self._set_fins(command.fins)
            self._lit = command.led
            if command.broadcasts == 0:
                self._own_flag = None  # the fish flags nothing this time: no flashing
            self._last_command = trio.current_time()
            self._counts["commands"] += 1
            self.state = "swimming"
            self._show_lights()
            self._wake()

    def _set_fins(self, gains: FloatArray) -> None:
        self._gains = np.asarray(gains, dtype=np.float64).copy()
        if self._gains.any():
            self.hardware.fins.set_gains(self._gains)
        else:
            self.hardware.fins.stop()

    def _stop(self, state: str) -> None:
        """Fins off, in ``state``; a robot that no longer swims holds no place, so its LEDs
        stop flashing (and go dark if an operator stopped it)."""
        self._gains = np.zeros(4)
        self.hardware.fins.stop()
        self.state = state
        self._own_flag = None
        self._show_lights()

    async def _guard(self) -> None:
        """The failsafe and the link: fins off when commands stop or the link stays down."""
        settings = self.settings
        poll = min(0.1, settings.command_timeout / 4)
        while True:
            now = trio.current_time()
            up = self._link_up()
            if up != self.link:
                self.link = up
                if up:
                    self._link_lost_at = None
                    log.warning("robot %d: link to the base station back", settings.robot_id)
                    if self.state == "stranded":
                        self.state = "waiting"
                else:
                    self._link_lost_at = now
                    self._counts["link_losses"] += 1
                    log.warning(
                        "robot %d: link to the base station lost; swimming on for at most %g s",
                        settings.robot_id,
                        settings.link_timeout,
                    )
            if (
                self._link_lost_at is not None
                and now - self._link_lost_at >= settings.link_timeout
                and self.state not in ("stranded", "stopped")
            ):
                self._stop("stranded")
                self._counts["stranded_stops"] += 1
                log.warning("robot %d: link down too long, fins off", settings.robot_id)
            if self.state == "swimming" and now - self._last_command >= settings.command_timeout:
                self._stop("failsafe")
                self._counts["failsafe_stops"] += 1
                log.warning(
                    "robot %d: no command for %g s, fins off",
                    settings.robot_id,
                    settings.command_timeout,
                )
            await trio.sleep(poll)

    async def _take_orders(self, orders: Inbox[tuple[str, bytes]]) -> None:
        async for key, payload in orders:
            order = self._intake.decode(key, payload, RobotOrder)
            if order is None or not order.addresses(self.settings.robot_id):
                continue
            self._counts["orders"] += 1
            if order.action == "formation":
                self._take_formation(order.formation)
            elif order.action == "stop":
                self._stop("stopped")
                log.warning("robot %d: stopped by an operator", self.settings.robot_id)
            elif self.state == "stopped":
                self.state = "waiting"
                log.warning("robot %d: resumed by an operator", self.settings.robot_id)
            self._wake()

    def _take_formation(self, shape: str | None) -> None:
        """An operator's formation order: the fish's perceptions name the shape from now on
        (a fish that runs another behaviour has none to take: the order is let go)."""
        robot_id, behavior = self.settings.robot_id, self.settings.behavior
        if behavior != "formation":
            log.warning("robot %d: let a formation order go: its fish run %s, not a "
                        "formation", robot_id, behavior)  # fmt: skip
        elif shape != self._formation:
            self._formation = shape
            log.warning("robot %d: formation %s, by an operator's order", robot_id, shape)

    # The link ---------------------------------------------------------------------------

    async def _pass_broadcasts(self, broadcasts: Inbox[tuple[str, bytes]], remote: Bus) -> None:
        """The fish's formation flag into light, its other broadcasts onto the link (flags
        travel between robots by light: on the link nothing takes them, and a simulated
        channel, which numbers broadcasts by its world's ticks, would refuse them). The
        fish's run is the driver's, which means nothing on the link: it is left off."""
        async for key, payload, broadcast in self._addressed(broadcasts, Broadcast, "sender_id"):
            if broadcast.kind != "formation":
                remote.put(
                    key, payload if broadcast.run is None else encode(replace(broadcast, run=None))
                )
                self._counts["broadcasts"] += 1
                continue
            # A broadcast is checked on decoding: a formation broadcast's numbers are a flag.
            self._own_flag = FormationFlag.from_values(broadcast.values)
            self._flagging = True
            self._show_lights()

    def _show_lights(self) -> None:
        """The LEDs as the fish wants them: flashing while it swims and its flag says it
        holds its place (its flag by light), else lit or dark as its command says; dark once
        stopped. A robot whose fins the failsafe or a lost link stopped holds no place, even
        if a flag of a decision under way comes after."""
        lit = self._lit and self.state != "stopped"
        flashing = (
            lit
            and self.state == "swimming"
            and self._own_flag is not None
            and self._own_flag.joined
        )
        if (lit, flashing) == self._shown:
            return
        self._shown = (lit, flashing)
        if flashing:
            self.hardware.leds.set_flashing(LED_FLASH_FREQUENCY)
        else:
            self.hardware.leds.set_lit(lit)

    async def _pass_out(self, messages: Inbox[tuple[str, bytes]], remote: Bus) -> None:
        """The fish's messages onto the link, as they are."""
        async for key, payload in messages:
            remote.put(key, payload)

    async def _show_worlds(self, worlds: Inbox[tuple[str, bool]], local: Bus) -> None:
        """Each world that is up on the link, shown to the fish by its liveliness token:
        the fish vouches for itself again whenever a world appears, as it does on a
        simulated swarm's bus."""
        shown: dict[str, Declared] = {}
        try:
            async for key, up in worlds:
                if up and key not in shown:
                    shown[key] = local.declare_token(key)
                elif not up and key in shown:
                    shown.pop(key).undeclare()
        finally:
            for token in shown.values():
                token.undeclare()

    async def _pass_deliveries(self, deliveries: Inbox[tuple[str, bytes]], local: Bus) -> None:
        async for key, _, delivery in self._addressed(deliveries, Delivery, "receiver_id"):
            # A channel numbers deliveries by its world's ticks and run; the fish acts on one
            # at the driver's next perception, and waits for it under that perception's tick
            # and run.
            local.put(key, encode(replace(delivery, tick=self._tick, run=self._run_id)))
            self._unannounced += 1
            self._counts["deliveries"] += 1

    async def _report(self, remote: Bus) -> None:
        """The status on the link every status period, and at once on a change of state."""
        key = self.settings.keys.robot_status(self.settings.robot_id)
        while True:
            remote.put(key, encode(self.status()))
            self._changed = trio.Event()
            with trio.move_on_after(self.settings.status_period):
                await self._changed.wait()

    def _wake(self) -> None:
        self._changed.set()
