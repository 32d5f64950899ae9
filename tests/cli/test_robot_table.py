"""The fleet as ``fishswarm robots`` prints it: a table, one robot a line, and JSON; and
what it says of robots that did not confirm an order."""

from __future__ import annotations

import numpy as np
import pytest

from fishswarm.actors.robot import FleetEntry
from fishswarm.cli.robot import _as_dict, fleet_table, say_unconfirmed
from fishswarm.protocols.messages import RobotOrder, RobotStatus


def status(robot_id: int, **changes: object) -> RobotStatus:
    fields: dict[str, object] = {
        "robot_id": robot_id, "version": "1.2", "behavior": "formation", "state": "swimming",
        "depth": 0.31, "fin_frequencies": np.array([2.0, 0.0, 0.0, 10.0]), "link": True,
        "cpu_temperature": 48.4, "uptime": 30.0,
    }  # fmt: skip
    fields.update(changes)
    return RobotStatus(**fields)  # type: ignore[arg-type]


def test_the_table_lines_up_each_robots_state_light_and_fins() -> None:
    fleet = [
        FleetEntry(3, status(3, flashing=True, flags_seen=7), True, 0.2),
        FleetEntry(4, status(4, state="failsafe", link=False, cpu_temperature=None), False, 3.0),
        FleetEntry(12, None, True, None),
    ]
    lines = fleet_table(fleet).splitlines()
    header = lines[0].split()
    assert header[:5] == ["id", "version", "behavior", "state", "light"]
    assert lines[1].split() == [
        "3", "1.2", "formation", "swimming", "flash", "0.31", "up",
        "2.0", "0.0", "0.0", "10.0", "48", "0.2", "s", "ago",
    ]  # fmt: skip
    # No light: the column is blank, and every later column stays under its heading.
    assert lines[2].split()[:5] == ["4", "1.2", "formation", "failsafe", "0.31"]
    assert lines[2].index("0.31") == lines[1].index("0.31")
    assert lines[2].index("down") == lines[1].index("up")
    assert "—" in lines[2] and lines[2].endswith("3.0 s ago (gone)")
    # Alive but not heard from: a question mark under each heading but the last.
    assert lines[3].split() == ["12", *["?"] * 8, "never"]


def test_the_json_tells_whether_a_robot_flashes_and_how_many_flags_it_saw() -> None:
    flashing = _as_dict(FleetEntry(3, status(3, flashing=True, flags_seen=7), True, 0.2))
    steady = _as_dict(FleetEntry(4, status(4), True, 0.2))
    unknown = _as_dict(FleetEntry(12, None, True, None))
    assert (flashing["flashing"], flashing["flags_seen"]) == (True, 7)
    assert (steady["flashing"], steady["flags_seen"]) == (False, 0)
    assert (unknown["flashing"], unknown["flags_seen"]) == (None, None)


def test_no_robots_heard_from_says_what_to_check() -> None:
    assert fleet_table([]) == "no robots heard from (are they up and connected to this router?)"


def test_robots_that_did_not_confirm_an_order_are_named_with_what_to_do(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """Robot 11 is up but did not stop: send it again. Robot 99 was never heard from: not a
    robot of this router, most likely a wrong id. Robot 12's fish run dispersion: a
    formation order cannot reach them, and sending again changes nothing."""
    fleet = [
        FleetEntry(10, status(10, state="stopped"), True, 0.1),
        FleetEntry(11, status(11), True, 0.1),
        FleetEntry(12, status(12, behavior="dispersion"), True, 0.1),
    ]
    stop = RobotOrder("stop", np.array([10, 11, 99]))
    assert sorted(say_unconfirmed(fleet, stop)) == [11, 99]
    said = capsys.readouterr().err.splitlines()
    assert said == [
        "robot 11 did not confirm the stop (still swimming): a robot whose link is down never "
        "hears it, and one that restarts comes back unstopped; send it again",
        "robot 99 did not confirm the stop (not heard from): no robot 99 is known on this "
        "router (robots heard from: 10, 11, 12); check the id, or whether it is up and "
        "connected",
    ]
    formation = RobotOrder("formation", np.array([12]), "column")
    assert list(say_unconfirmed(fleet, formation)) == [12]
    assert capsys.readouterr().err.strip() == (
        "robot 12 did not confirm the formation (its fish run dispersion, not a formation)"
    )
