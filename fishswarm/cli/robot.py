"""The ``robot`` and ``robots`` commands: a robot's driver and fish actor; the fleet."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import trio

from fishswarm.actors.driver import DriverSettings
from fishswarm.actors.robot import (
    FleetEntry,
    RobotSettings,
    order_fleet,
    run_robot,
    survey_fleet,
    unconfirmed,
)
from fishswarm.actors.security import SecurityError, robot_subject
from fishswarm.actors.session import ConnectError, SessionSettings, open_session
from fishswarm.actors.zenoh_bus import ZenohBus
from fishswarm.cli.common import UserError, client_settings, endpoint_of, run_trio, secure_extra
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import RobotOrder
from fishswarm.sim.scenario import ConfigError, Scenario


def robot(args: argparse.Namespace, scenario: Scenario) -> int:
    """``fishswarm robot``: the driver and the fish actor of one robot."""
    try:
        settings = RobotSettings(
            DriverSettings(
                args.robot_id,
                scenario.behavior,
                scenario.keys,
                control_period=scenario.control_period,
                command_timeout=(
                    args.command_timeout
                    if args.command_timeout is not None
                    else max(1.0, 2.5 * scenario.control_period)
                ),
                link_timeout=args.link_timeout,
            ),
            scenario.fish_params(),
            endpoint_of(args.connect, "--connect"),
            hardware=args.hardware,
            connect_timeout=args.connect_timeout,
            perception_timeout=args.perception_timeout,
            seed=scenario.seed,
            zenoh_config=_zenoh_config(args.zenoh_config),
            session_extra=secure_extra(
                args, robot_subject(args.robot_id), endpoint=args.connect, swarm=scenario.swarm
            ),
        )
    except ValueError as error:
        raise ConfigError(str(error)) from None
    except SecurityError as error:
        raise UserError(str(error)) from None

    async def main() -> None:
        async with trio.open_nursery() as nursery:
            await nursery.start(run_robot, settings)
            print(
                f"robot {args.robot_id} up on {args.connect} ({args.hardware} hardware, "
                f"{scenario.behavior}); Ctrl-C stops it",
                file=sys.stderr,
            )

    run_trio(main)
    return 0


def robots(args: argparse.Namespace, scenario: Scenario | None) -> int:
    """``fishswarm robots``: list the fleet, or send it an operator's order."""
    keys = KeySpace(args.swarm)
    order = ("stop", args.stop) if args.stop is not None else None
    if args.resume is not None:
        order = ("resume", args.resume)

    async def main() -> tuple[RobotOrder | None, list[FleetEntry]]:
        async with open_session(client_settings(args, "admin", swarm=keys.swarm)) as session:
            bus = ZenohBus(session)
            sent = None
            if order is not None:
                sent = order_fleet(bus, keys, order[0], order[1])
                whom = ", ".join(map(str, sent.robot_ids.tolist())) or "every robot"
                print(f"sent {order[0]} to {whom}", file=sys.stderr)
            return sent, await survey_fleet(bus, keys, listen=args.listen)

    sent, fleet = run_trio(main)
    if args.json:
        print(json.dumps([_as_dict(entry) for entry in fleet], indent=2))
    else:
        print(fleet_table(fleet))
    for entry in fleet:
        if entry.drivers > 1:
            print(
                f"warning: {entry.drivers} drivers report robot {entry.robot_id} (robots or "
                "processes started with one --id?): the line above is the last heard; give "
                "each robot its own id",
                file=sys.stderr,
            )
    if sent is None:
        return 0
    if not fleet and sent.robot_ids.size == 0:
        print(
            f"no robot was heard from, so none is known to have obeyed the {sent.action}: "
            "are they up and connected to this router? send it again once they are",
            file=sys.stderr,
        )
        return 1
    return 1 if say_unconfirmed(fleet, sent) else 0


