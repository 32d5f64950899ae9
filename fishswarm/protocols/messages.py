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
from numpy.typing import NDArray

SCHEMA_VERSION = 1
MAX_ROWS = 100_000
MAX_TEXT = 64
MAX_TICK = 2**62

FIN_NAMES = ("caudal", "dorsal", "pectoral_left", "pectoral_right")
"""Order of the fin gains in :attr:`Command.fins` and everywhere else."""

CONTROL_ACTIONS = ("status", "pause", "resume", "stop")

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def _set(obj: object, name: str, value: object) -> None:
    object.__setattr__(obj, name, value)


def _check_int(name: str, value: object, low: int = 0, high: int = MAX_TICK) -> None:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if not low <= int(value) <= high:
        raise ValueError(f"{name} must be in [{low}, {high}], got {value}")


def _check_float(name: str, value: object, low: float = -math.inf, high: float = math.inf) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be in [{low}, {high}], got {value}")


def _check_text(name: str, value: object) -> None:
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a string, got {type(value).__name__}")
    if not 0 < len(value) <= MAX_TEXT:
        raise ValueError(f"{name} must have 1 to {MAX_TEXT} characters, got {len(value)}")


def _array(
    obj: object, name: str, dtype: type[np.generic], columns: int | None, rows: int | None = None
) -> None:
    """Replace field ``name`` by a read-only array of ``dtype`` after checking its shape.

    ``columns`` None means a 1-D array; otherwise 2-D with that many columns. ``rows`` fixes
    the length when given; any length up to MAX_ROWS otherwise.
    """
    value = getattr(obj, name)
    array = value if isinstance(value, np.ndarray) else np.asarray(value)
    if array.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be a numeric array, got dtype {array.dtype}")
    if dtype is np.int64 and array.dtype.kind == "f":
        raise TypeError(f"{name} must be an integer array, got dtype {array.dtype}")
    if (dtype is np.bool_) != (array.dtype.kind == "b") and array.size:
        kind = "a boolean" if dtype is np.bool_ else "a numeric"
        raise TypeError(f"{name} must be {kind} array, got dtype {array.dtype}")
    expected_ndim = 1 if columns is None else 2
    if array.ndim != expected_ndim or (columns is not None and array.shape[1] != columns):
        want = "(n,)" if columns is None else f"(n, {columns})"
        raise ValueError(f"{name} must have shape {want}, got {array.shape}")
    if rows is not None and array.shape[0] != rows:
        raise ValueError(f"{name} must have {rows} rows, got {array.shape[0]}")
    if array.shape[0] > MAX_ROWS:
        raise ValueError(f"{name} has {array.shape[0]} rows, more than the limit {MAX_ROWS}")
    # Arrays decoded from the wire are read-only already and need no copy; anything the caller
    # could still change is copied, so that a message never changes after construction.
    if array.dtype != dtype or array.flags.writeable:
        array = np.array(array, dtype=dtype, copy=True)
        array.setflags(write=False)
    if dtype is np.float64 and not np.isfinite(array).all():
        raise ValueError(f"{name} must hold finite numbers only")
    _set(obj, name, array)


class Message:
    """Base of all messages: field-wise equality (arrays compared by value) and a wire name."""

    type_name: ClassVar[str]

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
    """

    type_name: ClassVar[str] = "perception"
    fish_id: int
    tick: int
    time: float
    depth: float
    neighbors: FloatArray
    landmarks: FloatArray
    inbox_count: int = 0

    def __post_init__(self) -> None:
        _check_int("fish_id", self.fish_id)
        _check_int("tick", self.tick)
        _check_float("time", self.time, low=0.0)
        _check_float("depth", self.depth)
        _array(self, "neighbors", np.float64, 3)
        _array(self, "landmarks", np.float64, 3)
        _check_int("inbox_count", self.inbox_count, high=MAX_ROWS)


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
    """

    type_name: ClassVar[str] = "command"
    fish_id: int
    tick: int
    fins: FloatArray
    led: bool = True
    broadcasts: int = 0

    def __post_init__(self) -> None:
        _check_int("fish_id", self.fish_id)
        _check_int("tick", self.tick)
        _array(self, "fins", np.float64, None, rows=len(FIN_NAMES))
        if (self.fins < 0.0).any() or (self.fins > 1.0).any():
            raise ValueError(f"fins must be gains in [0, 1], got {self.fins.tolist()}")
        if not isinstance(self.led, bool):
            raise TypeError(f"led must be a bool, got {type(self.led).__name__}")
        _check_int("broadcasts", self.broadcasts, high=MAX_ROWS)


def _check_ids(ids: IntArray) -> None:
    if ids.shape[0] > 1 and (ids[1:] <= ids[:-1]).any():
        raise ValueError("ids must be strictly ascending")
    if ids.shape[0] and ids[0] < 0:  # ascending: the first is the least
        raise ValueError("ids must be non-negative")


def _check_counts(name: str, counts: IntArray, rows: int, what: str) -> None:
    if (counts < 0).any():
        raise ValueError(f"{name} must be non-negative")
    if int(counts.sum()) != rows:
        raise ValueError(f"{name} add up to {int(counts.sum())}, but {what} has {rows} rows")


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

    def __post_init__(self) -> None:
        _check_int("tick", self.tick)
        _check_float("time", self.time, low=0.0)
        _array(self, "ids", np.int64, None)
        count = self.ids.shape[0]
        _check_ids(self.ids)
        _array(self, "depth", np.float64, None, rows=count)
        for name, rows in (("neighbor", "neighbors"), ("landmark", "landmarks")):
            _array(self, f"{name}_counts", np.int64, None, rows=count)
            _array(self, rows, np.float64, 3)
            counts = getattr(self, f"{name}_counts")
            _check_counts(f"{name}_counts", counts, getattr(self, rows).shape[0], rows)
        _array(self, "inbox_counts", np.int64, None, rows=count)
        if (self.inbox_counts < 0).any() or (self.inbox_counts > MAX_ROWS).any():
            raise ValueError(f"inbox_counts must be in [0, {MAX_ROWS}]")


