"""The world's queryables over Zenoh: ``world/control``, which anyone allowed (an operator, a
test, another program) asks for status, pause, resume, stop or a new formation, and
``world/scenario``, which tells observers the run's settings (JSON).

Zenoh-only (the Bus has no queries): the launcher and ``fishswarm world`` serve them beside
the world. A request that is not a control request is rejected and counted by the world.
"""

from __future__ import annotations

import json

import trio
import zenoh

from fishswarm.actors.world import World
from fishswarm.actors.zenoh_bus import open_queryable, query, reply
from fishswarm.protocols.keys import KeySpace
from fishswarm.sim.scenario import ConfigError, Scenario


async def run_control(
    session: zenoh.Session,
    world: World,
    *,
    task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
) -> None:
    """Answer the world's control and scenario queries until cancelled."""
    settings = json.dumps(world.scenario.to_dict()).encode()
    async with (
        open_queryable(session, world.keys.control) as queries,
        open_queryable(session, world.keys.scenario) as asked,
        trio.open_nursery() as nursery,
    ):

        async def tell_the_scenario() -> None:
            async for request in asked:
                reply(request, settings)

        nursery.start_soon(tell_the_scenario)
        task_status.started()
        async for request in queries:
            payload = b"" if request.payload is None else request.payload.to_bytes()
            answer = world.control_payload(str(request.key_expr), payload)
            if answer is None:
                request.drop()
            else:
                reply(request, answer)
        nursery.cancel_scope.cancel()


async def ask_scenario(
    session: zenoh.Session, keys: KeySpace, *, timeout: float = 5.0
) -> Scenario | None:
    """The settings of the swarm's run, as its world tells them (None if no world answers
    within ``timeout`` seconds).

    Raises:
        ConfigError: the answer is not a scenario.
    """
    answers = await query(session, keys.scenario, b"", timeout=timeout)
    if not answers:
        return None
    try:
        settings = json.loads(answers[0])
    except ValueError as error:
        raise ConfigError(f"the world's scenario is not JSON: {error}") from None
    if not isinstance(settings, dict):
        raise ConfigError(f"the world's scenario is not a table: {answers[0][:80]!r}")
    return Scenario.as_recorded(settings, source="the world's scenario")