def say_unconfirmed(fleet: list[FleetEntry], sent: RobotOrder) -> dict[int, str]:
    """Name each robot of ``fleet`` that does not report obeying ``sent``, and why; those
    robots, with why."""
    missing = unconfirmed(fleet, sent)
    restarted = "unstopped" if sent.action == "stop" else "as configured"
    known = [entry.robot_id for entry in fleet]
    heard = ", ".join(map(str, known)) if known else "none"
    for robot_id, why in missing.items():
        if why.startswith("its fish run "):
            advice = ""  # sending again cannot change the behaviour its fish run
        elif robot_id not in known:
            advice = (
                f": no robot {robot_id} is known on this router (robots heard from: {heard}); "
                "check the id, or whether it is up and connected"
            )
        else:
            advice = (
                f": a robot whose link is down never hears it, and one that restarts comes "
                f"back {restarted}; send it again"
            )
        print(f"robot {robot_id} did not confirm the {sent.action} ({why}){advice}",
              file=sys.stderr)  # fmt: skip
    return missing


def _as_dict(entry: FleetEntry) -> dict[str, object]:
    status = entry.status
    return {
        "id": entry.robot_id,
        "alive": entry.alive,
        "last_seen": entry.last_seen,
        "drivers": entry.drivers,
        "version": status.version if status else None,
        "behavior": status.behavior if status else None,
        "formation": status.formation if status else None,
        "flashing": bool(status.flashing) if status else None,
        "flags_seen": (status.flags_seen or 0) if status else None,
        "state": status.state if status else None,
        "depth": status.depth if status else None,
        "link": status.link if status else None,
        "fin_frequencies": status.fin_frequencies.tolist() if status else None,
        "cpu_temperature": status.cpu_temperature if status else None,
    }


_COLUMNS = (
    ("id", ">4"),
    ("version", "<8"),
    ("behavior", "<12"),
    ("state", "<9"),
    ("light", "<5"),
    ("depth m", ">7"),
    ("link", "<4"),
    ("fins Hz", "<19"),
    ("CPU °C", ">6"),
    ("last seen", ""),
)


def _row(cells: list[str]) -> str:
    return "  ".join(f"{cell:{spec}}" for cell, (_, spec) in zip(cells, _COLUMNS, strict=True))


def fleet_table(fleet: list[FleetEntry]) -> str:
    """The fleet as a table, one robot a line."""
    if not fleet:
        return "no robots heard from (are they up and connected to this router?)"
    lines = [_row([name for name, _ in _COLUMNS])]
    for entry in fleet:
        status = entry.status
        seen = "never" if entry.last_seen is None else f"{entry.last_seen:.1f} s ago"
        if not entry.alive:
            seen += " (gone)"
        if status is None:
            lines.append(_row([str(entry.robot_id), *["?"] * 8, seen]))
            continue
        temperature = status.cpu_temperature
        lines.append(
            _row(
                [
                    str(entry.robot_id),
                    status.version,
                    status.behavior,
                    status.state,
                    "flash" if status.flashing else "",
                    f"{status.depth:.2f}",
                    "up" if status.link else "down",
                    " ".join(f"{f:.1f}" for f in status.fin_frequencies),
                    "—" if temperature is None else f"{temperature:.0f}",
                    seen,
                ]
            )
        )
    return "\n".join(lines)


def _zenoh_config(path: Path | None) -> str | None:
    """``--zenoh-config``'s file, checked where the robot starts (its unit names it before
    the file is installed, so the parser leaves it alone).

    Raises:
        ConfigError: it does not exist, is not a file, or is not a Zenoh configuration
            (JSON5) — a bad file as a bad argument, before the robot starts.
    """
    if path is None:
        return None
    if not path.is_file():
        raise ConfigError(f"--zenoh-config {path} does not exist or is not a file")
    try:
        SessionSettings(mode="client", config_file=str(path)).to_config()
    except ConnectError as error:
        raise ConfigError(f"--zenoh-config: {error}") from None
    return str(path)
