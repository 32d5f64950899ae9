"""Robot pieces that need no router: the base station's view of the fleet on the in-memory
Bus with trio's MockClock (which robots are alive, what they last said, which did not obey an
operator's order), and what a robot's fish actor is told."""

from __future__ import annotations

import numpy as np
import trio

from fishswarm.actors.bus import MemoryBus
from fishswarm.actors.driver import DriverSettings
from fishswarm.actors.robot import FleetEntry, RobotSettings, survey_fleet, unconfirmed
from fishswarm.protocols.codec import encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import RobotOrder, RobotStatus
from fishswarm.sim.scenario import Scenario
from tests.conftest import run_mock

KEYS = KeySpace()


def status(robot_id: int, state: str = "swimming", uptime: float = 9.0) -> RobotStatus:
    return RobotStatus(robot_id, "1.0", "dispersion", state, 0.3, np.zeros(4), True, None, uptime)


def test_a_survey_hears_statuses_and_tokens_and_a_token_gone_is_not_alive() -> None:
    """Robot 1 holds its token and reports at 0.5 s; robot 2's token comes and goes during
    the 2-s survey; robot 3 reports without a token; a robot token with no id is ignored."""

    async def main() -> list[FleetEntry]:
        bus = MemoryBus()
        held = bus.declare_token(KEYS.alive("robot", 1))
        odd = bus.declare_token(KEYS.alive("robot", "spare"))
        async with trio.open_nursery() as nursery:

            async def robots() -> None:
                await trio.sleep(0.5)
                bus.put(KEYS.robot_status(1), encode(status(1)))
                bus.put(KEYS.robot_status(3), encode(status(3, "failsafe")))
                bus.put(KEYS.robot_status(4), b"not a status")
                coming = bus.declare_token(KEYS.alive("robot", 2))
                await trio.sleep(0.5)
                coming.undeclare()

            nursery.start_soon(robots)
            fleet = await survey_fleet(bus, KEYS, listen=2.0)
        held.undeclare()
        odd.undeclare()
        return fleet

    fleet = run_mock(main)
    assert [(e.robot_id, e.alive, e.last_seen) for e in fleet] == [
        (1, True, 1.5),
        (3, False, 1.5),
    ]
    assert fleet[0].status == status(1) and fleet[1].status == status(3, "failsafe")


def test_a_survey_tells_two_drivers_of_one_robot_id_apart_by_when_they_started() -> None:
    """Robot 5's driver reports every 0.5 s, up since 9 s before the survey; a second
    process given id 5 reports too, up 3 s. Robot 6's one driver reports four times, and
    one of its statuses comes 1.5 s late (Wi-Fi): no second driver."""

    async def main() -> list[FleetEntry]:
        bus = MemoryBus()
        async with trio.open_nursery() as nursery:

            async def robots() -> None:
                for step in range(4):
                    at = 0.5 * step
                    await trio.sleep_until(at)
                    bus.put(KEYS.robot_status(5), encode(status(5, uptime=9.0 + at)))
                    bus.put(KEYS.robot_status(6), encode(status(6, uptime=20.0 + at)))
                    await trio.sleep(0.01)
                    bus.put(KEYS.robot_status(5), encode(status(5, uptime=3.01 + at)))
                    if step == 2:
                        late = status(6, uptime=20.0 + at - 1.5)
                        bus.put(KEYS.robot_status(6), encode(late))

            nursery.start_soon(robots)
            fleet = await survey_fleet(bus, KEYS, listen=2.0)
        return fleet

    fleet = run_mock(main)
    assert [(e.robot_id, e.drivers) for e in fleet] == [(5, 2), (6, 1)]


def test_an_order_is_unconfirmed_for_robots_not_heard_from_or_not_obeying() -> None:
    fleet = [
        FleetEntry(1, status(1, "stopped"), True, 0.2),
        FleetEntry(2, status(2, "swimming"), True, 0.2),
        FleetEntry(3, None, True, None),  # alive, no status yet
    ]
    stop_some = RobotOrder("stop", np.array([1, 2, 3, 4]))
    assert unconfirmed(fleet, stop_some) == {
        2: "still swimming",
        3: "not heard from",
        4: "not heard from",
    }
    # An order to every robot is checked against those heard from.
    assert unconfirmed(fleet, RobotOrder("stop", np.array([], dtype=np.int64))) == {
        2: "still swimming",
        3: "not heard from",
    }
    assert unconfirmed(fleet, RobotOrder("resume", np.array([], dtype=np.int64))) == {
        1: "still stopped",
        3: "not heard from",
    }


def test_a_robots_fish_actor_serves_its_one_fish_with_the_robots_timeout() -> None:
    keys = KeySpace("tank2")
    params = Scenario(behavior="aggregation").fish_params()
    robot = RobotSettings(
        DriverSettings(7, "aggregation", keys), params, "tcp/127.0.0.1:7447",
        perception_timeout=1.5,
    )  # fmt: skip
    fish = robot.fish_settings()
    assert fish.fish_ids == (7,) and fish.params is params and fish.keys == keys
    assert fish.perception_timeout == 1.5 and fish.school is None


def test_a_formation_order_is_confirmed_by_robots_whose_fish_name_its_shape() -> None:
    """Robot 1 names the shape; robot 2 still names its own (it missed the order); robot 3's
    fish run dispersion, which has no formation to take."""

    def formation_status(robot_id: int, behavior: str, shape: str | None) -> RobotStatus:
        return RobotStatus(
            robot_id, "1.0", behavior, "swimming", 0.3, np.zeros(4), True, None, 9.0,
            formation=shape,
        )  # fmt: skip

    fleet = [
        FleetEntry(1, formation_status(1, "formation", "column"), True, 0.2),
        FleetEntry(2, formation_status(2, "formation", None), True, 0.2),
        FleetEntry(3, formation_status(3, "dispersion", None), True, 0.2),
    ]
    order = RobotOrder("formation", np.array([], dtype=np.int64), "column")
    assert unconfirmed(fleet, order) == {
        2: "its fish take their own",
        3: "its fish run dispersion, not a formation",
    }
    again = RobotOrder("formation", np.array([], dtype=np.int64), "diamond")
    assert unconfirmed(fleet[:1], again) == {1: "its fish take column"}
