"""Decoding received payloads: bad ones are rejected, counted and logged once per sender."""

from __future__ import annotations

import logging
from collections import Counter
from typing import TypeVar

from fishswarm.protocols.codec import MessageError, decode
from fishswarm.protocols.messages import Message

M = TypeVar("M", bound=Message)

log = logging.getLogger(__name__)


class Intake:
    """Decodes payloads for one actor and keeps count of what it had to reject.

    Args:
        actor: the actor's name, for the log.
    """

    def __init__(self, actor: str) -> None:
        self.actor = actor
        self.accepted = 0
        self.rejected: Counter[str] = Counter()
        self._logged: set[tuple[str, str]] = set()

    def decode(self, key: str, payload: bytes, expected: type[M]) -> M | None:
        """The message, or None (counted and logged) if the payload is not a valid one."""
        try:
            message = decode(payload, expected)
        except MessageError as error:
            self.reject(key, "malformed", str(error))
            return None
        self.accepted += 1
        return message

    def decode_addressed(
        self, key: str, payload: bytes, expected: type[M], *, field: str, owner: int
    ) -> M | None:
        """Decode a message that must name ``owner`` in ``field`` (the fish its key is about).

        A valid message about another fish is rejected as misaddressed.
        """
        message = self.decode(key, payload, expected)
        if message is not None and getattr(message, field) != owner:
            self.accepted -= 1
            self.reject(key, "misaddressed", f"{field} {getattr(message, field)}, key of {owner}")
            return None
        return message

    def reject(self, key: str, kind: str, reason: str) -> None:
        """Count a rejected message; log the first of each (sender key, kind)."""
        self.rejected[kind] += 1
        if (key, kind) not in self._logged:
            self._logged.add((key, kind))
            log.warning("%s rejected a %s message on %s: %s", self.actor, kind, key, reason)

    @property
    def rejected_total(self) -> int:
        """How many messages were rejected, of any kind."""
        return sum(self.rejected.values())
