"""Mock robots over real Zenoh on 127.0.0.1: they join a simulated swarm, show up in the
fleet, obey an operator's stop within a second, stop their fins within two seconds of losing
the router (their camera images come over that link), and swim again when it returns."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from pathlib import Path

import pytest
import trio

pytest.importorskip("gpiozero.pins.mock")

from fishswarm.actors.bus import Bus
from fishswarm.actors.driver import Driver, DriverSettings
from fishswarm.actors.mock_robot import BodyFins
from fishswarm.actors.robot import (
    RobotSettings,
    order_fleet,
    run_robot,
    survey_fleet,
)
from fishswarm.actors.security import init_secure, session_security
from fishswarm.behaviors.formation import NO_HOPS
from fishswarm.bluebot.gpio import GpioLeds
from fishswarm.protocols.codec import decode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import (
    FLASHING,
    FORMATION_SHAPES,
    Delivery,
    FormationFlag,
    RobotStatus,
    Snapshot,
)
from fishswarm.sim.scenario import Scenario
from fishswarm.study.recording import read_recording
from tests.conftest import free_port, open_client_bus, run_trio, subscription, wait_for_port

pytestmark = pytest.mark.integration

KEYS = KeySpace()
PERIOD = 0.2


def start_world(endpoint: str, folder: Path, *extra: str) -> subprocess.Popen[str]:
    """A realtime simulated swarm of three fish with its router, for 60 s (``extra``: more
    arguments to ``fishswarm run``)."""
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "fishswarm",
            "run",
            "--fish",
            "3",
            "--time",
            "realtime",
            "--period",
            str(PERIOD),
            "--duration",
            "60",
            "--quiet",
            "--listen",
            endpoint,
            "--record",
            str(folder / "run.mcap"),
            "--summary",
            str(folder / "run.json"),
            *extra,
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.fixture
def worlds() -> Iterator[list[subprocess.Popen[str]]]:
    started: list[subprocess.Popen[str]] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=30)


def settings(robot_id: int, endpoint: str, behavior: str = "dispersion") -> RobotSettings:
    return RobotSettings(
        DriverSettings(robot_id, behavior, KEYS, control_period=PERIOD, command_timeout=1.0),
        Scenario(control_period=PERIOD, behavior=behavior).fish_params(),
        endpoint,
        hardware="mock",
        connect_timeout=10.0,
    )


async def until(condition: object, *, timeout: float, step: float = 0.02) -> float:
    """Wait until ``condition()`` holds; how long it took, s."""
    start = trio.current_time()
    with trio.fail_after(timeout):
        while not condition():  # type: ignore[operator]
            await trio.sleep(step)
    return trio.current_time() - start


def beating(driver: Driver) -> bool:
    fins = driver.hardware.fins
    assert isinstance(fins, BodyFins)
    return any(f > 0 for f in fins.frequencies)


@pytest.mark.slow
def test_mock_robots_join_obey_a_stop_and_survive_losing_the_router(
    tmp_path: Path, worlds: list[subprocess.Popen[str]]
) -> None:
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    worlds.append(start_world(endpoint, tmp_path))
    wait_for_port(port)
    measured: dict[str, float] = {}

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            robots: list[Driver] = [
                await nursery.start(run_robot, settings(robot_id, endpoint))
                for robot_id in (10, 11)
            ]
            # They swim in the simulated world: its snapshots render their camera images,
            # their fish actors answer the perceptions the drivers make of them.
            await until(lambda: all(r.state == "swimming" for r in robots), timeout=20)
            assert all(r.statistics().perceptions > 0 for r in robots)

            async with open_client_bus(endpoint, 5.0) as base:
                fleet = await survey_fleet(base, KEYS, listen=1.0)
                assert [entry.robot_id for entry in fleet] == [10, 11]
                assert all(e.alive and e.status and e.status.link for e in fleet)
                listed = await trio.run_process(
                    [sys.executable, "-m", "fishswarm", "robots", "--connect", endpoint, "--json"],
                    capture_stdout=True,
                    capture_stderr=True,
                )
                rows = json.loads(listed.stdout)
                assert [row["id"] for row in rows] == [10, 11]
                assert {row["behavior"] for row in rows} == {"dispersion"}
                assert [row["drivers"] for row in rows] == [1, 1]  # one process each

                # An operator's stop reaches every robot: both report it.
                async with subscription(base, KEYS.robot_statuses()) as statuses:
                    start = trio.current_time()
                    order_fleet(base, KEYS, "stop", [])
                    stopped: set[int] = set()
                    with trio.fail_after(5):
                        while stopped != {10, 11}:
                            _, payload = await statuses.receive()
                            status = decode(payload, RobotStatus)
                            if status.state == "stopped":
                                stopped.add(status.robot_id)
                    measured["stop"] = trio.current_time() - start
                assert not any(beating(r) for r in robots)
                order_fleet(base, KEYS, "resume", [10, 11])
                await until(lambda: all(r.state == "swimming" for r in robots), timeout=5)

                # From the command line: the operator learns which robots did not confirm.
                async def robots_command(*words: str) -> tuple[int, str]:
                    done = await trio.run_process(
                        [sys.executable, "-m", "fishswarm", "robots", "--connect", endpoint,
                         "--listen", "1.5", *words],
                        capture_stdout=True, capture_stderr=True, check=False,
                    )  # fmt: skip
                    return done.returncode, done.stderr.decode()

                code, said = await robots_command("--stop", "10", "99")
                assert code == 1, said
                assert "robot 99 did not confirm the stop (not heard from)" in said
                assert "robot 10 did not" not in said and robots[0].state == "stopped"
                code, said = await robots_command("--resume", "10")
                assert code == 0 and "did not confirm" not in said, said
                # Another swarm's name on this router: no robot answers an order to all.
                code, said = await robots_command("--swarm", "nobody", "--stop")
                assert code == 1 and "no robot was heard from" in said, said
                # A robot named there is named as unconfirmed, with why.
                code, said = await robots_command("--swarm", "nobody", "--resume", "4")
                assert code == 1, said
                assert (
                    "robot 4 did not confirm the resume (not heard from): no robot 4 is known "
                    "on this router (robots heard from: none)" in said
                ), said
                await until(lambda: all(r.state == "swimming" for r in robots), timeout=5)

            # The router (and the world) die: no more frames, no more commands, fins off.
            await until(lambda: all(beating(r) for r in robots), timeout=5)
            start = trio.current_time()
            worlds[0].kill()
            measured["fins_off"] = await until(
                lambda: not any(beating(r) for r in robots), timeout=5
            )
            await until(lambda: not any(r.link for r in robots), timeout=5)
            # A new world on the same router address: the robots reconnect and swim again.
            worlds.append(start_world(endpoint, tmp_path / "again"))
            perceptions = [r.statistics().perceptions for r in robots]
            await until(
                lambda: all(
                    r.link and r.state == "swimming" and r.statistics().perceptions > p
                    for r, p in zip(robots, perceptions, strict=True)
                ),
                timeout=30,
            )
            assert all(r.statistics().failsafe_stops >= 1 for r in robots)
            nursery.cancel_scope.cancel()

    (tmp_path / "again").mkdir()
    run_trio(main, timeout=120)
    assert measured["stop"] <= 1.0, measured
    assert measured["fins_off"] <= 2.0, measured


def test_a_mock_robot_vouches_for_itself_and_joins_a_secured_swarm(
    tmp_path: Path, worlds: list[subprocess.Popen[str]]
) -> None:
    """A secured world admits only fish vouched for on their own about keys: the robot's
    fish actor vouches on its driver's in-memory bus, and the driver carries that onto the
    link, and shows the fish each world that comes up (so it vouches again for a world
    started after it)."""
    folder = tmp_path / "secure"
    init_secure(folder, robots=(10,))
    port = free_port()
    endpoint = f"tls/127.0.0.1:{port}"

    async def main() -> None:
        secured = dataclasses.replace(
            settings(10, endpoint), session_extra=session_security(folder, "robot-10")
        )
        worlds.append(start_world(endpoint, tmp_path, "--secure", str(folder)))
        async with trio.open_nursery() as nursery:
            driver: Driver = await nursery.start(run_robot, secured)
            await until(lambda: driver.state == "swimming", timeout=30)
            await trio.sleep(1.0)  # a few ticks with the robot in the world
            nursery.cancel_scope.cancel()

    run_trio(main, timeout=90)
    world = worlds[0]
    world.terminate()  # as Ctrl-C: the recording is closed whole
    world.communicate(timeout=30)
    ids = {int(i) for s in read_recording(tmp_path / "run.mcap").snapshots for i in s.ids}
    assert ids == {0, 1, 2, 10}


def test_a_world_names_a_robot_started_with_another_control_period(
    tmp_path: Path, worlds: list[subprocess.Popen[str]]
) -> None:
    """A robot is no fish the world expects, yet it joins the run: one started to decide
    every 0.4 s in a world of 0.2-s ticks is named in the world's log as it comes up."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    worlds.append(start_world(endpoint, tmp_path))
    wait_for_port(port)
    slower = Scenario(control_period=2 * PERIOD, behavior="dispersion")
    robot = RobotSettings(
        DriverSettings(12, "dispersion", KEYS, control_period=2 * PERIOD, command_timeout=1.0),
        slower.fish_params(),
        endpoint,
        hardware="mock",
        connect_timeout=10.0,
    )

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            driver: Driver = await nursery.start(run_robot, robot)
            await until(lambda: driver.state == "swimming", timeout=30)
            await trio.sleep(0.5)
            nursery.cancel_scope.cancel()

    run_trio(main, timeout=90)
    world = worlds[0]
    world.terminate()
    _, said = world.communicate(timeout=30)
    assert "fish 12 decide every 0.4 s, but this world's scenario says 0.2 s (--period)" in said


