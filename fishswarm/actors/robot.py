"""A robot: its driver and the unchanged fish actor in one process, bridged to the swarm, and
the fleet as a base station sees it.

:func:`run_robot` opens the robot's hardware (the BlueBot's, or a mock's that lives in a
simulated world), a Zenoh client session to the base station's router, and runs the fish
actor and the driver over an in-memory Bus between them (DESIGN §2). :func:`survey_fleet`
collects the robots' status messages and liveliness for ``fishswarm robots``;
:func:`order_fleet` sends an operator's stop or resume.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import os
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import trio
import zenoh

from fishswarm.actors.bus import Bus, MemoryBus, open_alive_events
from fishswarm.actors.driver import Driver, DriverSettings, Hardware, HardwareError
from fishswarm.actors.fish import Fish, FishSettings
from fishswarm.actors.inbox import Inbox, open_subscription
from fishswarm.actors.intake import Intake
from fishswarm.actors.mock_robot import open_mock_hardware
from fishswarm.actors.session import SessionSettings, open_session, reaches_router
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.behaviors.core import FishParams
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace, fish_id_of
from fishswarm.protocols.messages import RobotOrder, RobotStatus

HARDWARE = ("bluebot", "mock")
ROBOT_PERCEPTION_TIMEOUT = 3.0
"""How long a robot's fish actor goes without a perception from its driver before its
watchdog turns the fins off, by default, s (the driver perceives every period: seconds of
silence are a frozen driver, not a slow one)."""
ROBOT_LEASE = 1.0
"""The robot's Zenoh link lease, s: a link that carries nothing for this long is down."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RobotSettings:
    """How a robot process runs.

    Attributes:
        driver: the driver's settings (its id, timings, pipeline).
        fish: what the fish decides.
        connect: the base station's router endpoint.
        hardware: ``bluebot`` (gpiozero, picamera2, the MS5803) or ``mock`` (gpiozero's mock
            pins; cameras and depth from the simulated world the robot swims in).
        connect_timeout: longest wait for the router at start, s (< 0: forever).
        perception_timeout: the fish actor's own watchdog, s.
        seed: the mock cameras' sensor-noise seed.
        zenoh_config: a Zenoh configuration file to start the session from (None: defaults).
        session_extra: further Zenoh settings of the session (a secured swarm's TLS, see
            :func:`fishswarm.actors.security.session_security`).
    """

    driver: DriverSettings
    fish: FishParams
    connect: str
    hardware: str = "bluebot"
    connect_timeout: float = -1.0
    perception_timeout: float = ROBOT_PERCEPTION_TIMEOUT
    seed: int = 0
    zenoh_config: str | None = None
    session_extra: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.hardware not in HARDWARE:
            raise ValueError(
                f"hardware must be one of {', '.join(HARDWARE)}, got {self.hardware!r}"
            )
        if not (math.isfinite(self.perception_timeout) and self.perception_timeout > 0):
            raise ValueError(
                "perception_timeout must be a positive number of seconds, got "
                f"{self.perception_timeout:g}"
            )

    def fish_settings(self) -> FishSettings:
        """What the robot's fish actor is told: its one fish, what it does, the swarm's keys,
        and how long it swims on without a perception."""
        return FishSettings(
            (self.driver.robot_id,),
            self.fish,
            self.driver.keys,
            perception_timeout=self.perception_timeout,
        )


