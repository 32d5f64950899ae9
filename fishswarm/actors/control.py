"""The world's queryables over Zenoh: ``world/control``, which anyone allowed (an operator, a
test, another program) asks for status, pause, resume, stop or a new formation, and
``world/scenario``, which tells observers the run's settings (a :class:`RunSettings`).

Zenoh-only (the Bus has no queries): the launcher and ``fishswarm world`` serve them beside
the world. A request that is not a control request is rejected and counted by the world.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import trio
import zenoh

from fishswarm import __version__
from fishswarm.actors.world import World
from fishswarm.actors.zenoh_bus import open_queryable, query, reply
from fishswarm.behaviors.registry import names as behavior_names
from fishswarm.protocols.codec import MessageError, decode, encode
from fishswarm.protocols.keys import KeySpace
from fishswarm.protocols.messages import RunSettings
from fishswarm.sim.scenario import ConfigError, Scenario


async def run_control(
    session: zenoh.Session,
    world: World,
    *,
    task_status: trio.TaskStatus[None] = trio.TASK_STATUS_IGNORED,
) -> None:
    """Answer the world's control and scenario queries until cancelled."""
    settings = encode(RunSettings(world.scenario.to_dict()))

    # Whether the world was waiting its turn when a query came, not when trio takes it in:
    # a stop for the world that runs ends it, and this one may take its turn meanwhile.
    def answering() -> bool:
        return world.answering

    async with (
        open_queryable(session, world.keys.control, answering) as queries,
        open_queryable(session, world.keys.scenario, answering) as asked,
        trio.open_nursery() as nursery,
    ):

        async def tell_the_scenario() -> None:
            async for request, answers in asked:
                if not answers:
                    request.drop()  # the world that runs now answers
                else:
                    reply(request, settings)

        nursery.start_soon(tell_the_scenario)
        task_status.started()
        async for request, answers in queries:
            if not answers:
                # An operator's pause or stop is for the world that runs now: a world that
                # waits its turn answers nothing (Ctrl-C where it was started ends it).
                request.drop()
                continue
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
        ConfigError: the answer is not the settings of a run this fishswarm can read (not
            a :class:`RunSettings`, another schema version, or settings it does not know).
    """
    answers = await query(session, keys.scenario, b"", timeout=timeout)
    if not answers:
        return None
    try:
        settings = decode(answers[0], RunSettings)
    except MessageError as error:
        raise ConfigError(
            f"the world's answer on {keys.scenario} is no run settings: {error} (does the "
            f"world run this version of fishswarm, {__version__}?)"
        ) from None
    behavior = settings.scenario.get("behavior")
    if isinstance(behavior, str) and behavior not in behavior_names():
        raise UnreadableSettings(
            f"the world's run has the behaviour {behavior!r}, which is not installed here: "
            "another package's (docs/behaviors.md)? Install it beside fishswarm to measure "
            "the run as its world does",
            settings.scenario,
        )
    try:
        return Scenario.as_recorded(settings.scenario, source="the world's scenario")
    except ConfigError as error:
        raise UnreadableSettings(str(error), settings.scenario) from None


class UnreadableSettings(ConfigError):
    """A world told its run's settings, and they are not a scenario this fishswarm can run
    (a behaviour not installed here, a setting of a later version): said, with the settings
    as the world told them, which a recording can still hold."""

    def __init__(self, message: str, settings: dict[str, Any]) -> None:
        super().__init__(message)
        self.settings = settings


ASK_TIMEOUT = 2.0
"""How long :func:`wait_for_scenario` waits for each of the world's answers, s."""
ASK_EVERY = 0.2
"""How long :func:`wait_for_scenario` waits before asking again when no world answered, s
(a query no queryable matches comes back at once: asking often costs the router little)."""


async def wait_for_scenario(
    session: zenoh.Session, keys: KeySpace, *, on_waiting: Callable[[], None] | None = None
) -> Scenario:
    """The settings of the swarm's run, asking until its world answers; ``on_waiting`` is
    called once if the first question goes unanswered (to say so).

    Raises:
        ConfigError: as :func:`ask_scenario`.
    """
    while True:
        ran = await ask_scenario(session, keys, timeout=ASK_TIMEOUT)
        if ran is not None:
            return ran
        if on_waiting is not None:
            on_waiting()
            on_waiting = None
        await trio.sleep(ASK_EVERY)