@pytest.mark.slow
def test_fishswarm_formation_switches_robots_that_have_no_world_and_names_those_that_did_not(
    worlds: list[subprocess.Popen[str]],
) -> None:
    """Robots in a tank with no simulated world: ``fishswarm formation`` orders them (no
    world answers), robots 10 and 11 confirm the shape, and robot 12, whose fish run
    dispersion, is named as not having taken it (exit 1)."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    worlds.append(
        subprocess.Popen(
            [sys.executable, "-m", "fishswarm", "router", "--listen", endpoint],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
    )
    wait_for_port(port)
    said: dict[str, tuple[int, str]] = {}

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            robots: list[Driver] = [
                await nursery.start(run_robot, settings(robot_id, endpoint, behavior))
                for robot_id, behavior in ((10, "formation"), (11, "formation"))
            ]

            async def formation(shape: str) -> tuple[int, str]:
                done = await trio.run_process(
                    [sys.executable, "-m", "fishswarm", "formation", shape, "--connect",
                     endpoint, "--listen", "1.5"],
                    capture_stdout=True, capture_stderr=True, check=False,
                )  # fmt: skip
                return done.returncode, done.stdout.decode() + done.stderr.decode()

            said["two"] = await formation("column")
            assert [r.statistics().orders for r in robots] == [1, 1]
            listed = await trio.run_process(
                [sys.executable, "-m", "fishswarm", "robots", "--connect", endpoint, "--json"],
                capture_stdout=True,
            )
            rows = json.loads(listed.stdout)
            assert [(row["id"], row["formation"]) for row in rows] == [
                (10, "column"),
                (11, "column"),
            ]
            await nursery.start(run_robot, settings(12, endpoint, "dispersion"))
            said["three"] = await formation("diamond")
            nursery.cancel_scope.cancel()

    run_trio(main, timeout=120)
    code, text = said["two"]
    assert code == 0, text
    assert text.strip().splitlines() == ["formation column on robots 10, 11"]
    code, text = said["three"]
    assert code == 1, text
    assert "robot 12 did not confirm the formation (its fish run dispersion, not a formation)" in (
        text
    )
    assert "formation diamond on robots 10, 11" in text


@pytest.mark.slow
def test_two_mock_robots_in_a_formation_flag_to_each_other_by_light(
    worlds: list[subprocess.Popen[str]],
) -> None:
    """Robots have no simulated channel: a robot whose fish holds its place flashes its
    LEDs, the world names it flashing in its snapshots, and the other robot's cameras,
    rendered from them, see it flash — its driver hands its fish the flag. Two robots 0
    and 1 are the whole school of a world of two formation fish."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    worlds.append(fishswarm("router", "--listen", endpoint))
    wait_for_port(port)
    world = ["world", "--connect", endpoint, "--fish", "2", "--behavior", "formation"]
    worlds.append(
        fishswarm(*world, "--time", "realtime", "--period", str(PERIOD), "--duration", "60",
                  "--spawn-radius", "0.5", "--quiet")
    )  # fmt: skip
    named: set[int] = set()

    async def main() -> tuple[tuple[int, int], float]:
        async with two_formation_robots(endpoint) as (robots, base):

            def take(key: str, payload: bytes) -> None:
                snapshot = decode(payload, Snapshot)
                if snapshot.lights is not None:
                    named.update(snapshot.ids[snapshot.lights == FLASHING].tolist())

            base.subscribe(KEYS.snapshot, take)
            # One robot flashes while the other has been handed flags by light.
            took = await until(
                lambda: (
                    any(
                        flashing(a) and b.statistics().flags_seen > 0
                        for a, b in (robots, robots[::-1])
                    )
                    and named
                ),
                timeout=60,
            )
            flasher, seer = next(
                (a.settings.robot_id, b.settings.robot_id)
                for a, b in (robots, robots[::-1])
                if flashing(a) and b.statistics().flags_seen > 0
            )
        return (flasher, seer), took

    (flasher, seer), took = run_trio(main, timeout=120)
    # One robot flashed, the world named it so, and the other was handed its flags.
    assert flasher != seer and flasher in named and named <= {0, 1}, (flasher, named, took)


