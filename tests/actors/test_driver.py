"""The robot driver beside the unchanged fish actor, on in-memory Buses under trio's MockClock:
perceptions from rendered camera images, fins on gpiozero's mock pins, the failsafe, link
loss, operators' orders and the bridge."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from contextlib import asynccontextmanager
from typing import TypeVar

import numpy as np
import pytest
import trio

gpiozero_mock = pytest.importorskip("gpiozero.pins.mock")

from fishswarm.actors.bus import MemoryBus  # noqa: E402
from fishswarm.actors.driver import (  # noqa: E402
    Driver,
    DriverSettings,
    Hardware,
    Look,
    SensorUnavailable,
)
from fishswarm.actors.fish import Fish, FishSettings  # noqa: E402
from fishswarm.actors.inbox import Inbox  # noqa: E402
from fishswarm.behaviors.formation import NO_HOPS, flag_by_light  # noqa: E402
from fishswarm.bluebot.fisheye import Fisheye  # noqa: E402
from fishswarm.bluebot.gpio import GpioFins, GpioLeds  # noqa: E402
from fishswarm.bluebot.parameters import BlueBot, Wiring  # noqa: E402
from fishswarm.bluebot.ports import CameraSide  # noqa: E402
from fishswarm.bluebot.vision import to_body  # noqa: E402
from fishswarm.protocols.codec import decode, encode  # noqa: E402
from fishswarm.protocols.keys import KeySpace  # noqa: E402
from fishswarm.protocols.messages import (  # noqa: E402
    FORMATION_SHAPES,
    Broadcast,
    Command,
    Delivery,
    FishAbout,
    FormationFlag,
    Perception,
    RobotOrder,
    RobotStatus,
)
from fishswarm.sim.camera import Optics, render_views  # noqa: E402
from fishswarm.sim.scenario import Scenario  # noqa: E402
from tests.conftest import run_mock, subscription  # noqa: E402

KEYS = KeySpace("drv")
T = TypeVar("T")
ROBOT = 4
# The robot at 0.5 m depth facing +x; a neighbour 0.6 m ahead and 0.2 m to its right.
POSITION = np.array([[0.8, 0.8, 0.5], [1.4, 1.0, 0.5]])
YAW = np.array([0.0, 1.0])


class SceneCamera:
    """Both cameras seeing a fixed scene, rendered (a stand-in for picamera2)."""

    def __init__(self) -> None:
        self.images = render_views(
            POSITION,
            YAW,
            0,
            fisheye=Fisheye(),
            optics=Optics(),
            robot=BlueBot(),
            rng=np.random.default_rng(0),
        )
        self.working = True

    def capture(self, side: CameraSide) -> np.ndarray:
        if not self.working:
            raise SensorUnavailable("no frame")
        return self.images[side]

    def capture_frames(self, side: CameraSide, count: int) -> list[np.ndarray]:
        return [self.capture(side) for _ in range(count)]

    def close(self) -> None:
        pass


class FixedDepth:
    def read_depth(self) -> float:
        return 0.5

    def close(self) -> None:
        pass


@pytest.fixture
def factory() -> Iterator[object]:
    factory = gpiozero_mock.MockFactory()
    yield factory
    factory.reset()


@pytest.fixture
def hardware(factory: object) -> Iterator[Hardware]:
    ports = Hardware(
        GpioFins(pin_factory=factory), GpioLeds(pin_factory=factory), SceneCamera(), FixedDepth()
    )
    yield ports
    ports.close()


async def inline(function: Callable[[], Look]) -> Look:
    return function()


def make_driver(
    hardware: Hardware,
    link: list[bool],
    *,
    command_timeout: float = 1.0,
    behavior: str = "dispersion",
) -> Driver:
    settings = DriverSettings(
        ROBOT,
        behavior,
        KEYS,
        control_period=0.5,
        command_timeout=command_timeout,
        link_timeout=3.0,
    )
    return Driver(settings, hardware, link_up=lambda: link[0], run_blocking=inline)


def command(fins: list[float], led: bool = True) -> bytes:
    return encode(Command(ROBOT, 0, np.array(fins), led=led))


def test_the_fish_decides_on_what_the_cameras_see_and_its_fins_beat(
    hardware: Hardware, factory: object
) -> None:
    beating: list[tuple[float, ...]] = []

    async def main() -> tuple[Perception, RobotStatus]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        fish = Fish(FishSettings((ROBOT,), Scenario().fish_params(), KEYS))
        async with (
            subscription(local, KEYS.perception(ROBOT)) as perceptions,
            subscription(remote, KEYS.robot_status(ROBOT)) as statuses,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(fish.run, local)
            await nursery.start(driver.run, local, remote)
            _, payload = await perceptions.receive()
            await trio.sleep(0.1)
            status = decode(statuses.drain()[-1][1], RobotStatus)
            beating.append(hardware.fins.frequencies)  # type: ignore[attr-defined]
            nursery.cancel_scope.cancel()
        return decode(payload, Perception), status

    perception, status = run_mock(main)
    truth = to_body((POSITION[1:] - POSITION[0])[None], YAW[:1])[0]
    assert perception.fish_id == ROBOT and perception.depth == 0.5
    np.testing.assert_allclose(perception.neighbors, truth, rtol=0.02, atol=0.01)
    # A neighbour ahead and to the right: the dispersing fish turns away, left, with its
    # right pectoral fin, at the frequency of gain 1 (10 Hz for a pectoral, SPEC §6).
    assert status.state == "swimming" and status.commands == 1
    assert status.fin_frequencies.tolist() == [0.0, 0.0, 0.0, 10.0]
    assert beating == [(0.0, 0.0, 0.0, 10.0)]
    # When the driver ends, the fins stop and the LEDs go dark.
    assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
    assert not factory.pin(Wiring().led_pin).state  # type: ignore[attr-defined]
    assert status.version and status.behavior == "dispersion" and status.link


def test_fins_stop_when_commands_stop_for_the_timeout(hardware: Hardware) -> None:
    async def main() -> tuple[float, Driver]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            start = trio.current_time()
            await trio.sleep(0.01)
            assert hardware.fins.frequencies[0] > 0  # type: ignore[attr-defined]
            while driver.state != "failsafe":
                await trio.sleep(0.01)
            stopped_after = trio.current_time() - start
            nursery.cancel_scope.cancel()
        return stopped_after, driver

    stopped_after, driver = run_mock(main)
    # The guard polls every 0.1 s: the fins stop within one poll of the 1-s timeout.
    assert 1.0 <= stopped_after <= 1.11
    assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
    assert driver.statistics().failsafe_stops == 1


def test_with_the_link_down_it_swims_on_then_stops_until_the_link_returns(
    hardware: Hardware,
) -> None:
    link = [True]

    async def main() -> list[tuple[float, str]]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, link, command_timeout=10.0)
        states: list[tuple[float, str]] = []
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([0.5, 0.0, 0.0, 0.0]))
            start = trio.current_time()
            link[0] = False
            await trio.sleep(2.0)
            states.append((trio.current_time() - start, driver.state))  # still swimming
            await trio.sleep(1.2)
            states.append((trio.current_time() - start, driver.state))  # stranded
            # Stranded, the robot does not sense: its fish has nothing to decide on.
            sensed = driver.statistics().perceptions
            await trio.sleep(2.0)
            assert driver.statistics().perceptions == sensed
            local.put(KEYS.command(ROBOT), command([0.5, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            states.append((trio.current_time() - start, driver.state))  # commands ignored
            link[0] = True
            await trio.sleep(0.2)
            states.append((trio.current_time() - start, driver.state))  # waiting again
            local.put(KEYS.command(ROBOT), command([0.5, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            states.append((trio.current_time() - start, driver.state))
            nursery.cancel_scope.cancel()
        assert driver.statistics().link_losses == 1
        assert driver.statistics().stranded_stops == 1
        return states

    states = run_mock(main)
    assert [state for _, state in states] == [
        "swimming",
        "stranded",
        "stranded",
        "waiting",
        "swimming",
    ]


def test_a_robot_stopped_by_an_operator_stays_stopped_through_a_lost_link(
    hardware: Hardware,
) -> None:
    """Only an operator's resume ends a stop: not the link coming back, which ends a
    stranding."""
    link = [True]

    async def main() -> list[str]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, link, command_timeout=10.0)
        states = []
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            remote.put(KEYS.robot_order, encode(RobotOrder("stop")))
            await trio.sleep(0.01)
            states.append(driver.state)
            link[0] = False
            await trio.sleep(4.0)  # past the 3-s link timeout
            states.append(driver.state)
            link[0] = True
            await trio.sleep(0.2)
            states.append(driver.state)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            states.append(driver.state)
            assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
            nursery.cancel_scope.cancel()
        assert driver.statistics().stranded_stops == 0
        return states

    assert run_mock(main) == ["stopped", "stopped", "stopped", "stopped"]


def test_an_operators_stop_turns_fins_and_leds_off_until_resumed(
    hardware: Hardware, factory: object
) -> None:
    led = factory.pin(Wiring().led_pin)  # type: ignore[attr-defined]

    async def main() -> None:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True], command_timeout=10.0)
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([1.0, 1.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            assert led.state and driver.state == "swimming"
            remote.put(KEYS.robot_order, encode(RobotOrder("stop", np.array([ROBOT + 1]))))
            await trio.sleep(0.01)
            assert driver.state == "swimming"  # an order for another robot
            remote.put(KEYS.robot_order, encode(RobotOrder("stop")))
            await trio.sleep(0.01)
            assert driver.state == "stopped" and not led.state
            assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
            local.put(KEYS.command(ROBOT), command([1.0, 1.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            assert driver.state == "stopped"
            assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
            remote.put(KEYS.robot_order, encode(RobotOrder("resume", np.array([ROBOT]))))
            await trio.sleep(0.01)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            assert driver.state == "swimming" and led.state
            assert driver.statistics().orders == 2
            nursery.cancel_scope.cancel()

    run_mock(main)


def test_a_stop_of_the_fishs_watchdog_is_reported_as_a_failsafe_not_as_swimming(
    hardware: Hardware, caplog: pytest.LogCaptureFixture
) -> None:
    # The world has ended: the fish's watchdog turns the fins off. The robot said
    # 'swimming' with its fins off until its own failsafe fired, and then logged a second
    # stop; now it reports the failsafe at once, once, and swims at the next decision.
    watchdog = encode(Command(ROBOT, 0, np.zeros(4), led=False, watchdog=True))

    async def main() -> list[str]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True], command_timeout=10.0)
        states = []
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([1.0, 1.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            states.append(driver.state)
            local.put(KEYS.command(ROBOT), watchdog)
            await trio.sleep(0.01)
            states.append(driver.state)
            assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
            local.put(KEYS.command(ROBOT), watchdog)  # repeated: nothing new
            await trio.sleep(30.0)  # past the driver's own command timeout
            states.append(driver.state)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            states.append(driver.state)
            nursery.cancel_scope.cancel()
        assert driver.statistics().failsafe_stops == 1
        return states

    with caplog.at_level(logging.WARNING, "fishswarm"):
        states = run_mock(main)
    assert states == ["swimming", "failsafe", "failsafe", "swimming"]
    said = [r.getMessage() for r in caplog.records if "fins" in r.getMessage()]
    assert said == [
        f"robot {ROBOT}: its fish stopped the fins (no perception in time: is the world "
        "running, and the link up?)"
    ]


def test_a_resume_leaves_a_swimming_robot_swimming_under_its_failsafe(hardware: Hardware) -> None:
    """An operator resumes every robot while this one swims: it swims on, and the failsafe,
    which watches swimming robots, still stops its fins when commands stop."""

    async def main() -> tuple[str, float, Driver]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            await trio.sleep(0.01)
            start = trio.current_time()
            remote.put(KEYS.robot_order, encode(RobotOrder("resume")))
            await trio.sleep(0.01)
            after_resume = driver.state
            while driver.state != "failsafe":
                await trio.sleep(0.01)
            stopped_after = trio.current_time() - start
            nursery.cancel_scope.cancel()
        return after_resume, stopped_after, driver

    after_resume, stopped_after, driver = run_mock(main)
    assert after_resume == "swimming"
    assert 0.9 <= stopped_after <= 1.11  # the 1-s timeout from the last command, one poll
    assert hardware.fins.frequencies == (0.0, 0.0, 0.0, 0.0)  # type: ignore[attr-defined]
    assert driver.statistics().orders == 1


def test_each_perception_is_timed_from_the_start_and_announces_its_own_deliveries(
    hardware: Hardware,
) -> None:
    async def main() -> list[Perception]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        await trio.sleep(7.0)  # the driver starts at 7 s on the clock, its time at 0
        got = []
        async with (
            subscription(local, KEYS.perception(ROBOT)) as perceptions,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(driver.run, local, remote)
            got.append(decode((await perceptions.receive())[1], Perception))
            delivery = Delivery(ROBOT, 0, "signal", np.array([9]), np.array([0.3, 0.0, 0.0]))
            remote.put(KEYS.inbox(ROBOT), encode(delivery))
            remote.put(KEYS.inbox(ROBOT), encode(delivery))
            for _ in range(2):
                got.append(decode((await perceptions.receive())[1], Perception))
            nursery.cancel_scope.cancel()
        return got

    first, second, third = run_mock(main)
    assert [p.time for p in (first, second, third)] == [0.0, 0.5, 1.0]
    assert [p.tick for p in (first, second, third)] == [0, 1, 2]
    # Two deliveries came between the first and the second perception, none after.
    assert [p.inbox_count for p in (first, second, third)] == [0, 2, 0]


def test_a_slow_frame_does_not_make_the_robot_catch_up_the_periods_it_took(
    hardware: Hardware,
) -> None:
    """The second frame takes 1.6 s, over three 0.5-s periods. The period under way when it
    ends is sensed at once; after it, one frame a period, as before: the periods the slow
    frame took are not made up for by frames back to back."""
    calls = [0]

    async def slow_second(function: Callable[[], Look]) -> Look:
        calls[0] += 1
        if calls[0] == 2:
            await trio.sleep(1.6)
        return function()

    async def main() -> list[float]:
        local, remote = MemoryBus(), MemoryBus()
        settings = DriverSettings(ROBOT, "dispersion", KEYS, control_period=0.5)
        driver = Driver(settings, hardware, link_up=lambda: True, run_blocking=slow_second)
        times = []
        async with (
            subscription(local, KEYS.perception(ROBOT)) as perceptions,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(driver.run, local, remote)
            for _ in range(5):
                times.append(decode((await perceptions.receive())[1], Perception).time)
            nursery.cancel_scope.cancel()
        return times

    times = run_mock(main)
    np.testing.assert_allclose(times, [0.0, 2.1, 2.1, 2.6, 3.1], atol=1e-9)


def test_the_fish_vouches_for_itself_on_the_link_whenever_a_world_comes_up(
    hardware: Hardware,
) -> None:
    async def main() -> list[FishAbout]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        fish = Fish(FishSettings((ROBOT,), Scenario().fish_params(), KEYS))
        told = []
        async with (
            subscription(remote, KEYS.about(ROBOT)) as abouts,
            trio.open_nursery() as nursery,
        ):
            # A world already up when the robot starts, then a second one later.
            first = remote.declare_token(KEYS.alive("world", 0))
            await nursery.start(fish.run, local)
            await nursery.start(driver.run, local, remote)
            told.append(decode((await abouts.receive())[1], FishAbout))
            await trio.sleep(5.0)
            # Meanwhile the fish has said what it runs for the driver's run of
            # perceptions; its word for a world (run 0) comes only when one appears.
            assert all(decode(p, FishAbout).run != 0 for _, p in abouts.drain())
            first.undeclare()
            remote.declare_token(KEYS.alive("world", 1))
            told.append(decode((await abouts.receive())[1], FishAbout))
            nursery.cancel_scope.cancel()
        return told

    told = run_mock(main)
    assert [(about.ids.tolist(), about.run) for about in told] == [([ROBOT], 0), ([ROBOT], 0)]
    assert all(about.behavior == "dispersion" for about in told)


def test_broadcasts_go_out_and_deliveries_come_in_announced(hardware: Hardware) -> None:
    async def main() -> tuple[list[bytes], Perception]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        async with (
            subscription(remote, KEYS.outbox(ROBOT)) as outgoing,
            subscription(local, KEYS.inbox(ROBOT)) as incoming,
            subscription(local, KEYS.perception(ROBOT)) as perceptions,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(driver.run, local, remote)
            await perceptions.receive()  # the first perception, at start
            # The fish's broadcast names the driver's run, which means nothing on the link.
            broadcast = encode(Broadcast(ROBOT, 1, "signal", np.array([7]), 12345))
            local.put(KEYS.outbox(ROBOT), broadcast)
            # A simulated channel numbers its deliveries by its world's ticks (here 57) and
            # run (here 5); the fish acts on it at the driver's next perception (tick 1), and
            # waits for it under that perception's tick.
            delivery = Delivery(ROBOT, 57, "signal", np.array([9]), np.array([0.3, 0.0, 0.0]), 5)
            # A simulated fish's formation flag, which reaches a robot only through the
            # channel (its cameras never see a simulated fish flash), passes as well.
            flag = FormationFlag(FORMATION_SHAPES.index("pyramid"), 2, True, 1, 0, 4)
            heard = Delivery(ROBOT, 57, "formation", flag.values(), np.array([0.5, 0.0, 0.0]))
            remote.put(KEYS.inbox(ROBOT), encode(delivery))
            remote.put(KEYS.inbox(ROBOT), encode(heard))
            remote.put(KEYS.inbox(ROBOT), b"garbage")
            got = [(await incoming.receive())[1] for _ in range(2)]
            _, payload = await perceptions.receive()
            sent = [p for _, p in outgoing.drain()]
            perception = decode(payload, Perception)
            # ... and under its run, which the driver's perceptions carry (not the world's).
            assert [decode(p, Delivery) for p in got] == [
                dataclasses.replace(delivery, tick=1, run=perception.run),
                dataclasses.replace(heard, tick=1, run=perception.run),
            ]
            assert perception.tick == 1 and perception.run != 0
            nursery.cancel_scope.cancel()
        assert driver.statistics().rejected == 1
        return sent, decode(payload, Perception)

    sent, perception = run_mock(main)
    assert len(sent) == 1 and decode(sent[0], Broadcast).values.tolist() == [7]
    assert decode(sent[0], Broadcast).run is None
    assert perception.inbox_count == 2


def test_a_missing_frame_skips_the_period_and_malformed_commands_are_counted(
    hardware: Hardware,
) -> None:
    camera = hardware.camera
    assert isinstance(camera, SceneCamera)
    camera.working = False

    async def main() -> Driver:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        async with (
            subscription(local, KEYS.perception(ROBOT)) as perceptions,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), b"\x00not msgpack")
            await trio.sleep(1.2)  # three periods without frames
            assert perceptions.pending() == 0
            camera.working = True
            await perceptions.receive()
            nursery.cancel_scope.cancel()
        return driver

    statistics = run_mock(main).statistics()
    assert statistics.frames_missed == 3 and statistics.perceptions == 1
    assert statistics.rejected == 1 and statistics.commands == 0


class FlakyDepth:
    """A pressure sensor on an I²C bus that fails as real ones do, on the reads listed."""

    def __init__(self, failures: dict[int, Exception]) -> None:
        self.failures = failures
        self.reads = 0

    def read_depth(self) -> float:
        self.reads += 1
        failure = self.failures.get(self.reads)
        if failure is not None:
            raise failure
        return 0.5

    def close(self) -> None:
        pass


def test_a_failing_sensor_skips_its_periods_and_the_robot_senses_on(
    factory: object, caplog: pytest.LogCaptureFixture
) -> None:
    # Reads 2 and 3: the device does not answer on the bus (what smbus2 raises); read 5: a
    # reading the sensor's own checks refuse.
    from fishswarm.bluebot.pressure import SensorError

    nack = OSError(121, "Remote I/O error")
    depth = FlakyDepth({2: nack, 3: nack, 5: SensorError("pressure out of range")})
    hardware = Hardware(
        GpioFins(pin_factory=factory), GpioLeds(pin_factory=factory), SceneCamera(), depth
    )

    async def main() -> Driver:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True])
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            await trio.sleep(3.2)  # periods at 0, 0.5, …, 3.0 s: seven reads
            nursery.cancel_scope.cancel()
        return driver

    with caplog.at_level("WARNING", logger="fishswarm.actors.driver"):
        statistics = run_mock(main).statistics()
    hardware.close()
    assert depth.reads == 7
    assert statistics.frames_missed == 3 and statistics.perceptions == 4
    # Logged when a failure starts or changes, and when sensing comes back: not every period.
    messages = [record.getMessage() for record in caplog.records]
    assert len(messages) == 4
    assert "Remote I/O error" in messages[0] and "SensorError" not in messages[0]
    assert "sensing again after 2 periods" in messages[1]
    assert "SensorError: pressure out of range" in messages[2]
    assert "sensing again after 1 periods" in messages[3]


@pytest.mark.parametrize(
    "defect",
    [
        TypeError("read_depth() got an unexpected argument"),
        NotImplementedError("a port left unfinished"),  # a RuntimeError, yet a defect
    ],
)
def test_a_defect_in_a_sensor_port_still_ends_the_run(factory: object, defect: Exception) -> None:
    # Not a sensor's failure but a programming error: it must not be skipped in silence.
    depth = FlakyDepth({2: defect})
    hardware = Hardware(
        GpioFins(pin_factory=factory), GpioLeds(pin_factory=factory), SceneCamera(), depth
    )

    async def main() -> None:
        driver = make_driver(hardware, [True])
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, MemoryBus(), MemoryBus())
            await trio.sleep(3.0)

    with pytest.RaisesGroup(type(defect), flatten_subgroups=True, allow_unwrapped=True):
        run_mock(main)
    hardware.close()
    assert depth.reads == 2


def test_settings_that_would_stop_the_fins_between_commands_are_refused() -> None:
    with pytest.raises(ValueError, match="command_timeout"):
        DriverSettings(1, "dispersion", control_period=1.0, command_timeout=0.5)
    with pytest.raises(ValueError, match="robot_id must be a fish id"):
        DriverSettings(-1, "dispersion")
    with pytest.raises(ValueError, match="must exceed the control period"):
        DriverSettings(1, "dispersion", control_period=1.0, command_timeout=1.0)
    for name in ("control_period", "command_timeout", "link_timeout", "status_period"):
        with pytest.raises(ValueError, match=f"{name} must be a positive number of seconds"):
            DriverSettings(1, "dispersion", **{name: 0.0})  # type: ignore[arg-type]
    assert DriverSettings(0, "dispersion").robot_id == 0  # fish ids start at 0


def test_a_short_command_timeout_is_watched_closely(hardware: Hardware) -> None:
    """The guard looks four times a timeout (at most every 0.1 s): with 0.15 s, the fins
    stop within 0.0375 s of it, not at the next tenth of a second."""
    settings = DriverSettings(
        ROBOT, "dispersion", KEYS, control_period=0.1, command_timeout=0.15, link_timeout=3.0
    )

    async def main() -> float:
        local, remote = MemoryBus(), MemoryBus()
        driver = Driver(settings, hardware, link_up=lambda: True, run_blocking=inline)
        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            local.put(KEYS.command(ROBOT), command([1.0, 0.0, 0.0, 0.0]))
            start = trio.current_time()
            while driver.state != "failsafe":
                await trio.sleep(0.001)
            nursery.cancel_scope.cancel()
        return trio.current_time() - start

    assert 0.15 <= run_mock(main) <= 0.19


@pytest.mark.parametrize("behavior", ["formation", "dispersion"])
def test_an_operators_formation_order_reaches_the_fish_in_its_next_perception(
    hardware: Hardware, behavior: str
) -> None:
    """A robot has no world to tell its fish of a new shape: its driver takes the order,
    names the shape in every perception from then on and in its status; an order for
    another robot changes nothing, nor does one while stopped undo the stop (it is taken,
    for when the robot resumes). A fish that
    runs another behaviour has no formation to take: the order is let go."""

    async def main() -> tuple[list[str | None], list[str | None], str, int]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True], command_timeout=10.0, behavior=behavior)
        told: list[str | None] = []
        reported: list[str | None] = []
        local.subscribe(
            KEYS.perception(ROBOT), lambda k, p: told.append(decode(p, Perception).formation)
        )
        remote.subscribe(
            KEYS.robot_status(ROBOT),
            lambda k, p: reported.append(decode(p, RobotStatus).formation),
        )

        def order(action: str, ids: list[int], shape: str | None = None) -> None:
            ordered = RobotOrder(action, np.array(ids, dtype=np.int64), shape)
            remote.put(KEYS.robot_order, encode(ordered))

        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            await trio.sleep(0.75)  # perceptions at 0 and 0.5 s
            order("formation", [ROBOT + 1], "column")
            await trio.sleep(0.5)  # 1 s
            order("formation", [], "column")
            await trio.sleep(0.5)  # 1.5 s
            order("stop", [])
            order("formation", [ROBOT], "diamond")
            await trio.sleep(0.5)
            state, orders = driver.state, driver.statistics().orders
            nursery.cancel_scope.cancel()
        return told, reported, state, orders

    told, reported, state, orders = run_mock(main)
    assert state == "stopped"
    if behavior == "formation":
        # Perceptions at 0, 0.5, 1 and 1.5 s (the last after the order at 1 s); a stopped
        # robot makes none, but its status names the shape its fish will take.
        assert told == [None, None, None, "column"]
        assert reported[-1] == "diamond" and "column" in reported
    else:  # taken in and counted as an order, and let go
        assert set(told) == {None} and set(reported) == {None}
        assert orders == 3  # its own three: the one for another robot is not its


# The robot, a steady neighbour ahead to its right, and one 0.4 m to its left whose LEDs flash.
FLASHER = np.array([[0.8, 0.4, 0.5]])


class FlashingSceneCamera:
    """Both cameras seeing the steady neighbour and a flasher at 15 Hz: of a burst of
    frames at 60 fps, the first two show it lit, the next two dark, and so on; a lone
    frame shows it lit."""

    def __init__(self) -> None:
        scene = np.concatenate([POSITION, FLASHER])
        yaw = np.append(YAW, 0.5)
        self.images = [self._render(scene, yaw, lit) for lit in (True, False)]

    @staticmethod
    def _render(scene: np.ndarray, yaw: np.ndarray, lit: bool) -> dict[CameraSide, np.ndarray]:
        return render_views(
            scene, yaw, 0, fisheye=Fisheye(), optics=Optics(), robot=BlueBot(),
            rng=np.random.default_rng(0), lit=np.array([True, True, lit]),
        )  # fmt: skip

    def capture(self, side: CameraSide) -> np.ndarray:
        return self.images[0][side]

    def capture_frames(self, side: CameraSide, count: int) -> list[np.ndarray]:
        return [self.images[0 if frame % 4 < 2 else 1][side] for frame in range(count)]

    def close(self) -> None:
        pass


@asynccontextmanager
async def running_formation_driver(
    hardware: Hardware,
) -> AsyncIterator[tuple[MemoryBus, Inbox[tuple[str, bytes]], Driver]]:
    """A formation robot's driver running on ``hardware``, its link up: its local Bus, its
    fish's perceptions and the driver, until the block ends."""
    local, remote = MemoryBus(), MemoryBus()
    driver = make_driver(hardware, [True], command_timeout=10.0, behavior="formation")
    async with (
        subscription(local, KEYS.perception(ROBOT)) as perceived,
        trio.open_nursery() as nursery,
    ):
        await nursery.start(driver.run, local, remote)
        yield local, perceived, driver
        nursery.cancel_scope.cancel()


