"""What runs on a robot — the fish actor, the fish core and its behaviours, the Bus, the
wire, the hardware ports and drivers — imports nothing beyond numpy, trio, msgpack and
eclipse-zenoh, plus gpiozero and smbus2 for the hardware (DESIGN §7: a Pi Zero W cannot
pip-install scipy)."""

from __future__ import annotations

import subprocess
import sys

from tests.conftest import free_port
from tests.test_architecture import _imports, _modules

ROBOT_MODULES = (
    "fishswarm.actors.fish",
    "fishswarm.actors.bus",
    "fishswarm.actors.zenoh_bus",
    "fishswarm.actors.session",
    "fishswarm.behaviors.registry",
    "fishswarm.protocols.codec",
    "fishswarm.bluebot.ports",
    "fishswarm.bluebot.gpio",
    "fishswarm.bluebot.pressure",
    "fishswarm.bluebot.picamera",
    "fishswarm.bluebot.leds",
    "fishswarm.bluebot.blobs",
    "fishswarm.actors.driver",
)
# picamera2 and lgpio are Raspberry Pi OS's own packages (the venv sees them), imported when
# the cameras are opened.
ALLOWED = {"numpy", "trio", "msgpack", "zenoh", "gpiozero", "smbus2", "picamera2", "lgpio"}
BLOCKED = ("scipy", "mcap", "matplotlib", "cma", "imageio_ffmpeg")


def _closure() -> tuple[set[str], set[str]]:
    """The fishswarm modules the robot's modules import, lazily or not, and the other
    top-level packages those import."""
    modules = _modules()
    seen: set[str] = set()
    external: set[str] = set()
    todo = list(ROBOT_MODULES)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for target in _imports(modules[name]):
            if target in modules:
                todo.append(target)
            elif not target.startswith("fishswarm"):
                external.add(target.split(".")[0])
    return seen, external - set(sys.stdlib_module_names)


def test_the_robots_import_closure_holds_only_the_robots_packages() -> None:
    inside, external = _closure()
    assert "fishswarm.actors.fish" in inside and "fishswarm.behaviors.replica" in inside
    assert not any(m.startswith(("fishswarm.sim", "fishswarm.study")) for m in inside)
    assert external == ALLOWED


def test_the_robots_modules_import_with_the_base_station_packages_blocked() -> None:
    program = (
        "import sys\n"
        f"for name in {BLOCKED!r}:\n"
        "    sys.modules[name] = None\n"
        f"for module in {ROBOT_MODULES!r}:\n"
        "    __import__(module)\n"
        "from fishswarm.behaviors.registry import BEHAVIORS\n"
        "print(','.join(BEHAVIORS))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "dispersion,aggregation,orbit,milling,waltz,replica,formation"


DRIVE = """
import sys
for name in BLOCKED:
    sys.modules[name] = None
import numpy as np
import trio
from gpiozero.pins.mock import MockFactory
from fishswarm.actors.bus import MemoryBus
from fishswarm.actors.driver import Driver, DriverSettings, Hardware
from fishswarm.actors.fish import Fish, FishSettings
from fishswarm.behaviors.registry import fish_params
from fishswarm.bluebot.gpio import GpioFins, GpioLeds

frame = np.zeros((192, 256, 3), dtype=np.uint8)
frame[100:102, 60:62, 2] = 250   # a robot's two LEDs, one above the other, seen on the left
frame[90:92, 60:62, 2] = 250

class Camera:
    def capture(self, side):
        return frame if side == "left" else np.zeros_like(frame)
    def close(self):
        pass

class Depth:
    def read_depth(self):
        return 0.4
    def close(self):
        pass

async def main():
    factory = MockFactory()
    fins, leds = GpioFins(pin_factory=factory), GpioLeds(pin_factory=factory)
    hardware = Hardware(fins, leds, Camera(), Depth())
    settings = DriverSettings(5, "dispersion", control_period=0.2)
    driver = Driver(settings, hardware, link_up=lambda: True)
    local, remote = MemoryBus(), MemoryBus()
    async with trio.open_nursery() as nursery:
        params = fish_params(
            {"behavior": "dispersion", "tank": (1.78, 1.78, 1.17), "control_period": 0.2}
        )
        await nursery.start(Fish(FishSettings((5,), params)).run, local)
        await nursery.start(driver.run, local, remote)
        await trio.sleep(1.0)
        nursery.cancel_scope.cancel()
    hardware.close()
    stats = driver.statistics()
    scipy_loaded = sys.modules.get("scipy") is not None
    print(stats.perceptions, stats.commands, scipy_loaded)

trio.run(main)
"""


def test_the_driver_and_the_fish_actor_run_with_the_base_station_packages_blocked() -> None:
    program = f"BLOCKED = {BLOCKED!r}\n" + DRIVE
    result = subprocess.run(
        [sys.executable, "-c", program], capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stderr
    perceptions, commands, scipy_loaded = result.stdout.split()
    assert int(perceptions) >= 4 and int(commands) >= 4 and scipy_loaded == "False"


COMMANDS = """
import sys
for name in BLOCKED:
    sys.modules[name] = None
from fishswarm.cli import main
codes = []
for argv in ARGVS:
    try:
        codes.append(main(argv))
    except SystemExit as exit:
        codes.append(exit.code)
print(*codes)
"""


def test_the_robots_commands_run_with_the_base_station_packages_blocked() -> None:
    # What a robot's service runs, on a machine that is not a BlueBot (so its hardware cannot
    # be opened) and with no router listening: each must end in a message, not in an
    # ImportError of a base-station package.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    argvs = [
        ["robot", "--help"],
        ["robot", "--id", "3", "--hardware", "bluebot", "--connect", endpoint],
        ["robot", "--id", "3", "--hardware", "mock", "--connect", endpoint,
         "--connect-timeout", "0.5"],
        ["robots", "--connect", endpoint, "--connect-timeout", "0.5"],
    ]  # fmt: skip
    program = f"BLOCKED = {BLOCKED!r}\nARGVS = {argvs!r}\n" + COMMANDS
    result = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", program],
        capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout.split()[-4:] == ["0", "1", "1", "1"]
    assert "cannot open the BlueBot's hardware" in result.stderr
    assert result.stderr.count("cannot open a client session") == 2
    assert "Traceback" not in result.stderr
