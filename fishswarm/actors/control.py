"""The world's control over Zenoh: a queryable on ``world/control`` that anyone (an operator,
a test, another program) asks for status, pause, resume or stop.

Zenoh-only (the Bus has no queries): the launcher and ``fishswarm world`` serve it beside the
world. A request that is not a control request is rejected and counted by the world.
"""

from __future__ import annotations

import trio
import zenoh

from fishswarm.actors.world import World
from fishswarm.actors.zenoh_bus import open_queryable, reply


async def serve_control(
    session: zenoh.Session,
    world: World,
    *,
    task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
) -> None:
    """Answer the world's control queries until cancelled."""
    async with open_queryable(session, world.keys.control) as queries:
        task_status.started()
        async for request in queries:
            payload = b"" if request.payload is None else request.payload.to_bytes()
            answer = world.control_payload(str(request.key_expr), payload)
            if answer is None:
                request.drop()
            else:
                reply(request, answer)
