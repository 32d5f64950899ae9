"""A mock robot in its own network namespace, linked to the base station by a veth pair: cut
the link and its fins stop within two seconds (its camera images come over that link); bring
it back and the robot swims in the swarm again."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import trio

pytest.importorskip("gpiozero.pins.mock")

from fishswarm.protocols.codec import decode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import RobotStatus
from tests.conftest import end_processes, free_port, open_client_bus, run_trio, subscription

pytestmark = [
    pytest.mark.integration,
    pytest.mark.skipif(
        os.geteuid() != 0 or shutil.which("ip") is None,
        reason="network namespaces need root and iproute2",
    ),
]

ROBOT = 20


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, timeout=10)


@dataclass
class Link:
    """A namespace for the robot and a veth pair to it: base end in this namespace."""

    namespace: str
    base_end: str
    base_address: str
    robot_address: str

    def set(self, up: bool) -> None:
        ip("link", "set", self.base_end, "up" if up else "down")


@pytest.fixture
def link() -> Iterator[Link]:
    tag = f"{os.getpid() % 100_000}"
    subnet = 10 + os.getpid() % 200
    made = Link(f"fsrobot{tag}", f"fsb{tag}", f"10.213.{subnet}.1", f"10.213.{subnet}.2")
    robot_end = f"fsr{tag}"
    ip("netns", "add", made.namespace)
    try:
        ip("link", "add", made.base_end, "type", "veth", "peer", "name", robot_end)
        ip("link", "set", robot_end, "netns", made.namespace)
        ip("addr", "add", f"{made.base_address}/24", "dev", made.base_end)
        ip("link", "set", made.base_end, "up")
        inside = ["netns", "exec", made.namespace, "ip"]
        ip(*inside, "addr", "add", f"{made.robot_address}/24", "dev", robot_end)
        ip(*inside, "link", "set", robot_end, "up")
        ip(*inside, "link", "set", "lo", "up")
        yield made
    finally:
        subprocess.run(["ip", "link", "del", made.base_end], capture_output=True, timeout=10)
        subprocess.run(["ip", "netns", "del", made.namespace], capture_output=True, timeout=10)


@dataclass
class Lines:
    """A process's stderr lines with the time each arrived."""

    lines: list[tuple[float, str]] = field(default_factory=list)

    def follow(self, process: subprocess.Popen[str]) -> None:
        assert process.stderr is not None
        for line in process.stderr:
            self.lines.append((time.monotonic(), line.rstrip()))

    def first_after(self, start: float, text: str) -> float | None:
        return next((t - start for t, line in self.lines if t >= start and text in line), None)


@pytest.mark.slow
def test_a_robot_whose_link_is_cut_stops_its_fins_and_rejoins_when_it_returns(
    tmp_path: Path, link: Link
) -> None:
    port = free_port()
    endpoint = f"tcp/{link.base_address}:{port}"
    processes: list[subprocess.Popen[str]] = []
    robot_log = Lines()
    try:
        world = subprocess.Popen(
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
                "0.2",
                "--duration",
                "90",
                "--quiet",
                "--listen",
                endpoint,
                "--record",
                str(tmp_path / "run.mcap"),
                "--summary",
                str(tmp_path / "run.json"),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        processes.append(world)
        time.sleep(1.0)
        robot = subprocess.Popen(
            [
                "ip",
                "netns",
                "exec",
                link.namespace,
                sys.executable,
                "-m",
                "fishswarm",
                "--log-level",
                "WARNING",
                "robot",
                "--id",
                str(ROBOT),
                "--hardware",
                "mock",
                "--period",
                "0.2",
                "--connect",
                endpoint,
                "--connect-timeout",
                "20",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        processes.append(robot)
        threading.Thread(target=robot_log.follow, args=(robot,), daemon=True).start()
        cut: dict[str, float] = {}

        async def wait_swimming(statuses: object) -> RobotStatus:
            with trio.fail_after(30):
                while True:
                    _, payload = await statuses.receive()  # type: ignore[attr-defined]
                    status = decode(payload, RobotStatus)
                    if status.state == "swimming" and status.link and status.fin_frequencies.any():
                        return status

        async def main() -> RobotStatus:
            async with (
                open_client_bus(endpoint, 10.0) as base,
                subscription(base, KeySpace().robot_status(ROBOT)) as statuses,
            ):
                await wait_swimming(statuses)
                cut["at"] = time.monotonic()
                link.set(False)
                with trio.fail_after(10):
                    while robot_log.first_after(cut["at"], "fins off") is None:
                        await trio.sleep(0.05)
                await trio.sleep(1.0)
                link.set(True)
                statuses.drain()
                back = await wait_swimming(statuses)
                return back

        back = run_trio(main, timeout=90)
        fins_off = robot_log.first_after(cut["at"], "fins off")
        assert fins_off is not None and fins_off <= 2.0, robot_log.lines
        assert back.failsafe_stops >= 1
    finally:
        end_processes(processes, timeout=15)