def run_closing(hardware: Hardware, main: Callable[[], Awaitable[T]]) -> T:
    """``main`` under trio's MockClock, the robot's ports released after, however it ends."""
    try:
        return run_mock(main)
    finally:
        hardware.close()


def answer_flagging(
    local: MemoryBus, tick: int, *, joined: bool = True, led: bool = True, gain: float = 0.0
) -> None:
    """A formation fish's answer to the perception of ``tick``: its flag, then its command
    (every fin at ``gain``), which announces the flag."""
    local.put(KEYS.outbox(ROBOT), flag(joined, tick))
    command = Command(ROBOT, tick, np.full(4, gain), led=led, broadcasts=1)
    local.put(KEYS.command(ROBOT), encode(command))


def flag(joined: bool, tick: int) -> bytes:
    shape = FORMATION_SHAPES.index("triangle")
    values = FormationFlag(shape, 2, joined, 1, 45_000, tick + 1, 30).values()
    return encode(Broadcast(ROBOT, tick, "formation", values))


def test_a_robot_flashes_while_its_fish_holds_its_place_and_hands_it_the_flashers_it_sees(
    factory: object,
) -> None:
    """The driver plays the channel's part by light: the fish's flag, joined, flashes the
    LEDs at 15 Hz; a neighbour seen in only one of two frames half a flash period apart
    comes to the fish as a flag where the cameras see it, announced in its perception."""
    hardware = Hardware(
        GpioFins(pin_factory=factory),
        GpioLeds(pin_factory=factory),
        FlashingSceneCamera(),
        FixedDepth(),
    )
    leds: GpioLeds = hardware.leds  # type: ignore[assignment]
    lights: list[tuple[bool, float]] = []
    said: list[bool | None] = []
    seen_in_status: list[int | None] = []

    async def main() -> tuple[list[Perception], list[Delivery]]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, [True], command_timeout=10.0, behavior="formation")
        perceptions: list[Perception] = []
        async with (
            subscription(local, KEYS.perception(ROBOT)) as perceived,
            subscription(local, KEYS.inbox(ROBOT)) as inbox,
            subscription(remote, KEYS.outbox(ROBOT)) as outgoing,
            trio.open_nursery() as nursery,
        ):
            await nursery.start(driver.run, local, remote)

            async def answer(*flags: bytes, broadcasts: int) -> None:
                perception = decode((await perceived.receive())[1], Perception)
                perceptions.append(perception)
                for payload in flags:
                    local.put(KEYS.outbox(ROBOT), payload)
                local.put(
                    KEYS.command(ROBOT),
                    encode(Command(ROBOT, perception.tick, np.zeros(4), broadcasts=broadcasts)),
                )
                await trio.sleep(0.01)
                lights.append((leds.lit, leds.flash_frequency))
                said.append(driver.status().flashing)

            await answer(flag(True, 0), broadcasts=1)  # tick 0: joined → flashing
            await answer(broadcasts=0)  # tick 1: no flag → steady
            await answer(flag(False, 2), broadcasts=1)  # tick 2: seeking → steady
            await answer(flag(True, 3), broadcasts=1)  # tick 3: joined again
            seen_in_status.append(driver.status().flags_seen)
            deliveries = [decode(payload, Delivery) for _, payload in inbox.drain()]
            # The flags went by light: none onto the link.
            assert outgoing.drain() == [] and driver.statistics().broadcasts == 0
            # No more commands: the failsafe stops the fins, and a robot that no longer
            # swims holds no place (its LEDs steady); nor does one stranded.
            while driver.state != "failsafe":
                await trio.sleep(0.1)
            lights.append((leds.lit, leds.flash_frequency))
            remote.put(KEYS.robot_order, encode(RobotOrder("stop")))
            await trio.sleep(0.01)
            lights.append((leds.lit, leds.flash_frequency))
            local.put(KEYS.outbox(ROBOT), flag(True, 4))  # a flag while stopped
            await trio.sleep(0.01)
            lights.append((leds.lit, leds.flash_frequency))
            nursery.cancel_scope.cancel()
        return perceptions, deliveries

    perceptions, deliveries = run_closing(hardware, main)
    assert [flashing for _, flashing in lights] == [15.0, 0.0, 0.0, 15.0, 0.0, 0.0, 0.0]
    assert said == [True, None, None, True]  # as its status tells the base station
    assert [lit for lit, _ in lights[1:3]] == [True, True]  # steady, as the command says
    assert lights[4][0]  # the failsafe: steady
    assert [lit for lit, _ in lights[5:]] == [False, False]  # an operator's stop: dark
    # Tick 0 came before the fish's first flag: one frame per camera (the flasher lit in
    # it). From then on each camera takes frames 0 and 2 of a burst, and the flasher is lit
    # in one of them: a flag for the fish while it flags itself (its shape is the one the
    # flag by light takes); at tick 2 it had flagged nothing at its last decision.
    assert [p.inbox_count for p in perceptions] == [0, 1, 0, 1]
    assert [p.neighbors.shape[0] for p in perceptions] == [2, 2, 2, 2]
    assert [d.tick for d in deliveries] == [1, 3]
    own = FormationFlag.from_values(decode(flag(True, 0), Broadcast).values)
    for delivery in deliveries:
        assert delivery.kind == "formation" and delivery.receiver_id == ROBOT
        assert FormationFlag.from_values(delivery.values) == flag_by_light(own)
        truth = to_body((FLASHER - POSITION[0])[None], YAW[:1])[0, 0]
        np.testing.assert_allclose(delivery.sender_position, truth, rtol=0.05, atol=0.02)
    assert flag_by_light(own) == FormationFlag(own.shape, -1, True, NO_HOPS, 45_000, 0)
    assert seen_in_status == [2]  # by tick 3


