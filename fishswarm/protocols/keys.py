"""The fishswarm key space: every Zenoh key expression, spelled once.

All keys live under ``fishswarm/<swarm>/`` so that several swarms can share one router.
Each key carries exactly one message type (see :mod:`fishswarm.protocols.messages`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "fishswarm"
_NAME = re.compile(r"^[A-Za-z0-9_\-]+$")


def _check_name(kind: str, value: str) -> str:
    if not _NAME.match(value):
        raise ValueError(
            f"{kind} name {value!r} is not valid: use letters, digits, '-' and '_' only"
        )
    return value


@dataclass(frozen=True)
class KeySpace:
    """The key expressions of one swarm.

    Args:
        swarm: name of the swarm; several swarms can share one router.
    """

    swarm: str = "default"

    def __post_init__(self) -> None:
        _check_name("swarm", self.swarm)

    @property
    def prefix(self) -> str:
        """``fishswarm/<swarm>``: the root of every key of this swarm."""
        return f"{ROOT}/{self.swarm}"

    def perception(self, fish_id: int | str) -> str:
        """World or driver → fish: what fish ``fish_id`` perceives at a tick."""
        return f"{self.prefix}/fish/{fish_id}/perception"

    def command(self, fish_id: int | str) -> str:
        """Fish → world or driver: fin gains and LED state for a tick."""
        return f"{self.prefix}/fish/{fish_id}/command"

    def outbox(self, fish_id: int | str) -> str:
        """Fish → channel: a broadcast such as a formation flag."""
        return f"{self.prefix}/fish/{fish_id}/outbox"

    def inbox(self, fish_id: int | str) -> str:
        """Channel → fish: a delivered broadcast, situated in the receiver's body frame."""
        return f"{self.prefix}/fish/{fish_id}/inbox"

    @property
    def snapshot(self) -> str:
        """World → channel, observers: every fish's pose and velocity at a tick."""
        return f"{self.prefix}/world/snapshot"

    @property
    def control(self) -> str:
        """Queryable of the world: status, pause, resume, stop."""
        return f"{self.prefix}/world/control"

    @property
    def channel_report(self) -> str:
        """Channel → world: how many broadcasts each fish will find in its inbox at a tick."""
        return f"{self.prefix}/channel/report"

    def alive(self, role: str, member_id: int | str) -> str:
        """Liveliness token of one member (``role`` is fish, world, channel or observer)."""
        _check_name("role", role)
        return f"{self.prefix}/alive/{role}/{member_id}"

    def alive_all(self, role: str = "*") -> str:
        """Key expression matching the liveliness tokens of every member of ``role``."""
        return f"{self.prefix}/alive/{role}/*"

    @property
    def all_fish(self) -> str:
        """Key expression matching every per-fish key."""
        return f"{self.prefix}/fish/*/*"

    def fish_commands(self) -> str:
        """Key expression matching every fish's command key."""
        return f"{self.prefix}/fish/*/command"

    def fish_outboxes(self) -> str:
        """Key expression matching every fish's outbox key."""
        return f"{self.prefix}/fish/*/outbox"

    def member_of(self, key: str) -> tuple[str, str]:
        """Split a per-member key: ``.../fish/3/command`` → ("3", "command").

        Works for ``fish/<id>/<kind>`` and ``alive/<role>/<id>`` keys (then (id, role)).

        Raises:
            ValueError: the key is not a per-member key of this swarm.
        """
        parts = key.split("/")
        if len(parts) == 5 and "/".join(parts[:2]) == self.prefix:
            if parts[2] == "fish":
                return parts[3], parts[4]
            if parts[2] == "alive":
                return parts[4], parts[3]
        raise ValueError(f"{key!r} is not a per-member key of swarm {self.swarm!r}")
