"""The fishswarm key space: every Zenoh key expression, spelled once.

All keys live under ``fishswarm/<swarm>/`` so that several swarms can share one router.
Each key carries exactly one message type (see :mod:`fishswarm.protocols.messages`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "fishswarm"
_NAME = re.compile(r"[A-Za-z0-9_\-]{1,64}")
_FISH_ID = re.compile(r"[0-9]{1,18}")
_PLACE = re.compile(r"([0-9]{1,20})-([0-9]{1,20})")
MAX_FISH_ID = 10**18 - 1
"""The largest fish id a key may name (ids fit in every message's integer fields)."""


def fish_id_of(text: str) -> int | None:
    """The fish id a key chunk names (ASCII digits, at most 18), or None if it names none."""
    return int(text) if _FISH_ID.fullmatch(text) else None


def run_id_of(text: str) -> int | None:
    """The run a world's liveliness token id names (ASCII digits), or None if it names none."""
    return int(text) if text.isascii() and text.isdigit() else None


def check_name(kind: str, value: str) -> str:
    """``value``, a name that may stand in a key (a swarm's, a school's, an observer's).

    Raises:
        ValueError: it is empty, longer than 64 characters, or not letters, digits, '-'
            and '_' only.
    """
    if not _NAME.fullmatch(value):
        raise ValueError(
            f"{kind} name {value!r} is not valid: use 1 to 64 letters, digits, '-' and '_'"
        )
    return value


@dataclass(frozen=True)
class Member:
    """A member of the swarm as its liveliness token names it.

    Attributes:
        role: fish, world, channel or observer; or ``queue`` for a world waiting for its
            turn (see :meth:`KeySpace.queue_place`).
        member_id: its id within the role.
        school: the school whose keys serve it (fish only), or None for its own keys.
    """

    role: str
    member_id: str
    school: str | None = None


@dataclass(frozen=True)
class KeySpace:
    """The key expressions of one swarm.

    Args:
        swarm: name of the swarm; several swarms can share one router.
    """

    swarm: str = "default"

    def __post_init__(self) -> None:
        check_name("swarm", self.swarm)

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

    def school_perceptions(self, school: str) -> str:
        """World → school: the perceptions of all the school's fish at a tick, as arrays.

        A school is a group of fish served by one actor (a worker process). It carries one
        message per tick each way instead of one per fish; robots keep the per-fish keys.
        """
        return f"{self.prefix}/school/{check_name('school', school)}/perceptions"

    def school_commands(self, school: str) -> str:
        """School → world: the commands of all the school's fish for a tick."""
        return f"{self.prefix}/school/{check_name('school', school)}/commands"

    @property
    def snapshot(self) -> str:
        """World → channel, observers: every fish's pose and velocity at a tick."""
        return f"{self.prefix}/world/snapshot"

    @property
    def control(self) -> str:
        """Queryable of the world: status, pause, resume, stop."""
        return f"{self.prefix}/world/control"

    @property
    def scenario(self) -> str:
        """Queryable of the world: the run's settings, as JSON (what an observer needs to
        draw the tank and measure the formation)."""
        return f"{self.prefix}/world/scenario"

    @property
    def world_pulse(self) -> str:
        """World → fish: the world is alive and the run goes on (:class:`WorldPulse`)."""
        return f"{self.prefix}/world/pulse"

    @property
    def channel_report(self) -> str:
        """Channel → world: how many broadcasts each fish will find in its inbox at a tick."""
        return f"{self.prefix}/channel/report"

    def about(self, fish_id: int | str, school: str | None = None) -> str:
        """Fish actor → world: what its fish run (:class:`FishAbout`), on the fish's own key
        or its school's."""
        if school is not None:
            return f"{self.prefix}/school/{check_name('school', school)}/about"
        return f"{self.prefix}/fish/{fish_id}/about"

    def abouts(self) -> tuple[str, str]:
        """Key expressions matching every fish's and every school's ``about`` key."""
        return self.about("*"), self.every_school("about")

    def robot_status(self, robot_id: int | str) -> str:
        """Robot driver → base station: the robot's :class:`RobotStatus`."""
        return f"{self.prefix}/robot/{robot_id}/status"

    def robot_statuses(self) -> str:
        """Key expression matching every robot's status key."""
        return self.robot_status("*")

    @property
    def robot_order(self) -> str:
        """Operator → every robot's driver: stop or resume."""
        return f"{self.prefix}/robots/order"

    def alive(self, role: str, member_id: int | str, school: str | None = None) -> str:
        """Liveliness token of one member (``role`` is fish, world, channel or observer).

        A fish served through a school's keys says so in its token:
        ``alive/fish/<id>/<school>``; a fish on its own keys has ``alive/fish/<id>``.
        """
        check_name("role", role)
        token = f"{self.prefix}/alive/{role}/{member_id}"
        return token if school is None else f"{token}/{check_name('school', school)}"

    def queue_place(self, arrived: int, run_id: int) -> str:
        """Liveliness token of a world waiting for its turn: ``alive/queue/<arrived>-<run>``.

        Worlds of a swarm run one at a time, in the order of their places: when they
        arrived (µs since the epoch, on the world's own clock), ties broken by run id.
        """
        return self.alive("queue", f"{arrived}-{run_id}")

    @staticmethod
    def place_of(member_id: str) -> tuple[int, int] | None:
        """The place (arrival µs, run id) a queue token's id names, or None if it names none."""
        match = _PLACE.fullmatch(member_id)
        return None if match is None else (int(match[1]), int(match[2]))

    def alive_all(self, role: str = "*") -> str:
        """Key expression matching the liveliness tokens of every member of ``role``."""
        return f"{self.prefix}/alive/{role}/**"

    def parse_alive(self, key: str) -> Member:
        """Who a liveliness token stands for.

        Raises:
            ValueError: the key is not a liveliness token of this swarm.
        """
        parts = key.split("/")
        if len(parts) in (5, 6) and "/".join(parts[:2]) == self.prefix and parts[2] == "alive":
            return Member(parts[3], parts[4], parts[5] if len(parts) == 6 else None)
        raise ValueError(f"{key!r} is not a liveliness token of swarm {self.swarm!r}")

    def robot_of(self, key: str) -> int | None:
        """The robot a liveliness token stands for (its driver's ``alive/robot/<id>``), or
        None for any other token, or one that names no robot id."""
        try:
            member = self.parse_alive(key)
        except ValueError:
            return None
        return fish_id_of(member.member_id) if member.role == "robot" else None

    def every_school(self, kind: str) -> str:
        """Key expression matching one kind of school key (``perceptions``, ``commands``,
        ``about``) of every school."""
        return f"{self.prefix}/school/*/{check_name('kind', kind)}"

    def fish_outboxes(self) -> str:
        """Key expression matching every fish's outbox key."""
        return self.outbox("*")

    def fish_inboxes(self) -> str:
        """Key expression matching every fish's inbox key."""
        return self.inbox("*")

    def school_of_key(self, key: str) -> str | None:
        """The school a ``school/<name>/<kind>`` key of this swarm names (None for others)."""
        parts = key.split("/")
        if len(parts) == 5 and "/".join(parts[:2]) == self.prefix and parts[2] == "school":
            return parts[3]
        return None

    def member_of(self, key: str) -> tuple[str, str]:
        """Split a per-member key: ``.../fish/3/command`` → ("3", "command").

        Works for ``fish/<id>/<kind>`` keys; for liveliness tokens see :meth:`parse_alive`.

        Raises:
            ValueError: the key is not a per-member key of this swarm.
        """
        parts = key.split("/")
        if len(parts) == 5 and "/".join(parts[:2]) == self.prefix and parts[2] == "fish":
            return parts[3], parts[4]
        raise ValueError(f"{key!r} is not a per-member key of swarm {self.swarm!r}")