class RecordingLeds:
    """LEDs that note what they were told."""

    def __init__(self) -> None:
        self.told: list[str] = []

    def set_lit(self, lit: bool) -> None:
        self.told.append(f"lit {lit}")

    def set_flashing(self, frequency: float) -> None:
        self.told.append(f"flashing {frequency:g}")

    def close(self) -> None:
        self.told.append("close")


class BurstCountingCamera(FlashingSceneCamera):
    """The flashing scene, counting the bursts of frames the driver asks for."""

    def __init__(self) -> None:
        super().__init__()
        self.bursts = 0

    def capture_frames(self, side: CameraSide, count: int) -> list[np.ndarray]:
        self.bursts += 1
        return super().capture_frames(side, count)


def test_a_robot_that_goes_on_holding_its_place_starts_its_flashing_once(
    factory: object,
) -> None:
    """While the fish's flags go on saying it holds its place, the LEDs are told to flash
    once: told again at every flag and command, gpiozero's blinking thread would start
    afresh, lit, each period, and a flasher would no longer be lit in exactly one of two
    frames half a flash period apart. A broadcast of another kind makes the cameras take
    no bursts of frames: only a formation flag does."""
    leds = RecordingLeds()
    camera = BurstCountingCamera()
    hardware = Hardware(GpioFins(pin_factory=factory), leds, camera, FixedDepth())
    signal = encode(Broadcast(ROBOT, 0, "signal", np.array([7])))

    async def main() -> tuple[list[int], list[str]]:
        bursts: list[int] = []
        async with running_formation_driver(hardware) as (local, perceived, _):
            for step in range(4):
                tick = decode((await perceived.receive())[1], Perception).tick
                bursts.append(camera.bursts)
                if step == 0:
                    local.put(KEYS.outbox(ROBOT), signal)
                    command = Command(ROBOT, tick, np.zeros(4), broadcasts=1)
                    local.put(KEYS.command(ROBOT), encode(command))
                else:
                    answer_flagging(local, tick)
            await trio.sleep(0.01)
            told = list(leds.told)
        return bursts, told

    bursts, told = run_closing(hardware, main)
    # No burst before the first formation flag (after tick 1's perception); then one of
    # each camera at each perception.
    assert bursts == [0, 0, 2, 4]
    # Lit by the first command; flashing from the first joined flag, and left flashing.
    assert told == ["lit True", "flashing 15"]


