"""The fish core: what B fish perceive, hear and decide, as arrays with a leading batch axis.

Every behaviour has the one shape ``decide(memory, perception, inbox, *, params) -> (memory,
Decision)``: the memory a fish carries from one decision to the next goes in and comes out,
so deciding is a pure function. The same call serves one fish (a fish actor on a robot, a
batch of one) and a whole swarm (the world's batch engine, sweeps, learning); a batch gives
the result of a loop over its fish bit for bit (tested for every behaviour).

A behaviour *steers* — it says where the fish wants to go (a target vector in its body
frame), whether its LEDs are lit and what it broadcasts — and a controller turns the target
into fin gains (:mod:`fishswarm.bluebot.control`). Each behaviour family owns its
parameters and its memory type and is found by name in :mod:`fishswarm.behaviors.registry`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np
from numpy.typing import NDArray

from fishswarm.bluebot.control import CONTROLLERS, PidGains, PidState, homing, pid
from fishswarm.bluebot.parameters import effort_rate
from fishswarm.protocols.messages import BROADCAST_WIDTH

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
Rows = NDArray[np.intp]

T = TypeVar("T")


@dataclass(frozen=True)
class Perception:
    """What B fish perceive at one decision.

    Attributes:
        time: (B,) time of the perception, s (simulated or the robot's clock).
        depth: (B,) each fish's depth from its pressure sensor, m (z down).
        neighbors: (B, K, 3) visible neighbours in each fish's body frame, m; no ids.
        neighbor_mask: (B, K) which neighbour rows are real.
        landmarks: (B, L, 3) visible landmarks in the body frame, m (an orbit centre first).
        landmark_mask: (B, L) which landmark rows are real.
        heading: (B,) each fish's heading from a compass, rad in the tank frame (yaw; NaN
            where a fish has none), or None when no fish has one.
        effort: (B,) each fish's own effort so far, gain-weighted fin beats: its count of
            the beats of the fins it commanded, each weighted by the fin's gain
            (:func:`decide` fills it in from the fish's memory).
    """

    time: FloatArray
    depth: FloatArray
    neighbors: FloatArray
    neighbor_mask: BoolArray
    landmarks: FloatArray
    landmark_mask: BoolArray
    heading: FloatArray | None = None
    effort: FloatArray | None = None

    @property
    def count(self) -> int:
        """B, the number of fish."""
        return int(self.depth.shape[0])


@dataclass(frozen=True)
class Inbox:
    """Broadcasts delivered to B fish since their last decision, M rows per fish.

    Attributes:
        kind: (B, M) what each says, as an index into
            :data:`~fishswarm.protocols.messages.BROADCAST_KINDS`.
        values: (B, M, W) its numbers (W = BROADCAST_WIDTH, zero-padded).
        sender: (B, M, 3) where the sender appeared in the receiver's body frame, m.
        mask: (B, M) which rows are real.
    """

    kind: IntArray
    values: IntArray
    sender: FloatArray
    mask: BoolArray

    @classmethod
    def empty(cls, count: int) -> Inbox:
        """The inbox of ``count`` fish that heard nothing (read-only, shared)."""
        return _empty(count)


@dataclass(frozen=True)
class Outbox:
    """What B fish broadcast at one decision: at most one broadcast each.

    Attributes:
        kind: (B,) index into :data:`~fishswarm.protocols.messages.BROADCAST_KINDS`.
        values: (B, W) its numbers.
        mask: (B,) which fish broadcast.
    """

    kind: IntArray
    values: IntArray
    mask: BoolArray

    @classmethod
    def silent(cls, count: int) -> Outbox:
        """``count`` fish that broadcast nothing (read-only arrays, shared between calls:
        most decisions of most behaviours are silent, and a fish actor decides often)."""
        return _silent(count)


@dataclass(frozen=True)
class Steering:
    """What a behaviour decides for B fish, before a controller makes fin gains of it.

    Attributes:
        target: (B, 3) desired motion in the body frame, m.
        led: (B,) whether each fish's LEDs are lit.
        outbox: what the fish broadcast.
    """

    target: FloatArray
    led: BoolArray
    outbox: Outbox


@dataclass(frozen=True)
class Decision:
    """What B fish do for one control period.

    Attributes:
        fins: (B, 4) gains in [0, 1]: caudal, dorsal, pectoral left, pectoral right.
        led: (B,) whether each fish's LEDs are lit.
        outbox: what the fish broadcast.
    """

    fins: FloatArray
    led: BoolArray
    outbox: Outbox


class Steer(Protocol):
    """A behaviour family's decision: memory, perception and inbox → memory and steering."""

    def __call__(
        self, memory: Any, perception: Perception, inbox: Inbox, *, params: Any
    ) -> tuple[Any, Steering]: ...


@dataclass(frozen=True)
class NoMemory:
    """The memory of a behaviour that remembers nothing."""


def no_memory(count: int) -> NoMemory:
    """The (empty) memory of ``count`` fish."""
    return NoMemory()


def steady(target: FloatArray) -> Steering:
    """Steering towards ``target`` with LEDs lit and nothing broadcast (most behaviours)."""
    count = target.shape[0]
    return Steering(target, _lit(count), Outbox.silent(count))


def _read_only(*arrays: np.ndarray) -> None:
    for array in arrays:
        array.setflags(write=False)


@functools.lru_cache(maxsize=64)
def _silent(count: int) -> Outbox:
    kind = np.zeros(count, dtype=np.int64)
    values = np.zeros((count, BROADCAST_WIDTH), dtype=np.int64)
    mask = np.zeros(count, dtype=np.bool_)
    _read_only(kind, values, mask)
    return Outbox(kind, values, mask)


@functools.lru_cache(maxsize=64)
def _empty(count: int) -> Inbox:
    kind = np.zeros((count, 0), dtype=np.int64)
    values = np.zeros((count, 0, BROADCAST_WIDTH), dtype=np.int64)
    sender = np.zeros((count, 0, 3))
    mask = np.zeros((count, 0), dtype=np.bool_)
    _read_only(kind, values, sender, mask)
    return Inbox(kind, values, sender, mask)


@functools.lru_cache(maxsize=64)
def _lit(count: int) -> BoolArray:
    led = np.ones(count, dtype=np.bool_)
    _read_only(led)
    return led


@dataclass(frozen=True)
class Behavior:
    """A behaviour family as the registry knows it.

    Attributes:
        name: how scenarios, the command line and experiments call it.
        summary: one line for ``--help``.
        steer: its decision (:class:`Steer`).
        fresh_memory: the memory of B fish that have not decided yet.
        parameters: its parameters from a scenario's settings (a mapping of setting name →
            value, with the defaults already applied); raises ValueError on bad ones.
        spawn_radius: default distance from the tank centre within which fish start, m.
        circles_landmark: whether it needs a landmark (by default a post at the tank centre).
        pid_gains: the gains its fish use with the pid controller (None: the defaults).
        controller: the controller its fish use unless a scenario names one.
        settings: its own settings, by name, with their defaults (a number, text or true
            or false each): what a scenario's ``behavior_settings`` and the command line's
            ``--behavior-setting NAME=VALUE`` may set, and an experiment may sweep (the
            numbers). ``parameters`` finds them, defaults filled in, under the setting
            ``behavior_settings``.
    """

    name: str
    summary: str
    steer: Steer
    fresh_memory: Callable[[int], Any]
    parameters: Callable[[Mapping[str, Any]], Any]
    spawn_radius: float
    circles_landmark: bool = False
    pid_gains: PidGains | None = None
    controller: str = "homing"
    settings: Mapping[str, bool | int | float | str] = field(default_factory=dict)


@dataclass(frozen=True)
class FishParams:
    """Everything a fish's decision depends on besides its memory and what it perceives.

    Attributes:
        behavior: the behaviour family.
        steering: the family's parameters.
        controller: ``homing`` (the research code's) or ``pid``.
        control_period: nominal time between decisions, s; the pid loops use it for a fish's
            first decision, and the real elapsed time after.
        caudal_cap: largest caudal gain of the homing controller.
        pid_gains: gains of the pid loops.
        right_when_ahead: the homing controller turns a target dead ahead, or none, to the
            right pectoral fin, as the study's code did (SPEC §8).
    """

    behavior: Behavior
    steering: Any
    controller: str = "homing"
    control_period: float = 1.0
    caudal_cap: float = 1.0
    pid_gains: PidGains = PidGains()
    right_when_ahead: bool = False

    def __post_init__(self) -> None:
        if self.controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {self.controller!r}")
        if not self.control_period > 0:
            raise ValueError(f"control_period must be positive, got {self.control_period}")


@dataclass(frozen=True)
class FishMemory:
    """What B fish remember between decisions.

    Attributes:
        behavior: the behaviour family's own memory.
        dorsal_on: (B,) the homing controller's dorsal state.
        pid: the pid loops' state.
        last_time: (B,) time of each fish's last decision, s (NaN before the first).
        fins: (B, 4) the fin gains of the last decision, held since.
        effort: (B,) gain-weighted fin beats commanded so far (up to the last decision).
    """

    behavior: Any
    dorsal_on: BoolArray
    pid: PidState
    last_time: FloatArray
    fins: FloatArray
    effort: FloatArray

    @classmethod
    def fresh(cls, params: FishParams, count: int) -> FishMemory:
        """The memory of ``count`` fish that have not decided yet."""
        return cls(
            params.behavior.fresh_memory(count),
            np.zeros(count, dtype=np.bool_),
            PidState.zeros(count),
            np.full(count, np.nan),
            np.zeros((count, 4)),
            np.zeros(count),
        )


class BehaviorError(ValueError):
    """A behaviour's steering failed, or gave what no controller can use (its name, the
    fish's number and what went wrong in the message)."""


def _steer(
    params: FishParams, memory: Any, perception: Perception, inbox: Inbox
) -> tuple[Any, Steering]:
    """The behaviour's steering, checked: a (memory, Steering) pair whose target is (B, 3)
    and finite, its LEDs (B,) and its outbox B fish's — so that a behaviour of one's own
    that errs is named where it errs, not in the controller or a message check after."""
    name, count = params.behavior.name, perception.count

    def wrong(what: str) -> BehaviorError:
        seen = perception.neighbors.shape[1]
        return BehaviorError(
            f"the behaviour {name!r} deciding for {count} fish ({seen} neighbour rows each): {what}"
        )

    try:
        result = params.behavior.steer(memory, perception, inbox, params=params.steering)
    except Exception as error:  # a behaviour's own code
        raise wrong(f"its steer raised {type(error).__name__}: {error}") from error
    if not (isinstance(result, tuple) and len(result) == 2 and isinstance(result[1], Steering)):
        raise wrong(f"its steer must return (memory, Steering), got {type(result).__name__}")
    steering = result[1]
    target = np.asarray(steering.target)
    if target.dtype.kind not in "fiu":
        raise wrong(f"its target must hold numbers, got dtype {target.dtype}")
    if target.shape != (count, 3):
        raise wrong(f"its target must be (B, 3) = ({count}, 3) in m, got shape {target.shape}")
    if not np.isfinite(target).all():
        rows = np.flatnonzero(~np.isfinite(target).all(axis=1))
        raise wrong(f"its target is not finite for fish rows {rows[:10].tolist()}")
    outbox = steering.outbox
    shapes = (
        ("led", np.shape(steering.led), (count,)),
        ("outbox.kind", np.shape(outbox.kind), (count,)),
        ("outbox.values", np.shape(outbox.values), (count, BROADCAST_WIDTH)),
        ("outbox.mask", np.shape(outbox.mask), (count,)),
    )
    for part, shape, expected in shapes:
        if shape != expected:
            raise wrong(f"its {part} must have shape {expected}, got {shape}")
    return result


def decide(
    memory: FishMemory, perception: Perception, inbox: Inbox, *, params: FishParams
) -> tuple[FishMemory, Decision]:
    """One decision of B fish: behaviour → desired motion → controller → fin gains.

    Args:
        memory: what the fish remember (:meth:`FishMemory.fresh` at first).
        perception: what they perceive now.
        inbox: the broadcasts delivered to them since their last decision.
        params: behaviour, controller and their parameters.

    Returns:
        The fish's memory after deciding, and their decision.

    Raises:
        BehaviorError: the behaviour's steering failed, or gave what cannot be used.
    """
    # The fins a fish commanded ran since its last decision: it counts their beats.
    elapsed = perception.time - memory.last_time
    ran = np.where(elapsed > 0, elapsed, 0.0)
    effort = memory.effort + effort_rate(memory.fins) * ran
    perception = dataclasses.replace(perception, effort=effort)
    remembered, steering = _steer(params, memory.behavior, perception, inbox)
    target = steering.target
    if params.controller == "pid":
        # The loops integrate over the real time since a fish's last decision (jittered or
        # late perceptions included); a first decision, or a clock that went back (a new
        # run), counts one nominal period.
        period = np.where(elapsed > 0, elapsed, params.control_period)
        fins, pid_state = pid(target, state=memory.pid, period=period, gains=params.pid_gains)
        dorsal = memory.dorsal_on
    else:
        fins, dorsal = homing(
            target,
            dorsal_on=memory.dorsal_on,
            caudal_cap=params.caudal_cap,
            right_when_ahead=params.right_when_ahead,
        )
        pid_state = memory.pid
    after = FishMemory(
        remembered, dorsal, pid_state, perception.time.astype(np.float64), fins, effort
    )
    return after, Decision(fins, steering.led, steering.outbox)


def take_rows(tree: T, rows: Rows) -> T:
    """The rows ``rows`` of every array in a (nested) frozen dataclass of batched arrays."""
    if isinstance(tree, np.ndarray):
        return tree[rows]  # type: ignore[return-value]
    if dataclasses.is_dataclass(tree) and not isinstance(tree, type):
        changes = {f.name: take_rows(getattr(tree, f.name), rows) for f in dataclasses.fields(tree)}
        return dataclasses.replace(tree, **changes)
    return tree


def put_rows(tree: T, rows: Rows, new: T) -> T:
    """A copy of ``tree`` whose rows ``rows`` are ``new`` (as :func:`take_rows` took them)."""
    if isinstance(tree, np.ndarray):
        copy = tree.copy()
        copy[rows] = new
        return copy
    if dataclasses.is_dataclass(tree) and not isinstance(tree, type):
        changes = {
            f.name: put_rows(getattr(tree, f.name), rows, getattr(new, f.name))
            for f in dataclasses.fields(tree)
        }
        return dataclasses.replace(tree, **changes)
    return tree


def pad_rows(counts: IntArray, stacked: FloatArray) -> tuple[FloatArray, BoolArray]:
    """Rows stacked fish after fish, as the padded batch a decision takes.

    Args:
        counts: (B,) how many rows each fish has.
        stacked: (ΣK, 3) the rows, fish by fish.

    Returns:
        (B, K, 3) with K = max(counts), zero in the padding, and the mask (B, K).
    """
    if counts.size == 1:  # one fish (a robot): nothing to pad
        return stacked[None], np.ones((1, stacked.shape[0]), dtype=np.bool_)
    width = int(counts.max()) if counts.size else 0
    mask: BoolArray = np.arange(width) < counts[:, None]
    padded = np.zeros((counts.size, width, 3))
    _records(padded.reshape(-1, 3))[mask.ravel()] = _records(stacked)
    return padded, mask


def stack_rows(padded: FloatArray, mask: BoolArray) -> FloatArray:
    """The real rows of a padded batch, stacked fish after fish (the inverse of
    :func:`pad_rows`).

    Args:
        padded: (B, K, C) rows, C columns each.
        mask: (B, K) which rows are real.

    Returns:
        (mask.sum(), C), a new array.
    """
    columns = padded.shape[2]
    rows = _records(padded.reshape(-1, columns))[mask.ravel()]
    stacked: FloatArray = rows.view(np.float64).reshape(-1, columns)
    return stacked


def _records(rows: FloatArray) -> NDArray[np.void]:
    """(M, C) rows as (M,) records of C floats: numpy moves a record in one step where a
    boolean index over rows of floats moves float by float (7–12× slower at 1000 fish)."""
    contiguous = np.ascontiguousarray(rows, dtype=np.float64)
    record = np.dtype((np.void, contiguous.shape[1] * contiguous.itemsize))
    records: NDArray[np.void] = contiguous.view(record).reshape(-1)
    return records


Heard = tuple[int, IntArray, FloatArray]
"""One delivered broadcast: (kind index, values (≤ W,), sender position (3,) in the body frame)."""


def inbox_of(heard: list[list[Heard]]) -> Inbox:
    """The inbox of B fish from what each heard, in the order it heard it."""
    count = len(heard)
    width = max((len(rows) for rows in heard), default=0)
    if not width:
        return Inbox.empty(count)
    inbox = Inbox(
        np.zeros((count, width), dtype=np.int64),
        np.zeros((count, width, BROADCAST_WIDTH), dtype=np.int64),
        np.zeros((count, width, 3)),
        np.zeros((count, width), dtype=np.bool_),
    )
    for fish, rows in enumerate(heard):
        for column, (kind, values, sender) in enumerate(rows):
            inbox.kind[fish, column] = kind
            inbox.values[fish, column, : values.shape[0]] = values
            inbox.sender[fish, column] = sender
            inbox.mask[fish, column] = True
    return inbox