@pytest.mark.slow
def test_a_simulated_fish_among_mock_robots_is_shown_a_flashing_robots_flag(
    worlds: list[subprocess.Popen[str]],
) -> None:
    """Robots 0 and 1 and a simulated fish 2 in one formation: once a robot holds its place
    and flashes, the channel shows fish 2, which sees it, a one-bit flag (no slot, joined,
    no hops, no sequence); the robots get none of those (they see flashes with their
    cameras), but fish 2's own flags, which reach them only through the channel."""
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    worlds.append(fishswarm("router", "--listen", endpoint))
    wait_for_port(port)
    worlds.append(fishswarm("channel", "--connect", endpoint))
    worlds.append(
        fishswarm("world", "--connect", endpoint, "--fish", "3", "--behavior", "formation",
                  "--time", "realtime", "--period", str(PERIOD), "--duration", "60",
                  "--spawn-radius", "0.5", "--quiet")
    )  # fmt: skip
    worlds.append(
        fishswarm("fish", "--id", "2", "--connect", endpoint, "--behavior", "formation",
                  "--period", str(PERIOD))
    )  # fmt: skip
    flags: dict[int, list[FormationFlag]] = {0: [], 1: [], 2: []}

    def by_light(flag: FormationFlag) -> bool:
        # What light says: a fish's own flags have a slot or a sequence number.
        return flag.slot == -1 and flag.sequence == 0

    async def main() -> None:
        async with two_formation_robots(endpoint) as (robots, base):

            def take(key: str, payload: bytes) -> None:
                delivery = decode(payload, Delivery)
                if delivery.kind == "formation":
                    flags[delivery.receiver_id].append(FormationFlag.from_values(delivery.values))

            for fish in flags:
                base.subscribe(KEYS.inbox(fish), take)
            await until(
                lambda: any(map(by_light, flags[2])) and any(map(flashing, robots)),
                timeout=90,
            )

    run_trio(main, timeout=150)
    flag = next(flag for flag in flags[2] if by_light(flag))
    assert flag.joined and flag.hops == NO_HOPS and flag.shape == FORMATION_SHAPES.index("pyramid")
    to_robots = flags[0] + flags[1]
    assert to_robots and not any(map(by_light, to_robots))


@asynccontextmanager
async def two_formation_robots(endpoint: str) -> AsyncIterator[tuple[list[Driver], Bus]]:
    """Mock robots 0 and 1 in a formation on ``endpoint``, and a Bus of the base station's
    on it; the robots stop when the block ends."""
    async with trio.open_nursery() as nursery:
        robots: list[Driver] = [
            await nursery.start(run_robot, settings(robot_id, endpoint, "formation"))
            for robot_id in (0, 1)
        ]
        async with open_client_bus(endpoint, 5.0) as base:
            yield robots, base
        nursery.cancel_scope.cancel()


def flashing(driver: Driver) -> bool:
    leds = driver.hardware.leds
    assert isinstance(leds, GpioLeds)
    return leds.flash_frequency > 0


def fishswarm(*words: str) -> subprocess.Popen[str]:
    """A ``fishswarm`` command in its own process, its errors kept."""
    return subprocess.Popen(
        [sys.executable, "-m", "fishswarm", *words],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