class PhasedFlashingCamera(FlashingSceneCamera):
    """The flashing scene, the flasher's period starting ``offset`` frames before a burst:
    lit in the frames where (frame + offset) mod 4 is 0 or 1."""

    def __init__(self, offset: int) -> None:
        super().__init__()
        self.offset = offset

    def capture_frames(self, side: CameraSide, count: int) -> list[np.ndarray]:
        lit = [(frame + self.offset) % 4 < 2 for frame in range(count)]
        return [self.images[0 if shown else 1][side] for shown in lit]


@pytest.mark.parametrize("offset", [0, 1, 2, 3])
def test_a_flasher_is_told_from_frames_0_and_2_of_a_burst_whatever_its_phase(
    factory: object, offset: int
) -> None:
    """At 60 fps a 15-Hz flasher is lit in two consecutive frames of every four: frames 0
    and 2 of a burst, half a flash period apart, show it lit in exactly one, whatever the
    phase of its period; any other pair of frames misses it (both dark) or takes it for
    steady (both lit) at some phase."""
    hardware = Hardware(
        GpioFins(pin_factory=factory), RecordingLeds(), PhasedFlashingCamera(offset), FixedDepth()
    )

    async def main() -> Perception:
        async with running_formation_driver(hardware) as (local, perceived, _):
            await perceived.receive()  # tick 0, before the fish flags: no burst
            answer_flagging(local, 0)
            perception = decode((await perceived.receive())[1], Perception)
        return perception

    perception = run_closing(hardware, main)
    # Both neighbours seen, the flasher handed to the fish as a flag.
    assert perception.neighbors.shape[0] == 2 and perception.inbox_count == 1