@dataclass(frozen=True, eq=False)
class CommandBatch(Message):
    """What every fish of a school orders for a tick: school → world.

    Attributes:
        tick: the perception tick these commands answer.
        ids: (G,) the fish, ascending.
        fins: (G, 4) fin gains in [0, 1], columns in the order of :data:`FIN_NAMES`.
        led: (G,) whether each fish's LEDs are on.
        broadcasts: (G,) outbox messages each fish sent for this tick.
    """

    type_name: ClassVar[str] = "command_batch"
    tick: int
    ids: IntArray
    fins: FloatArray
    led: BoolArray
    broadcasts: IntArray

    def __post_init__(self) -> None:
        _check_int("tick", self.tick)
        _array(self, "ids", np.int64, None)
        count = self.ids.shape[0]
        _check_ids(self.ids)
        _array(self, "fins", np.float64, len(FIN_NAMES), rows=count)
        if (self.fins < 0.0).any() or (self.fins > 1.0).any():
            raise ValueError("fins must be gains in [0, 1]")
        _array(self, "led", np.bool_, None, rows=count)
        _array(self, "broadcasts", np.int64, None, rows=count)
        if (self.broadcasts < 0).any() or (self.broadcasts > MAX_ROWS).any():
            raise ValueError(f"broadcasts must be in [0, {MAX_ROWS}]")


@dataclass(frozen=True, eq=False)
class Broadcast(Message):
    """A broadcast a fish sends to whoever can receive it: fish → channel.

    Attributes:
        sender_id: the sending fish.
        tick: the tick it was sent at.
        kind: what it says, e.g. ``"formation"`` for a formation flag.
        value: the content, e.g. the sender's role in its shape.
    """

    type_name: ClassVar[str] = "broadcast"
    sender_id: int
    tick: int
    kind: str
    value: int = 0

    def __post_init__(self) -> None:
        _check_int("sender_id", self.sender_id)
        _check_int("tick", self.tick)
        _check_text("kind", self.kind)
        _check_int("value", self.value, low=-MAX_TICK)


@dataclass(frozen=True, eq=False)
class Delivery(Message):
    """A broadcast as one receiver gets it: channel → fish.

    Attributes:
        receiver_id: the receiving fish.
        tick: the tick at which the receiver acts on it.
        kind: as in :class:`Broadcast`.
        value: as in :class:`Broadcast`.
        sender_position: (3,) where the sender is, in the receiver's body frame, m (situated,
            like an LED signal: there is no sender id).
    """

    type_name: ClassVar[str] = "delivery"
    receiver_id: int
    tick: int
    kind: str
    value: int
    sender_position: FloatArray

    def __post_init__(self) -> None:
        _check_int("receiver_id", self.receiver_id)
        _check_int("tick", self.tick)
        _check_text("kind", self.kind)
        _check_int("value", self.value, low=-MAX_TICK)
        _array(self, "sender_position", np.float64, None, rows=3)


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
    """

    type_name: ClassVar[str] = "snapshot"
    tick: int
    time: float
    ids: IntArray
    position: FloatArray
    velocity: FloatArray
    yaw: FloatArray
    neighbors_seen: IntArray
    broadcasts: IntArray

    def __post_init__(self) -> None:
        _check_int("tick", self.tick)
        _check_float("time", self.time, low=0.0)
        _array(self, "ids", np.int64, None)
        count = self.ids.shape[0]
        _array(self, "position", np.float64, 3, rows=count)
        _array(self, "velocity", np.float64, 3, rows=count)
        _array(self, "yaw", np.float64, None, rows=count)
        _array(self, "neighbors_seen", np.int64, None, rows=count)
        _array(self, "broadcasts", np.int64, None, rows=count)
        _check_ids(self.ids)


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
        _check_int("tick", self.tick)
        _array(self, "ids", np.int64, None)
        _array(self, "inbox_counts", np.int64, None, rows=self.ids.shape[0])


@dataclass(frozen=True, eq=False)
class ControlRequest(Message):
    """A request to the world's control queryable.

    Attributes:
        action: one of :data:`CONTROL_ACTIONS`.
    """

    type_name: ClassVar[str] = "control_request"
    action: str

    def __post_init__(self) -> None:
        _check_text("action", self.action)
        if self.action not in CONTROL_ACTIONS:
            raise ValueError(f"action must be one of {CONTROL_ACTIONS}, got {self.action!r}")


@dataclass(frozen=True, eq=False)
class ControlReply(Message):
    """The world's answer to a :class:`ControlRequest`.

    Attributes:
        state: waiting, running, paused, finished or stopped.
        tick: the current tick.
        time: the current simulated time, s.
        live_fish: how many fish are live.
    """

    type_name: ClassVar[str] = "control_reply"
    state: str
    tick: int
    time: float
    live_fish: int

    def __post_init__(self) -> None:
        _check_text("state", self.state)
        _check_int("tick", self.tick)
        _check_float("time", self.time, low=0.0)
        _check_int("live_fish", self.live_fish, high=MAX_ROWS)


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
    """The message's fields as a dict (arrays not copied)."""
    return {name: getattr(message, name) for name in field_names(type(message))}
