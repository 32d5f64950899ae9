"""What runs on a robot — the fish actor, the fish core and its behaviours, the Bus, the
wire, the hardware ports and drivers — imports nothing beyond numpy, trio, msgpack and
eclipse-zenoh, plus gpiozero and smbus2 for the hardware (DESIGN §7: a Pi Zero W cannot
pip-install scipy)."""

from __future__ import annotations

import subprocess
import sys

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
)
ALLOWED = {"numpy", "trio", "msgpack", "zenoh", "gpiozero", "smbus2"}
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
