"""Decoding received payloads: bad ones are rejected, counted and logged once per sender."""

from __future__ import annotations

import logging
from collections import Counter
from typing import TypeVar

from fishswarm.protocols.codec import MessageError, decode
from fishswarm.protocols.messages import Message

M = TypeVar("M", bound=Message)

LOGGED_SENDERS = 64
"""Most (sender key, kind) pairs an actor logs a rejection for: a sender choosing new keys
(any fish id on a wildcard subscription) must not grow the memory or the log without end.
Past it, rejections are counted only, and the log says so once per kind."""

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
        self._silenced: set[str] = set()

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
            self.refuse(key, "misaddressed", f"{field} {getattr(message, field)}, key of {owner}")
            return None
        return message

    def refuse(self, key: str, kind: str, reason: str) -> None:
        """Reject a message that decoded (a valid message, but stale, misaddressed, one too
        many): it no longer counts as accepted."""
        self.accepted -= 1
        self.reject(key, kind, reason)

    def disregard(self) -> None:
        """Let go a message that decoded but is not this actor's to take (another run's
        traffic on a key it shares): neither accepted nor rejected, and not logged."""
        self.accepted -= 1

    def reject(self, key: str, kind: str, reason: str) -> None:
        """Count a rejected message; log the first of each (sender key, kind), for up to
        :data:`LOGGED_SENDERS` of them."""
        self.rejected[kind] += 1
        if (key, kind) in self._logged:
            return
        if len(self._logged) < LOGGED_SENDERS:
            self._logged.add((key, kind))
            log.warning(
                "%s rejected %s %s message on %s: %s", self.actor, _article(kind), kind, key, reason
            )
        elif kind not in self._silenced:
            self._silenced.add(kind)
            log.warning(
                "%s rejected %s %s message on %s: %s; %s senders have been named, further %s "
                "rejections are counted, not logged",
                self.actor, _article(kind), kind, key, reason, LOGGED_SENDERS, kind,
            )  # fmt: skip

    @property
    def rejected_total(self) -> int:
        """How many messages were rejected, of any kind."""
        return sum(self.rejected.values())


def _article(word: str) -> str:
    """``a`` or ``an`` before ``word`` (the kinds of rejection are plain English words)."""
    return "an" if word[:1] in "aeiou" else "a"
