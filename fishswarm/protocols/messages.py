"""Message types of the fishswarm wire, validated on construction.

Every message is a frozen dataclass whose ``__post_init__`` checks types, shapes, finite
numbers and sizes, so that a bad message cannot be built: the codec decodes by constructing,
and turns any complaint into :class:`~fishswarm.protocols.codec.MessageError`.

Frames and units follow SPEC.md: SI units, body frame x forward, y right, z down; the tank
frame has its origin at a corner with z down (z is depth).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fishswarm.protocols.checks import (
    MAX_ROWS,
    MAX_TICK,
    BoolArray,
    FloatArray,
    IntArray,
    check_array,
    check_counts,
    check_float,
    check_ids,
    check_int,
    check_text,
)

SCHEMA_VERSION = 1

FIN_NAMES = ("caudal", "dorsal", "pectoral_left", "pectoral_right")
"""Order of the fin gains in :attr:`Command.fins` and everywhere else."""

WORLD_STATES = ("waiting", "running", "pausing", "paused", "stopping", "finished", "stopped")
"""What a world is doing, as its control queryable answers."""
CONTROL_ACTIONS = ("status", "pause", "resume", "stop", "formation")

BROADCAST_KINDS = ("signal", "formation")
"""What a broadcast can say; a fish's decision names its broadcast by the index in this tuple.
``signal`` is a plain flag with numbers of the sender's choosing; ``formation`` a formation
flag."""

BROADCAST_WIDTH = 8
"""Most numbers one broadcast carries."""

LIGHTS = ("dark", "steady", "flashing")
"""What a fish's LEDs do, as a snapshot tells it: off, on, or flashing (a robot's formation flag
by light)."""
DARK, STEADY, FLASHING = range(len(LIGHTS))
FORMATION_SHAPES = (
    "fibonacci",
    "pyramid",
    "column",
    "tetrahedral-pyramid",
    "diamond",
    "phalanx",
    "triangle",
    "trigonal-planar",
    "tetrahedron",
)
"""Every formation a flag can name: the global maps, then the local shapes."""


def _check_formation(formation: object) -> None:
    if formation is not None and formation not in FORMATION_SHAPES:
        raise ValueError(f"formation must be one of {FORMATION_SHAPES}, got {formation!r}")


class Message:
    """Base of all messages: field-wise equality (arrays compared by value) and a wire name."""

    type_name: ClassVar[str]
    added_later: ClassVar[frozenset[str]] = frozenset()
    """Fields added after the type was first sent: left off the wire while None (their
    default), so that a peer of the earlier version still reads the message (a robot not
    yet upgraded takes a base station's stop; :func:`fields_of`)."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        for field in dataclasses.fields(self):  # type: ignore[arg-type]
            mine, theirs = getattr(self, field.name), getattr(other, field.name)
            if isinstance(mine, np.ndarray):
                if not np.array_equal(mine, theirs):
                    return False
            elif mine != theirs:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class Perception(Message):
    """What one fish perceives at a tick: world (simulation) or driver (robot) → fish.

    Attributes:
        fish_id: the receiving fish.
        tick: control tick this perception belongs to.
        time: simulated (or robot) time of the tick, s.
        depth: the fish's own depth from its pressure sensor, m (z down).
        neighbors: (K, 3) body-frame positions of the visible neighbours, m. No ids: a camera
            cannot read them.
        landmarks: (L, 3) body-frame positions of visible landmarks (e.g. an orbit centre), m.
        inbox_count: how many inbox deliveries belong to this tick; the fish waits for them.
        run: which run of the world this tick belongs to; a fish that sees a new run starts
            afresh (ticks from the start, memory fresh).
        heading: the fish's heading from a compass, rad in the tank frame; None without one.
        formation: the shape an operator asked formation fish to take (None: as configured).
    """

    type_name: ClassVar[str] = "perception"
    fish_id: int
    tick: int
    time: float
    depth: float
    neighbors: FloatArray
    landmarks: FloatArray
    inbox_count: int = 0
    run: int = 0
    heading: float | None = None
    formation: str | None = None

    def __post_init__(self) -> None:
        _check_formation(self.formation)
        check_int("fish_id", self.fish_id)
        check_int("tick", self.tick)
        check_int("run", self.run)
        if self.heading is not None:
            check_float("heading", self.heading, low=-2 * math.pi, high=2 * math.pi)
        check_float("time", self.time, low=0.0)
        check_float("depth", self.depth)
        check_array(self, "neighbors", np.float64, 3)
        check_array(self, "landmarks", np.float64, 3)
        check_int("inbox_count", self.inbox_count, high=MAX_ROWS)


@dataclass(frozen=True, eq=False)
class Command(Message):
    """What one fish orders for a tick: fish → world or driver.

    Attributes:
        fish_id: the sending fish.
        tick: the perception tick this command answers.
        fins: (4,) fin gains in [0, 1], in the order of :data:`FIN_NAMES`.
        led: whether the LEDs are on.
        broadcasts: how many outbox messages the fish sent for this tick (the channel and the
            world wait for exactly that many).
        flashing: a robot's LEDs flash — its formation flag by light (None: they do not;
            only a mock robot's body tells the world, so that other robots' cameras show it).
        watchdog: True when the fish's safety watchdog turned the fins off (no perception
            nor pulse of the world in time), not a decision (None: a decision).
    """

    type_name: ClassVar[str] = "command"
    added_later: ClassVar[frozenset[str]] = frozenset({"flashing", "watchdog"})
    fish_id: int
    tick: int
    fins: FloatArray
    led: bool = True
    broadcasts: int = 0
    flashing: bool | None = None
    watchdog: bool | None = None

    def __post_init__(self) -> None:
        check_int("fish_id", self.fish_id)
        check_int("tick", self.tick)
        check_array(self, "fins", np.float64, None, rows=len(FIN_NAMES))
        if (self.fins < 0.0).any() or (self.fins > 1.0).any():
            raise ValueError(f"fins must be gains in [0, 1], got {self.fins.tolist()}")
        if not isinstance(self.led, bool):
            raise TypeError(f"led must be a bool, got {type(self.led).__name__}")
        check_int("broadcasts", self.broadcasts, high=MAX_ROWS)
        if self.flashing is not None and not isinstance(self.flashing, bool):
            raise TypeError(f"flashing must be a bool or None, got {type(self.flashing).__name__}")
        if self.watchdog is not None and self.watchdog is not True:
            raise TypeError(f"watchdog must be True or None, got {self.watchdog!r}")


@dataclass(frozen=True, eq=False)
class PerceptionBatch(Message):
    """What every fish of a school perceives at a tick: world → school.

    The same content as one :class:`Perception` per fish, as arrays: the neighbours of all
    fish are stacked, fish after fish, and ``neighbor_counts`` says how many rows are whose.

    Attributes:
        tick: control tick.
        time: simulated time of the tick, s.
        ids: (G,) the fish, ascending.
        depth: (G,) each fish's depth, m.
        neighbor_counts: (G,) visible neighbours of each fish.
        neighbors: (ΣK, 3) body-frame positions of the visible neighbours, m, fish by fish.
        landmark_counts: (G,) visible landmarks of each fish.
        landmarks: (ΣL, 3) body-frame positions of the visible landmarks, m, fish by fish.
        inbox_counts: (G,) deliveries each fish waits for.
        run: which run of the world this tick belongs to (as in :class:`Perception`).
        heading: (G,) each fish's compass heading, rad in the tank frame; None without.
        formation: as in :class:`Perception`.
    """

    type_name: ClassVar[str] = "perception_batch"
    tick: int
    time: float
    ids: IntArray
    depth: FloatArray
    neighbor_counts: IntArray
    neighbors: FloatArray
    landmark_counts: IntArray
    landmarks: FloatArray
    inbox_counts: IntArray
    run: int = 0
    heading: FloatArray | None = None
    formation: str | None = None

    def __post_init__(self) -> None:
        _check_formation(self.formation)
        check_int("tick", self.tick)
        check_int("run", self.run)
        check_float("time", self.time, low=0.0)
        check_array(self, "ids", np.int64, None)
        count = self.ids.shape[0]
        check_ids(self.ids)
        check_array(self, "depth", np.float64, None, rows=count)
        for name, rows in (("neighbor", "neighbors"), ("landmark", "landmarks")):
            check_array(self, f"{name}_counts", np.int64, None, rows=count)
            check_array(self, rows, np.float64, 3)
            counts = getattr(self, f"{name}_counts")
            check_counts(f"{name}_counts", counts, getattr(self, rows).shape[0], rows)
        check_array(self, "inbox_counts", np.int64, None, rows=count)
        if (self.inbox_counts < 0).any() or (self.inbox_counts > MAX_ROWS).any():
            raise ValueError(f"inbox_counts must be in [0, {MAX_ROWS}]")
        if self.heading is not None:
            check_array(self, "heading", np.float64, None, rows=count)
            if (np.abs(self.heading) > 2 * math.pi).any():
                raise ValueError("heading must be in [-2π, 2π] rad")


@dataclass(frozen=True, eq=False)
class CommandBatch(Message):
    """What every fish of a school orders for a tick: school → world.

    Attributes:
        tick: the perception tick these commands answer.
        ids: (G,) the fish, ascending.
        fins: (G, 4) fin gains in [0, 1], columns in the order of :data:`FIN_NAMES`.
        led: (G,) whether each fish's LEDs are on.
        broadcasts: (G,) outbox messages each fish sent for this tick.
        watchdog: True when the school's safety watchdog turned these fish's fins off (no
            perception nor pulse of the world in time), repeating their last tick; not a
            decision (None: a decision).
    """

    type_name: ClassVar[str] = "command_batch"
    added_later: ClassVar[frozenset[str]] = frozenset({"watchdog"})
    tick: int
    ids: IntArray
    fins: FloatArray
    led: BoolArray
    broadcasts: IntArray
    watchdog: bool | None = None

    def __post_init__(self) -> None:
        check_int("tick", self.tick)
        check_array(self, "ids", np.int64, None)
        count = self.ids.shape[0]
        check_ids(self.ids)
        check_array(self, "fins", np.float64, len(FIN_NAMES), rows=count)
        if (self.fins < 0.0).any() or (self.fins > 1.0).any():
            raise ValueError("fins must be gains in [0, 1]")
        check_array(self, "led", np.bool_, None, rows=count)
        check_array(self, "broadcasts", np.int64, None, rows=count)
        if (self.broadcasts < 0).any() or (self.broadcasts > MAX_ROWS).any():
            raise ValueError(f"broadcasts must be in [0, {MAX_ROWS}]")
        if self.watchdog is not None and self.watchdog is not True:
            raise TypeError(f"watchdog must be True or None, got {self.watchdog!r}")


def _check_broadcast(message: Broadcast | Delivery) -> None:
    check_text("kind", message.kind)
    if message.kind not in BROADCAST_KINDS:
        raise ValueError(f"kind must be one of {BROADCAST_KINDS}, got {message.kind!r}")
    check_array(message, "values", np.int64, None)
    if message.values.shape[0] > BROADCAST_WIDTH:
        raise ValueError(f"values hold at most {BROADCAST_WIDTH} numbers")
    if message.kind == "formation":
        FormationFlag.from_values(message.values)
    if message.run is not None:
        check_int("run", message.run)


@dataclass(frozen=True, eq=False)
class Broadcast(Message):
    """A broadcast a fish sends to whoever can receive it: fish → channel.

    Attributes:
        sender_id: the sending fish.
        tick: the tick it was decided at.
        kind: what it says, one of :data:`BROADCAST_KINDS`.
        values: (≤ :data:`BROADCAST_WIDTH`,) its numbers, e.g. a formation flag's slot.
        run: the run the tick is of, as the sender's perception carried it (None: not told).
    """

    type_name: ClassVar[str] = "broadcast"
    added_later: ClassVar[frozenset[str]] = frozenset({"run"})
    sender_id: int
    tick: int
    kind: str
    values: IntArray
    run: int | None = None

    def __post_init__(self) -> None:
        check_int("sender_id", self.sender_id)
        check_int("tick", self.tick)
        _check_broadcast(self)


@dataclass(frozen=True, eq=False)
class Delivery(Message):
    """A broadcast as one receiver gets it: channel → fish.

    Attributes:
        receiver_id: the receiving fish.
        tick: the tick at which the receiver acts on it.
        kind: as in :class:`Broadcast`.
        values: as in :class:`Broadcast`.
        sender_position: (3,) where the sender is, in the receiver's body frame, m (situated,
            like an LED signal: there is no sender id).
        run: the run the tick is of, as the receiver's perceptions carry it (None: not told).
    """

    type_name: ClassVar[str] = "delivery"
    added_later: ClassVar[frozenset[str]] = frozenset({"run"})
    receiver_id: int
    tick: int
    kind: str
    values: IntArray
    sender_position: FloatArray
    run: int | None = None

    def __post_init__(self) -> None:
        check_int("receiver_id", self.receiver_id)
        check_int("tick", self.tick)
        _check_broadcast(self)
        check_array(self, "sender_position", np.float64, None, rows=3)


@dataclass(frozen=True)
class FormationFlag:
    """A formation flag: what a fish in a shape tells the fish around it (SPEC §5). It
    travels as the numbers of a ``formation`` :class:`Broadcast`.

    Attributes:
        shape: the formation, an index into :data:`FORMATION_SHAPES`.
        slot: the slot (global map) or spot (local shape) the fish holds; −1 for none.
        joined: whether the fish is in its slot, within the tolerance.
        hops: hops from the leader (0: the leader itself).
        heading_mdeg: the formation's orientation the sender follows, millidegrees in the
            tank frame, in [−180 000, 180 000].
        sequence: the sender's flag count, to tell a new flag from an old one.
        effort: the sender's effort so far, whole gain-weighted fin beats (0: not told).
        swap: the slot whose holder the sender asks to swap places with (−1: none; sent
            as swap + 1, so that 0 means none); a tired fish in a costly slot asks a
            rested one.
    """

    shape: int
    slot: int
    joined: bool
    hops: int
    heading_mdeg: int
    sequence: int
    effort: int = 0
    swap: int = -1

    def __post_init__(self) -> None:
        check_int("shape", self.shape, high=len(FORMATION_SHAPES) - 1)
        check_int("slot", self.slot, low=-1, high=MAX_ROWS)
        if not isinstance(self.joined, bool | np.bool_):
            raise TypeError(f"joined must be a bool, got {type(self.joined).__name__}")
        check_int("hops", self.hops, high=MAX_ROWS)
        check_int("heading_mdeg", self.heading_mdeg, low=-180_000, high=180_000)
        check_int("sequence", self.sequence)
        check_int("effort", self.effort)
        check_int("swap", self.swap, low=-1, high=MAX_ROWS)

    def values(self) -> IntArray:
        """The flag as a broadcast's numbers."""
        return np.array(
            [
                self.shape,
                self.slot,
                int(self.joined),
                self.hops,
                self.heading_mdeg,
                self.sequence,
                self.effort,
                self.swap + 1,  # 0 on the wire is "none", as in a zero-padded inbox row
            ],
            dtype=np.int64,
        )

    @classmethod
    def from_values(cls, values: IntArray) -> FormationFlag:
        """The flag a broadcast's numbers carry.

        Raises:
            ValueError: the numbers are not a formation flag.
        """
        if values.shape[0] < 6:
            raise ValueError(f"a formation flag has 6 to 8 numbers, got {values.shape[0]}")
        shape, slot, joined, hops, heading, sequence = (int(v) for v in values[:6])
        if joined not in (0, 1):
            raise ValueError(f"joined must be 0 or 1, got {joined}")
        # Flags of 6 numbers (before effort sharing) read as effort 0, no swap.
        effort = int(values[6]) if values.shape[0] > 6 else 0
        swap = int(values[7]) - 1 if values.shape[0] > 7 else -1
        return cls(shape, slot, bool(joined), hops, heading, sequence, effort, swap)


@dataclass(frozen=True, eq=False)
class Snapshot(Message):
    """Every live fish's state at a tick: world → channel and observers.

    Attributes:
        tick: the tick.
        time: simulated time, s.
        ids: (N,) fish ids, ascending.
        position: (N, 3) positions in the tank frame, m.
        velocity: (N, 3) velocities in the tank frame, m/s.
        yaw: (N,) yaw angles, rad.
        neighbors_seen: (N,) how many neighbours each fish saw at this tick.
        broadcasts: (N,) how many broadcasts each fish sent at the previous tick.
        effort: (N,) each fish's effort so far, gain-weighted fin beats (None: not
            measured).
        formation: the shape formation fish are told to take at this tick, after a switch
            (None: as configured, or not a formation run).
        run: the world's run id, as its perceptions carry it (0: not told).
        lights: (N,) each fish's LEDs as robots' commands tell them, an index into
            :data:`LIGHTS` (dark, steady, or flashing: a formation flag by light); None: all
            steady.
    """

    type_name: ClassVar[str] = "snapshot"
    added_later: ClassVar[frozenset[str]] = frozenset({"lights"})
    tick: int
    time: float
    ids: IntArray
    position: FloatArray
    velocity: FloatArray
    yaw: FloatArray
    neighbors_seen: IntArray
    broadcasts: IntArray
    effort: FloatArray | None = None
    formation: str | None = None
    run: int = 0
    lights: IntArray | None = None

    def __post_init__(self) -> None:
        _check_formation(self.formation)
        check_int("tick", self.tick)
        check_int("run", self.run)
        check_float("time", self.time, low=0.0)
        check_array(self, "ids", np.int64, None)
        count = self.ids.shape[0]
        check_array(self, "position", np.float64, 3, rows=count)
        check_array(self, "velocity", np.float64, 3, rows=count)
        check_array(self, "yaw", np.float64, None, rows=count)
        check_array(self, "neighbors_seen", np.int64, None, rows=count)
        check_array(self, "broadcasts", np.int64, None, rows=count)
        if self.effort is not None:
            check_array(self, "effort", np.float64, None, rows=count)
            if (self.effort < 0).any():
                raise ValueError("effort must not be negative")
        if self.lights is not None:
            check_array(self, "lights", np.int64, None, rows=count)
            if ((self.lights < 0) | (self.lights >= len(LIGHTS))).any():
                raise ValueError(f"lights must be indices into {LIGHTS}")
        check_ids(self.ids)


@dataclass(frozen=True, eq=False)
class ChannelReport(Message):
    """How many deliveries each fish gets at a tick: channel → world.

    Attributes:
        tick: the tick at which the fish act on the deliveries.
        ids: (N,) fish ids, ascending.
        inbox_counts: (N,) deliveries per fish.
    """

    type_name: ClassVar[str] = "channel_report"
    tick: int
    ids: IntArray
    inbox_counts: IntArray

    def __post_init__(self) -> None:
        check_int("tick", self.tick)
        check_array(self, "ids", np.int64, None)
        check_ids(self.ids)
        check_array(self, "inbox_counts", np.int64, None, rows=self.ids.shape[0])
        if (self.inbox_counts < 0).any() or (self.inbox_counts > MAX_ROWS).any():
            raise ValueError(f"inbox_counts must be in [0, {MAX_ROWS}]")


@dataclass(frozen=True, eq=False)
class ControlRequest(Message):
    """A request to the world's control queryable.

    Attributes:
        action: one of :data:`CONTROL_ACTIONS`.
        formation: with ``formation``, the shape the school is to take from the next tick,
            one of :data:`FORMATION_SHAPES`.
    """

    type_name: ClassVar[str] = "control_request"
    action: str
    formation: str | None = None

    def __post_init__(self) -> None:
        check_text("action", self.action)
        if self.action not in CONTROL_ACTIONS:
            raise ValueError(f"action must be one of {CONTROL_ACTIONS}, got {self.action!r}")
        if (self.action == "formation") != (self.formation is not None):
            raise ValueError("a formation request, and only one, names a formation")
        if self.formation is not None and self.formation not in FORMATION_SHAPES:
            raise ValueError(f"formation must be one of {FORMATION_SHAPES}, got {self.formation!r}")


@dataclass(frozen=True, eq=False)
class ControlReply(Message):
    """The world's answer to a :class:`ControlRequest`.

    Attributes:
        state: waiting, running, paused, stopping, finished or stopped.
        tick: the current tick.
        time: the current simulated time, s.
        live_fish: how many fish are live.
        refused: why the request was not carried out (None: it was, or it only asked).
    """

    type_name: ClassVar[str] = "control_reply"
    state: str
    tick: int
    time: float
    live_fish: int
    refused: str | None = None

    def __post_init__(self) -> None:
        check_text("state", self.state)
        if self.state not in WORLD_STATES:
            raise ValueError(f"state must be one of {WORLD_STATES}, got {self.state!r}")
        check_int("tick", self.tick)
        check_float("time", self.time, low=0.0)
        check_int("live_fish", self.live_fish, high=MAX_ROWS)
        if self.refused is not None:
            check_text("refused", self.refused)


MAX_ABOUT_PARTS = 128
"""Most parameters a :class:`FishAbout` may name (a behaviour's own settings, up to
:data:`MAX_SETTING_LIST`, and the controller's)."""


@dataclass(frozen=True, eq=False)
class FishAbout(Message):
    """What some fish run, said by their actor when a run of the world starts for them.

    Attributes:
        ids: the fish, ascending.
        behavior: the behaviour their decisions follow.
        version: the fishswarm version of their actor.
        run: the run of the world they start.
        rules: ``paper``, or the study code's fish-side switches their decisions follow
            (e.g. ``lennard-jones,homing``).
        control_period: the time between their decisions they were started with, s
            (None: not said, by an older fishswarm).
        settings: a fingerprint of the rest of what their decisions depend on
            (:func:`fishswarm.behaviors.registry.settings_digest`; None: not said).
        parts: a short fingerprint of each of those parameters by name
            (:func:`fishswarm.behaviors.registry.settings_parts`), so that a world can name
            the ones that differ from its own; None: not said.
    """

    type_name: ClassVar[str] = "fish_about"
    added_later: ClassVar[frozenset[str]] = frozenset({"control_period", "settings", "parts"})
    ids: IntArray
    behavior: str
    version: str
    run: int = 0
    rules: str = "paper"
    control_period: float | None = None
    settings: str | None = None
    parts: dict[str, str] | None = None

    def __post_init__(self) -> None:
        check_array(self, "ids", np.int64, None)
        check_ids(self.ids)
        if self.ids.shape[0] == 0:
            raise ValueError("ids must name at least one fish")
        check_text("behavior", self.behavior)
        check_text("version", self.version)
        check_int("run", self.run)
        check_text("rules", self.rules)
        if self.control_period is not None:
            check_float("control_period", self.control_period, 0.0)
        if self.settings is not None:
            check_text("settings", self.settings)
        if self.parts is not None:
            if not isinstance(self.parts, dict):
                raise TypeError(f"parts must be a table, got {type(self.parts).__name__}")
            if len(self.parts) > MAX_ABOUT_PARTS:
                raise ValueError(f"parts must have at most {MAX_ABOUT_PARTS} entries")
            for name, fingerprint in self.parts.items():
                check_text("a part's name", name)
                check_text(f"part {name}", fingerprint)
            object.__setattr__(self, "parts", dict(self.parts))


@dataclass(frozen=True, eq=False)
class WorldPulse(Message):
    """World → fish, about once a second while a run goes on: the world is alive and the
    next perceptions will come, however long it computes or waits for other fish.

    A fish's safety watchdog counts a pulse of its run as a sign of life, so a slow world
    (a large swarm, a paused run, a fish that holds up a tick) does not stop the fins; a
    world that dies or is cut off stops pulsing.

    Attributes:
        run: the run of the world.
        tick: the last tick the world published.
        state: what the world is doing: running, paused, stopping, or ended (its last
            pulse: the run is over, its fish are no longer watched for it).
    """

    type_name: ClassVar[str] = "world_pulse"
    run: int
    tick: int
    state: str

    def __post_init__(self) -> None:
        check_int("run", self.run)
        check_int("tick", self.tick)
        if self.state not in WORLD_PULSE_STATES:
            raise ValueError(f"state must be one of {WORLD_PULSE_STATES}, got {self.state!r}")


WORLD_PULSE_STATES = ("running", "paused", "stopping", "ended")


MAX_SETTINGS = 200
"""Most settings a :class:`RunSettings` may carry."""
MAX_SETTING_TEXT = 4096
"""Most characters of a setting's text (a model's path may be long)."""
MAX_SETTING_LIST = 64
"""Most values of a setting that is a list."""


def _check_setting(name: str, value: object) -> object:
    """A setting's value if it is plain data: None, a boolean, an integer, a finite number,
    text, a short list of those (given back as a tuple, so the message cannot change), or a
    short table of those by name (a behaviour's own settings)."""
    if value is None or isinstance(value, bool):
        return value
    if isinstance(value, int):
        check_int(name, value, low=-MAX_TICK, high=MAX_TICK)
        return value
    if isinstance(value, float):
        check_float(name, value)
        return value
    if isinstance(value, str):
        if len(value) > MAX_SETTING_TEXT:
            raise ValueError(f"{name} must have at most {MAX_SETTING_TEXT} characters")
        return value
    if isinstance(value, list | tuple):
        if len(value) > MAX_SETTING_LIST:
            raise ValueError(f"{name} must have at most {MAX_SETTING_LIST} values")
        # Checked before looking inside: a list of lists is refused at the first level,
        # however deep a hostile payload nests them.
        if any(isinstance(item, list | tuple) for item in value):
            raise TypeError(f"{name} must be a list of plain values, not of lists")
        return tuple(_check_setting(f"{name}[{index}]", item) for index, item in enumerate(value))
    if isinstance(value, dict):
        if len(value) > MAX_SETTING_LIST:
            raise ValueError(f"{name} must have at most {MAX_SETTING_LIST} entries")
        # As for lists: one level only, refused before looking deeper.
        if any(isinstance(item, list | tuple | dict) for item in value.values()):
            raise TypeError(f"{name} must be a table of plain values, not of lists or tables")
        table: dict[str, object] = {}
        for key, item in value.items():
            check_text(f"a name in {name}", key)
            table[key] = _check_setting(f"{name}.{key}", item)
        return table
    raise TypeError(f"{name} must be plain data, got {type(value).__name__}")


@dataclass(frozen=True, eq=False)
class RunSettings(Message):
    """World → whoever asks its ``world/scenario`` queryable: the settings of the run.

    Attributes:
        scenario: the scenario as plain data (``Scenario.to_dict``): setting names to None,
            booleans, integers, finite numbers, text, lists of those (the tank's size, the
            flow, the study code's switches), or tables of those by name (a behaviour's own
            settings). The settings themselves are checked by whoever builds a scenario
            from them.
    """

    type_name: ClassVar[str] = "run_settings"
    scenario: dict[str, Any]

    def __post_init__(self) -> None:
        if not isinstance(self.scenario, dict):
            raise TypeError(f"scenario must be a table, got {type(self.scenario).__name__}")
        if len(self.scenario) > MAX_SETTINGS:
            raise ValueError(f"scenario must have at most {MAX_SETTINGS} settings")
        checked: dict[str, Any] = {}
        for name, value in self.scenario.items():
            check_text("a setting's name", name)
            checked[name] = _check_setting(name, value)
        object.__setattr__(self, "scenario", checked)


ROBOT_STATES = ("swimming", "waiting", "failsafe", "stranded", "stopped")
"""What a robot's driver is doing: swimming (commands arrive), waiting (no perception yet),
failsafe (no command for too long: fins off), stranded (link to the base station lost for
too long: fins off until it returns), stopped (an operator's order: fins off until resumed)."""
ROBOT_ORDERS = ("stop", "resume", "formation")


@dataclass(frozen=True, eq=False)
class RobotStatus(Message):
    """How a robot is: its driver → the base station, a few times a second.

    Attributes:
        robot_id: the robot (its fish's id).
        version: the fishswarm version it runs.
        behavior: the behaviour its fish actor runs.
        state: one of :data:`ROBOT_STATES`.
        depth: its depth from the pressure sensor, m.
        fin_frequencies: (4,) the frequency each fin beats at now, Hz.
        link: whether its Zenoh session reaches a router.
        cpu_temperature: the Pi's SoC temperature, °C; None where it cannot be read.
        uptime: time since the driver started, s.
        perceptions: perceptions its driver made.
        commands: commands it obeyed.
        failsafe_stops: times its fins were stopped for lack of commands.
        formation: the shape an operator's order told its formation fish to take (None: as
            configured).
        flashing: its LEDs flash: its fish holds its place, and says so by light (None:
            they do not).
        flags_seen: flashing neighbours its driver handed its fish as formation flags so far
            (None: none).
    """

    type_name: ClassVar[str] = "robot_status"
    added_later: ClassVar[frozenset[str]] = frozenset({"formation", "flashing", "flags_seen"})
    robot_id: int
    version: str
    behavior: str
    state: str
    depth: float
    fin_frequencies: FloatArray
    link: bool
    cpu_temperature: float | None
    uptime: float
    perceptions: int = 0
    commands: int = 0
    failsafe_stops: int = 0
    formation: str | None = None
    flashing: bool | None = None
    flags_seen: int | None = None

    def __post_init__(self) -> None:
        check_int("robot_id", self.robot_id)
        check_text("version", self.version)
        check_text("behavior", self.behavior)
        check_text("state", self.state)
        if self.state not in ROBOT_STATES:
            raise ValueError(f"state must be one of {ROBOT_STATES}, got {self.state!r}")
        check_float("depth", self.depth)
        check_array(self, "fin_frequencies", np.float64, None, rows=len(FIN_NAMES))
        if (self.fin_frequencies < 0).any():
            raise ValueError("fin_frequencies must not be negative")
        if not isinstance(self.link, bool):
            raise TypeError(f"link must be a bool, got {type(self.link).__name__}")
        if self.cpu_temperature is not None:
            check_float("cpu_temperature", self.cpu_temperature, low=-100.0, high=200.0)
        check_float("uptime", self.uptime, low=0.0)
        for name in ("perceptions", "commands", "failsafe_stops"):
            check_int(name, getattr(self, name))
        _check_formation(self.formation)
        if self.flashing is not None and not isinstance(self.flashing, bool):
            raise TypeError(f"flashing must be a bool or None, got {type(self.flashing).__name__}")
        if self.flags_seen is not None:
            check_int("flags_seen", self.flags_seen)


@dataclass(frozen=True, eq=False)
class RobotOrder(Message):
    """An operator's order to robots: base station → every robot's driver.

    Attributes:
        action: ``stop`` (fins off, LEDs off, commands ignored), ``resume``, or
            ``formation`` (its formation fish take the shape ``formation`` from their next
            perception on: on robots there is no world to tell them).
        robot_ids: the robots it is for, ascending; empty: every robot.
        formation: with ``formation``, the shape (one of :data:`FORMATION_SHAPES`); None
            with the other actions.
    """

    type_name: ClassVar[str] = "robot_order"
    added_later: ClassVar[frozenset[str]] = frozenset({"formation"})
    action: str
    robot_ids: IntArray = dataclasses.field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    formation: str | None = None

    def __post_init__(self) -> None:
        check_text("action", self.action)
        if self.action not in ROBOT_ORDERS:
            raise ValueError(f"action must be one of {ROBOT_ORDERS}, got {self.action!r}")
        check_array(self, "robot_ids", np.int64, None)
        check_ids(self.robot_ids)
        _check_formation(self.formation)
        if (self.formation is None) == (self.action == "formation"):
            raise ValueError(
                "a formation order names its shape, and only a formation order names one: "
                f"action {self.action!r} with formation {self.formation!r}"
            )

    def addresses(self, robot_id: int) -> bool:
        """Whether the order is for robot ``robot_id``."""
        return self.robot_ids.size == 0 or bool(np.isin(robot_id, self.robot_ids))


MESSAGE_TYPES: dict[str, type[Message]] = {
    cls.type_name: cls
    for cls in (
        Perception,
        Command,
        PerceptionBatch,
        CommandBatch,
        Broadcast,
        Delivery,
        Snapshot,
        ChannelReport,
        ControlRequest,
        ControlReply,
        RobotStatus,
        RobotOrder,
        FishAbout,
        WorldPulse,
        RunSettings,
    )
}


_FIELD_NAMES: dict[str, tuple[str, ...]] = {}


def field_names(cls: type[Message]) -> tuple[str, ...]:
    """The names of a message type's fields, in order (looked up once per type)."""
    names = _FIELD_NAMES.get(cls.type_name)
    if names is None:
        fields = dataclasses.fields(cls)  # type: ignore[arg-type]
        names = _FIELD_NAMES[cls.type_name] = tuple(f.name for f in fields)
    return names


def fields_of(message: Message) -> dict[str, Any]:
    """The message's fields as a dict (arrays not copied), but those added later while None."""
    fields = {name: getattr(message, name) for name in field_names(type(message))}
    for name in message.added_later:
        if fields[name] is None:
            del fields[name]
    return fields