@contextlib.contextmanager
def open_bluebot_hardware() -> Iterator[Hardware]:
    """The BlueBot's own ports, released on exit: fins and LEDs on gpiozero, both cameras
    through picamera2, the MS5803 depth sensor over I²C (each released again if a later one
    fails to open).

    Under systemd (``StateDirectory=``, as the deployment's unit has it) the depth sensor
    keeps its surface pressure in the robot's state folder, so that a restart in mid-dive
    does not take that depth for the surface.

    Raises:
        HardwareError: a library is missing or a device does not answer, with which.
    """
    from fishswarm.bluebot.gpio import GpioFins, GpioLeds
    from fishswarm.bluebot.picamera import PiCameras
    from fishswarm.bluebot.pressure import SURFACE_FILE, SensorError, i2c_depth_sensor

    state = os.environ.get("STATE_DIRECTORY")
    surface_file = Path(state.split(":")[0]) / SURFACE_FILE if state else None

    # gpiozero warns of each pin library it could not load before it finds one: on a robot
    # worth a line in the log; where it finds none, the reasons join the error's one line.
    # (The hardware is opened before the robot starts any thread: catching warnings is
    # process-wide.)
    with warnings.catch_warnings(record=True) as fallbacks:
        warnings.simplefilter("always")
        try:
            with contextlib.ExitStack() as opened:
                fins = GpioFins()
                opened.callback(fins.close)
                leds = GpioLeds()
                opened.callback(leds.close)
                camera = PiCameras()
                opened.callback(camera.close)
                depth = i2c_depth_sensor(surface_file=surface_file)
                opened.pop_all()
        except (ImportError, OSError, SensorError, RuntimeError) as error:
            tried = "; ".join(str(fallback.message) for fallback in fallbacks)
            raise HardwareError(
                f"cannot open the BlueBot's hardware: {error}"
                + (f" ({tried})" if tried else "")
                + " (on a laptop, use --hardware mock)"
            ) from error
    for fallback in fallbacks:
        log.warning("opening the hardware: %s", fallback.message)
    hardware = Hardware(fins, leds, camera, depth)
    try:
        yield hardware
    finally:
        hardware.close()


async def run_robot(
    settings: RobotSettings, *, task_status: trio.TaskStatus[Driver] = trio.TASK_STATUS_IGNORED
) -> None:
    """Run one robot until cancelled: driver and fish actor, bridged to the router; reports
    readiness with its driver (whose state and ports can be watched).

    Raises:
        ConnectError: the router could not be reached within ``connect_timeout``.
    """
    robot_id = settings.driver.robot_id
    keys = settings.driver.keys
    session_settings = SessionSettings(
        mode="client",
        connect=(settings.connect,),
        connect_timeout=settings.connect_timeout,
        lease=ROBOT_LEASE,
        config_file=settings.zenoh_config,
        extra=dict(settings.session_extra),
    )
    body = None
    with contextlib.ExitStack() as ports:
        if settings.hardware == "mock":
            hardware, body = ports.enter_context(
                open_mock_hardware(
                    robot_id, keys, control_period=settings.driver.control_period,
                    seed=settings.seed,
                )
            )  # fmt: skip
        else:
            hardware = ports.enter_context(open_bluebot_hardware())
        async with open_session(session_settings) as session, trio.open_nursery() as nursery:
            remote, local = ZenohBus(session), MemoryBus()
            if body is not None:
                await nursery.start(body.run, remote)
            fish = Fish(settings.fish_settings())
            await nursery.start(fish.run, local)
            driver = Driver(settings.driver, hardware, link_up=_link_probe(session))
            await nursery.start(driver.run, local, remote)
            task_status.started(driver)


def _link_probe(session: zenoh.Session) -> Callable[[], bool]:
    return partial(reaches_router, session)


@dataclass(frozen=True)
class FleetEntry:
    """One robot as the base station last heard of it.

    Attributes:
        status: its last status message (None: alive, but no status heard yet).
        alive: whether its liveliness token is up.
        last_seen: how long ago its last status arrived, s (None: never).
        drivers: how many drivers report this id (told apart by when each started, from
            their uptimes): more than one means processes were given one id.
    """

    robot_id: int
    status: RobotStatus | None
    alive: bool
    last_seen: float | None
    drivers: int = 1


DRIVERS_APART = 1.0
"""Statuses of one id whose drivers started this far apart, s, come from two drivers (one
driver's statuses agree on its start within the network's delays)."""