def test_a_command_that_darkens_the_leds_ends_their_flashing(factory: object) -> None:
    """The fish's command says whether its LEDs are on: dark LEDs do not flash, even while
    its flag says it holds its place; lit again, they flash again."""
    leds = RecordingLeds()
    hardware = Hardware(GpioFins(pin_factory=factory), leds, FlashingSceneCamera(), FixedDepth())

    async def main() -> list[str]:
        async with running_formation_driver(hardware) as (local, perceived, _):
            await perceived.receive()  # tick 0: lit, no flag
            local.put(KEYS.command(ROBOT), encode(Command(ROBOT, 0, np.zeros(4))))
            for led in (True, False, True):
                tick = decode((await perceived.receive())[1], Perception).tick
                answer_flagging(local, tick, led=led)
            await trio.sleep(0.01)
            told = list(leds.told)
        return told

    told = run_closing(hardware, main)
    # Tick 0: lit; tick 1: flashing; tick 2: dark (its flag says it holds its place);
    # tick 3: lit, and flashing again.
    assert told == ["lit True", "flashing 15", "lit False", "flashing 15"]


@pytest.mark.parametrize("end", ["stranded", "failsafe"])
def test_a_flag_of_a_decision_under_way_does_not_restart_a_stopped_robots_flashing(
    factory: object, end: str
) -> None:
    """The fins stop — the link lost too long, or no command for the timeout — and the
    LEDs steady; a joined flag of a decision that was under way comes after: a robot that
    no longer swims holds no place, so they stay steady."""
    leds = RecordingLeds()
    hardware = Hardware(GpioFins(pin_factory=factory), leds, FlashingSceneCamera(), FixedDepth())
    link = [True]

    async def main() -> tuple[str, list[str], bool | None]:
        local, remote = MemoryBus(), MemoryBus()
        driver = make_driver(hardware, link, command_timeout=1.0, behavior="formation")

        async with trio.open_nursery() as nursery:
            await nursery.start(driver.run, local, remote)
            answer_flagging(local, 0, gain=0.5)
            await trio.sleep(0.01)
            assert leds.told[-1] == "flashing 15"
            if end == "stranded":
                link[0] = False
                while driver.state != "stranded":  # commands keep coming: the link decides
                    answer_flagging(local, 0, gain=0.5)
                    await trio.sleep(0.1)
            else:
                while driver.state != "failsafe":
                    await trio.sleep(0.1)
            local.put(KEYS.outbox(ROBOT), flag(True, 1))  # the late flag
            await trio.sleep(5.0)
            told, flashing = list(leds.told), driver.status().flashing
            nursery.cancel_scope.cancel()
        return driver.state, told, flashing

    state, told, flashing = run_closing(hardware, main)
    assert state == end
    assert told[-1] == "lit True" and told.count("flashing 15") == 1, told
    assert flashing is None
