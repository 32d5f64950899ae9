"""A behaviour for tests of the broadcast path: fish that answer what they hear.

Each fish broadcasts a ``signal`` with (how many broadcasts it heard, its decision count),
lights its LEDs only when it heard something, and swims towards the mean position of the
fish it heard (straight on when it heard nobody) — so what a fish hears changes where it
goes, and a trajectory shows whether deliveries arrived.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fishswarm.behaviors.core import Behavior, Inbox, Outbox, Perception, Steering
from fishswarm.behaviors.registry import BEHAVIORS, register
from fishswarm.protocols.messages import BROADCAST_KINDS, BROADCAST_WIDTH


@dataclass(frozen=True)
class SignalMemory:
    """How many decisions each fish has made."""

    decisions: np.ndarray


def steer_signal(
    memory: SignalMemory, perception: Perception, inbox: Inbox, *, params: None
) -> tuple[SignalMemory, Steering]:
    count = perception.count
    heard = inbox.mask.sum(axis=1)
    total = (inbox.sender * inbox.mask[..., None]).sum(axis=1)
    toward = total / np.maximum(heard, 1)[:, None]
    target = np.where((heard > 0)[:, None], toward, np.array([0.3, 0.0, 0.0]))
    values = np.zeros((count, BROADCAST_WIDTH), dtype=np.int64)
    values[:, 0] = heard
    values[:, 1] = memory.decisions
    outbox = Outbox(
        np.full(count, BROADCAST_KINDS.index("signal"), dtype=np.int64),
        values,
        np.ones(count, dtype=np.bool_),
    )
    return SignalMemory(memory.decisions + 1), Steering(target, heard > 0, outbox)


def _params(settings: Mapping[str, Any]) -> None:
    return None


def _fresh(count: int) -> SignalMemory:
    return SignalMemory(np.zeros(count, dtype=np.int64))


SIGNAL = Behavior(
    "test-signal",
    "tests only: broadcast what was heard, swim towards who was heard",
    steer_signal,
    _fresh,
    _params,
    spawn_radius=0.5,
)


def registered() -> Behavior:
    """The behaviour, registered (once) under its name."""
    if SIGNAL.name not in BEHAVIORS:
        register(SIGNAL)
    return SIGNAL


def steer_until_the_third(
    memory: SignalMemory, perception: Perception, inbox: Inbox, *, params: None
) -> tuple[SignalMemory, Steering]:
    """The signal behaviour's steering, failing at every fish's third decision."""
    if memory.decisions.max() == 3:
        raise RuntimeError("no third decision")
    return steer_signal(memory, perception, inbox, params=params)


FAILING = Behavior(
    "test-fails-at-third",
    "tests only: the signal behaviour, failing at the third decision",
    steer_until_the_third,
    _fresh,
    _params,
    spawn_radius=0.5,
)
"""A behaviour of one's own that errs, at module level so that worker processes get it."""