def _drivers(starts: list[float]) -> int:
    """How many drivers the start times ``starts`` (s, on this clock) were reported by:
    groups of starts apart by more than :data:`DRIVERS_APART`, each of two statuses or
    more (one status delayed on its way is no second driver); at least 1."""
    ordered = sorted(starts)
    groups: list[int] = []
    for index, start in enumerate(ordered):
        if index == 0 or start - ordered[index - 1] > DRIVERS_APART:
            groups.append(0)
        groups[-1] += 1
    return max(1, sum(size >= 2 for size in groups))


async def survey_fleet(bus: Bus, keys: KeySpace, *, listen: float) -> list[FleetEntry]:
    """The robots heard from within ``listen`` s: statuses and liveliness, by id."""
    statuses: dict[int, tuple[float, RobotStatus]] = {}
    starts: dict[int, list[float]] = {}
    alive: set[int] = set()
    intake = Intake("fleet survey")
    tokens: Inbox[tuple[str, bool]] = Inbox()
    async with (
        open_subscription(bus, keys.robot_statuses()) as samples,
        open_alive_events(bus, keys.alive_all("robot"), lambda k, a: tokens.push((k, a))),
    ):
        with trio.move_on_after(listen):
            async for key, payload in samples:
                status = intake.decode(key, payload, RobotStatus)
                if status is not None:
                    now = trio.current_time()
                    statuses[status.robot_id] = (now, status)
                    starts.setdefault(status.robot_id, []).append(now - status.uptime)
        for key, up in tokens.drain():
            try:
                robot = fish_id_of(keys.parse_alive(key).member_id)
            except ValueError:  # a token no robot of ours holds
                continue
            if robot is not None:
                (alive.add if up else alive.discard)(robot)
    now = trio.current_time()
    return [
        FleetEntry(
            robot_id,
            statuses[robot_id][1] if robot_id in statuses else None,
            robot_id in alive,
            now - statuses[robot_id][0] if robot_id in statuses else None,
            _drivers(starts.get(robot_id, [])),
        )
        for robot_id in sorted(set(statuses) | alive)
    ]


def order_fleet(
    bus: Bus, keys: KeySpace, action: str, robot_ids: list[int], formation: str | None = None
) -> RobotOrder:
    """Send an operator's order to the robots ``robot_ids`` (empty: all); the order sent
    (``formation``: the shape of a formation order)."""
    order = RobotOrder(action, np.array(sorted(set(robot_ids)), dtype=np.int64), formation)
    bus.put(keys.robot_order, encode(order))
    return order


def unconfirmed(fleet: list[FleetEntry], order: RobotOrder) -> dict[int, str]:
    """The robots an order was for that do not report obeying it, each with why: a stop is
    obeyed by a robot that says it is ``stopped``, a resume by one that no longer does, a
    formation order by one that names its shape.

    An order is one message: a robot whose link was down when it went out never hears it,
    and a robot that restarts comes back unstopped, so the operator must know. An order to
    every robot is checked against the robots heard from: one that is silent is not known
    to be missing (with none heard from, the command says so).
    """
    heard = {entry.robot_id: entry for entry in fleet}
    wanted = order.robot_ids.tolist() or sorted(heard)
    missing: dict[int, str] = {}
    for robot_id in wanted:
        entry = heard.get(robot_id)
        if entry is None or entry.status is None:
            missing[robot_id] = "not heard from"
            continue
        if order.action == "formation":
            if entry.status.behavior != "formation":
                missing[robot_id] = f"its fish run {entry.status.behavior}, not a formation"
            elif entry.status.formation != order.formation:
                missing[robot_id] = f"its fish take {entry.status.formation or 'their own'}"
            continue
        stopped = entry.status.state == "stopped"
        if stopped != (order.action == "stop"):
            missing[robot_id] = f"still {entry.status.state}"
    return missing
