"""Round trips and rejection of malformed input for every message type."""

from __future__ import annotations

import contextlib
import dataclasses
import inspect
import math
import struct
from collections.abc import Callable

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fishswarm.protocols import MessageError, codec, decode, encode
from fishswarm.protocols.checks import MAX_ROWS
from fishswarm.protocols.messages import (
    DARK,
    FLASHING,
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    STEADY,
    Broadcast,
    ChannelReport,
    Command,
    CommandBatch,
    ControlReply,
    ControlRequest,
    Delivery,
    FishAbout,
    FormationFlag,
    Message,
    Perception,
    PerceptionBatch,
    RobotOrder,
    RobotStatus,
    RunSettings,
    Snapshot,
    WorldPulse,
)

EXAMPLES: list[Message] = [
    Perception(3, 7, 7.0, 0.5, np.array([[0.1, 0.2, 0.3], [1.0, -1.0, 0.0]]), np.zeros((0, 3)), 2),
    Command(3, 7, np.array([1.0, 0.0, 0.6, 0.0]), led=True, broadcasts=1),
    PerceptionBatch(
        7,
        7.0,
        np.array([2, 3, 9]),
        np.array([0.5, 0.4, 0.3]),
        np.array([2, 0, 1]),
        np.arange(9.0).reshape(3, 3),
        np.array([0, 1, 0]),
        np.ones((1, 3)),
        np.array([0, 2, 0]),
    ),
    CommandBatch(
        7,
        np.array([2, 3]),
        np.array([[1.0, 0.0, 0.6, 0.0], [0.0, 1.0, 0.0, 0.0]]),
        np.array([True, False]),
        np.array([0, 1]),
    ),
    Broadcast(3, 7, "signal", np.array([2, 0, -5])),
    Broadcast(3, 7, "formation", FormationFlag(1, 4, True, 2, -90_000, 17).values()),
    Delivery(4, 8, "signal", np.array([2]), np.array([0.3, -0.1, 0.0])),
    Snapshot(
        5,
        5.0,
        np.array([0, 1, 4]),
        np.ones((3, 3)),
        np.zeros((3, 3)),
        np.array([0.0, 1.0, -1.0]),
        np.array([2, 2, 1]),
        np.zeros(3, dtype=np.int64),
    ),
    ChannelReport(8, np.array([0, 1]), np.array([1, 0])),
    ControlRequest("status"),
    ControlReply("running", 4, 4.0, 25),
    RobotStatus(
        3, "0.4.0", "dispersion", "swimming", 0.42, np.array([2.0, 0.0, 1.5, 0.0]), True, 51.5, 9.0
    ),
    RobotStatus(4, "0.4.0", "formation", "stranded", 0.1, np.zeros(4), False, None, 0.0, 5, 4, 1),
    RobotOrder("stop"),
    FishAbout(np.array([0, 1, 2]), "dispersion", "0.1.0", 7),
    FishAbout(np.array([4]), "aggregation", "0.1.0", 2, "lennard-jones,homing"),
    FishAbout(np.array([5, 6]), "formation", "0.1.0", 3, "paper", 0.5),
    FishAbout(np.array([7]), "formation", "0.1.0", 3, "paper", 0.5, "01", {"count": "89"}),
    RobotOrder("resume", np.array([2, 5])),
    RobotOrder("formation", np.array([], dtype=np.int64), "column"),
    RobotStatus(
        5, "0.4.0", "formation", "swimming", 0.2, np.zeros(4), True, None, 3.0, formation="column"
    ),
    WorldPulse(2**61 + 5, 12, "paused"),
    RunSettings(
        {"fish": 25, "duration": 15.0, "tank": (1.78, 1.78, 1.17), "model": None, "flags": True}
    ),
    RunSettings({"behavior": "nearest", "behavior_settings": {"distance": 0.3, "mode": "x"}}),
]


@pytest.mark.parametrize("message", EXAMPLES, ids=lambda m: m.type_name)
def test_round_trip(message: Message) -> None:
    assert decode(encode(message), type(message)) == message


def test_decoded_arrays_are_read_only() -> None:
    message = decode(encode(EXAMPLES[0]), Perception)
    with pytest.raises(ValueError, match="read-only"):
        message.neighbors[0, 0] = 1.0


floats = st.floats(allow_nan=False, allow_infinity=False, width=64)


@given(
    neighbors=hnp.arrays(np.float64, st.tuples(st.integers(0, 40), st.just(3)), elements=floats),
    tick=st.integers(0, 2**40),
    depth=floats,
)
def test_perception_round_trip_property(neighbors: np.ndarray, tick: int, depth: float) -> None:
    message = Perception(1, tick, 1.5, depth, neighbors, np.zeros((1, 3)), 0)
    decoded = decode(encode(message), Perception)
    assert decoded == message
    assert decoded.neighbors.dtype == np.float64


@given(data=st.binary(max_size=200))
def test_garbage_never_escapes_as_another_error(data: bytes) -> None:
    with contextlib.suppress(MessageError):
        decode(data)


def _ext_array(values: list[float] | list[int]) -> msgpack.ExtType:
    """The codec's array extension around ``values`` (int64 if all are ints, else float64)."""
    ints = all(isinstance(v, int) for v in values)
    array = np.asarray(values, dtype="<i8" if ints else "<f8")
    header = struct.pack("<BBI", 1 if ints else 0, 1, array.size)
    return msgpack.ExtType(1, header + array.tobytes())


_ARRAYS = st.lists(st.floats(), max_size=3).map(_ext_array) | st.lists(
    st.integers(-(2**63), 2**63 - 1), max_size=3
).map(_ext_array)
_LEAVES = (
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=6)
    | st.binary(max_size=8)
    | _ARRAYS
)
_VALUES = st.recursive(
    _LEAVES,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=8,
)


@st.composite
def _hostile(draw: st.DrawFn) -> bytes:
    """A message's outline — the right keys, a real type name and its field names — with
    anything at all in them."""
    cls = draw(st.sampled_from(sorted(MESSAGE_TYPES.values(), key=lambda c: c.type_name)))
    names = list(inspect.signature(cls).parameters)
    fields = draw(st.dictionaries(st.sampled_from(names), _VALUES, max_size=len(names)))
    version = draw(st.just(SCHEMA_VERSION) | _ARRAYS | _VALUES)
    type_name = draw(st.just(cls.type_name) | _VALUES)
    packed: bytes = msgpack.packb({"v": version, "t": type_name, "f": fields}, use_bin_type=True)
    return packed


@given(payload=_hostile())
def test_hostile_fields_never_escape_as_another_error(payload: bytes) -> None:
    # Whatever a sender puts in a message's fields — arrays for numbers, numbers past int64,
    # an array for the schema version — decoding says MessageError and nothing else.
    with contextlib.suppress(MessageError):
        decode(payload)


def test_a_schema_version_or_counts_meant_to_fool_the_checks_are_rejected() -> None:
    pulse = {"run": 1, "tick": 1, "state": "running"}
    for version in (_ext_array([1.0, 1.0]), _ext_array([]), [1], "1", True):
        payload = msgpack.packb({"v": version, "t": "world_pulse", "f": pulse})
        with pytest.raises(MessageError, match="schema version"):
            decode(payload)
    # Counts that wrap around int64 to the right total: 2^63-1 + 2^63-1 + 2 = 0 rows.
    three = np.zeros(3, dtype=np.int64)
    fields = _perception_batch_fields(
        ids=np.arange(3), depth=np.full(3, 0.5), neighbors=np.zeros((0, 3)),
        neighbor_counts=np.array([2**63 - 1, 2**63 - 1, 2]), landmark_counts=three,
        inbox_counts=three,
    )  # fmt: skip
    with pytest.raises(MessageError, match="neighbor_counts must each be at most the 0 rows"):
        decode(_raw("perception_batch", fields), PerceptionBatch)


DTYPE_CODES = {"<f8": 0, "<i8": 1, "|b1": 2, "<f4": 7}


def _raw(type_name: str, fields: dict[str, object], version: int = 1) -> bytes:
    """Pack a message by hand, bypassing the codec's checks (to build bad ones)."""

    def default(value: object) -> object:
        assert isinstance(value, np.ndarray)
        code = DTYPE_CODES[value.dtype.str]
        header = struct.pack(f"<BB{value.ndim}I", code, value.ndim, *value.shape)
        return msgpack.ExtType(1, header + value.tobytes())

    packed: bytes = msgpack.packb({"v": version, "t": type_name, "f": fields}, default=default)
    return packed


def _command_fields(**overrides: object) -> dict[str, object]:
    fields: dict[str, object] = {
        "fish_id": 1,
        "tick": 2,
        "fins": np.zeros(4),
        "led": True,
        "broadcasts": 0,
    }
    fields.update(overrides)
    return fields


def _perception_fields(**overrides: object) -> dict[str, object]:
    fields: dict[str, object] = {
        "fish_id": 1,
        "tick": 0,
        "time": 0.0,
        "depth": 0.0,
        "neighbors": np.zeros((0, 3)),
        "landmarks": np.zeros((0, 3)),
    }
    fields.update(overrides)
    return fields


@pytest.mark.parametrize(
    ("payload", "reason"),
    [
        (b"\xc1garbage", "not msgpack"),
        (b"", "not msgpack"),
        (msgpack.packb([1, 2, 3]), "expected a map"),
        (_raw("command", _command_fields(), version=99), "schema version 99"),
        (_raw("spaceship", {}), "unknown message type"),
        (_raw("command", _command_fields(tick="seven")), "tick must be an integer"),
        (_raw("command", _command_fields(tick=True)), "tick must be an integer"),
        (_raw("command", _command_fields(tick=-1)), "tick must be in"),
        (_raw("command", _command_fields(fins=np.array([math.nan, 0, 0, 0]))), "finite"),
        (_raw("command", _command_fields(fins=np.zeros(3))), "4 rows"),
        (_raw("command", _command_fields(fins=np.array([2.0, 0, 0, 0]))), r"gains in \[0, 1\]"),
        (_raw("command", _command_fields(fins=np.zeros(4, dtype=np.float32))), "dtype code"),
        (_raw("command", _command_fields(led="yes")), "led must be a bool"),
        (_raw("command", _command_fields(extra=1)), "unexpected keyword"),
        (_raw("command", {"fish_id": 1}), "missing"),
        (
            _raw("perception", _perception_fields(time=math.inf)),
            "time must be finite",
        ),
        (
            _raw("perception", _perception_fields(neighbors=np.zeros((2, 2)))),
            r"shape \(n, 3\)",
        ),
        (
            _raw("perception", _perception_fields(neighbors=np.zeros((MAX_ROWS + 1, 3)))),
            "exceeds",
        ),
        (_raw("perception", _perception_fields(run=-3)), "run must be in"),
        (
            _raw(
                "channel_report",
                {"tick": 1, "ids": np.array([0, 1]), "inbox_counts": np.array([2, -1])},
            ),
            "inbox_counts must be in",
        ),
        (
            _raw(
                "channel_report",
                {"tick": 1, "ids": np.array([1, 0]), "inbox_counts": np.array([0, 0])},
            ),
            "ascending",
        ),
        (
            _raw("broadcast", {"sender_id": 1, "tick": 0, "kind": "gossip", "values": np.zeros(1)}),
            "kind must be one of",
        ),
        (
            _raw(
                "broadcast",
                {"sender_id": 1, "tick": 0, "kind": "signal", "values": np.zeros(9, np.int64)},
            ),
            "at most 8 numbers",
        ),
        (
            _raw(
                "broadcast",
                {"sender_id": 1, "tick": 0, "kind": "signal", "values": np.array([0.5])},
            ),
            "integer array",
        ),
        (
            _raw(
                "broadcast",
                {"sender_id": 1, "tick": 0, "kind": "formation", "values": np.array([1, 2])},
            ),
            "a formation flag has 6 to 8 numbers",
        ),
        (
            _raw(
                "broadcast",
                {
                    "sender_id": 1,
                    "tick": 0,
                    "kind": "formation",
                    "values": np.array([99, 0, 1, 0, 0, 0]),
                },
            ),
            "shape must be in",
        ),
    ],
)
def test_malformed_input_is_rejected_with_reason(payload: bytes, reason: str) -> None:
    with pytest.raises(MessageError, match=reason):
        decode(payload)


def _perception_batch_fields(**overrides: object) -> dict[str, object]:
    fields: dict[str, object] = {
        "tick": 1,
        "time": 1.0,
        "ids": np.array([0, 1]),
        "depth": np.array([0.5, 0.5]),
        "neighbor_counts": np.array([1, 1]),
        "neighbors": np.zeros((2, 3)),
        "landmark_counts": np.array([0, 0]),
        "landmarks": np.zeros((0, 3)),
        "inbox_counts": np.array([0, 0]),
    }
    fields.update(overrides)
    return fields


def _command_batch_fields(**overrides: object) -> dict[str, object]:
    fields: dict[str, object] = {
        "tick": 1,
        "ids": np.array([0, 1]),
        "fins": np.zeros((2, 4)),
        "led": np.array([True, True]),
        "broadcasts": np.array([0, 0]),
    }
    fields.update(overrides)
    return fields


@pytest.mark.parametrize(
    ("payload", "expected", "reason"),
    [
        (_raw("perception_batch", _perception_batch_fields()), CommandBatch, "expected a command"),
        (
            _raw("perception_batch", _perception_batch_fields(neighbor_counts=np.array([1, 2]))),
            PerceptionBatch,
            "add up to 3, but neighbors has 2 rows",
        ),
        (
            _raw("perception_batch", _perception_batch_fields(neighbor_counts=np.array([3, -1]))),
            PerceptionBatch,
            "non-negative",
        ),
        (
            _raw("perception_batch", _perception_batch_fields(ids=np.array([1, 1]))),
            PerceptionBatch,
            "strictly ascending",
        ),
        (
            _raw("perception_batch", _perception_batch_fields(depth=np.array([0.5]))),
            PerceptionBatch,
            "depth must have 2 rows",
        ),
        (
            _raw("command_batch", _command_batch_fields(led=np.array([1.0, 0.0]))),
            CommandBatch,
            "led must be a boolean array",
        ),
        (
            _raw("command_batch", _command_batch_fields(fins=np.full((2, 4), math.nan))),
            CommandBatch,
            "finite",
        ),
        (
            _raw("command_batch", _command_batch_fields(fins=np.zeros((2, 3)))),
            CommandBatch,
            r"shape \(n, 4\)",
        ),
        (
            _raw("command_batch", _command_batch_fields(broadcasts=np.array([0, -2]))),
            CommandBatch,
            r"broadcasts must be in",
        ),
    ],
)
def test_malformed_batches_are_rejected_with_reason(
    payload: bytes, expected: type[Message], reason: str
) -> None:
    with pytest.raises(MessageError, match=reason):
        decode(payload, expected)


def test_truncated_array_is_rejected() -> None:
    good = encode(EXAMPLES[1])
    with pytest.raises(MessageError):
        decode(good[:-5], Command)


def test_wrong_type_for_key_is_rejected() -> None:
    with pytest.raises(MessageError, match="expected a command message, got broadcast"):
        decode(encode(Broadcast(1, 1, "signal", np.zeros(0, np.int64))), Command)


def test_bad_messages_cannot_be_built() -> None:
    with pytest.raises(ValueError, match="ascending"):
        Snapshot(
            0,
            0.0,
            np.array([2, 1]),
            np.zeros((2, 3)),
            np.zeros((2, 3)),
            np.zeros(2),
            np.zeros(2, dtype=np.int64),
            np.zeros(2, dtype=np.int64),
        )
    with pytest.raises(ValueError, match="action must be one of"):
        ControlRequest("explode")
    with pytest.raises(TypeError, match="integer array"):
        ChannelReport(0, np.array([0.5]), np.array([1]))
    with pytest.raises(ValueError, match="state must be one of"):
        RobotStatus(1, "0.4.0", "dispersion", "dancing", 0.0, np.zeros(4), True, None, 0.0)
    with pytest.raises(ValueError, match="fin_frequencies must have 4 rows"):
        RobotStatus(1, "0.4.0", "dispersion", "swimming", 0.0, np.zeros(3), True, None, 0.0)
    with pytest.raises(ValueError, match="action must be one of"):
        RobotOrder("explode")
    with pytest.raises(ValueError, match="at least one fish"):
        FishAbout(np.zeros(0, dtype=np.int64), "dispersion", "0.1.0")
    with pytest.raises(ValueError, match=r"control_period must be in \[0.0, inf\]"):
        FishAbout(np.array([1]), "dispersion", "0.1.0", 0, "paper", -1.0)
    with pytest.raises(ValueError, match="control_period must be finite"):
        FishAbout(np.array([1]), "dispersion", "0.1.0", 0, "paper", math.nan)
    with pytest.raises(TypeError, match="parts must be a table, got list"):
        FishAbout(np.array([1]), "dispersion", "0.1.0", parts=["count"])  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="part count must be a string, got int"):
        FishAbout(np.array([1]), "dispersion", "0.1.0", parts={"count": 5})  # type: ignore[dict-item]
    with pytest.raises(ValueError, match="a part's name must have 1 to 64 characters, got 65"):
        FishAbout(np.array([1]), "dispersion", "0.1.0", parts={"x" * 65: "01234567"})
    with pytest.raises(ValueError, match="parts must have at most 128 entries"):
        FishAbout(np.array([1]), "dispersion", "0.1.0", parts={str(i): "0" for i in range(129)})
    with pytest.raises(ValueError, match="ascending"):
        RobotOrder("stop", np.array([3, 1]))
    with pytest.raises(ValueError, match="state must be one of"):
        WorldPulse(1, 0, "computing")


def _snapshot(**overrides: object) -> Snapshot:
    fields: dict[str, object] = {
        "tick": 1, "time": 1.0, "ids": np.array([0, 1]), "position": np.zeros((2, 3)),
        "velocity": np.zeros((2, 3)), "yaw": np.zeros(2),
        "neighbors_seen": np.zeros(2, dtype=np.int64),
        "broadcasts": np.zeros(2, dtype=np.int64),
    }  # fmt: skip
    fields.update(overrides)
    return Snapshot(**fields)  # type: ignore[arg-type]


def _perception(**overrides: object) -> Perception:
    fields: dict[str, object] = {
        "fish_id": 0, "tick": 1, "time": 1.0, "depth": 0.2, "neighbors": np.zeros((0, 3)),
        "landmarks": np.zeros((0, 3)),
    }  # fmt: skip
    fields.update(overrides)
    return Perception(**fields)  # type: ignore[arg-type]


def _robot_status(**overrides: object) -> RobotStatus:
    fields: dict[str, object] = {
        "robot_id": 1, "version": "0.4.0", "behavior": "dispersion", "state": "swimming",
        "depth": 0.2, "fin_frequencies": np.zeros(4), "link": True, "cpu_temperature": 50.0,
        "uptime": 3.0,
    }  # fmt: skip
    fields.update(overrides)
    return RobotStatus(**fields)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("build", "reason"),
    [
        (lambda: _snapshot(ids=np.array([-1, 0])), "ids must be non-negative"),
        (lambda: _snapshot(position=np.array([[0, 0, np.inf], [0, 0, 0]])), "finite numbers"),
        (lambda: _snapshot(position=np.array([[0, 0, -np.inf], [0, 0, 0]])), "finite numbers"),
        (lambda: _snapshot(effort=np.array([1.0, -0.5])), "effort must not be negative"),
        (lambda: ControlReply("", 0, 0.0, 0), "state must have 1 to"),
        (lambda: ControlReply("dancing", 0, 0.0, 0), "state must be one of"),
        (lambda: ControlRequest("stop", formation="pyramid"), "only one, names a formation"),
        (
            lambda: CommandBatch(
                1,
                np.array([0]),
                np.array([[0.5, -0.1, 0, 0]]),
                np.array([False]),
                np.array([0]),
            ),
            "fins must be gains in",
        ),
        (lambda: _perception(heading=7.0), "heading must be in"),
        (lambda: _perception(time=-1.0), "time must be in"),
        (lambda: FormationFlag(0, 0, True, 0, 200_000, 0), "heading_mdeg must be in"),
        (lambda: FormationFlag(0, 0, True, 0, -180_001, 0), "heading_mdeg must be in"),
        (lambda: FormationFlag.from_values(np.array([1, 0, 2, 0, 0, 0])), "joined must be 0"),
        (
            lambda: Delivery(1, 1, "signal", np.array([1]), np.array([0.1, 0.2])),
            "sender_position must have 3 rows",
        ),
        (lambda: RunSettings([("fish", 25)]), "scenario must be a table"),  # type: ignore[arg-type]
        (lambda: RunSettings({"": 1}), "a setting's name must have 1 to"),
        (lambda: RunSettings({"duration": math.nan}), "duration must be finite"),
        (lambda: RunSettings({"seed": 2**63}), "seed must be in"),
        (lambda: RunSettings({"model": "m" * 4097}), "model must have at most 4096"),
        (lambda: RunSettings({"tank": [1.0, [2.0]]}), "tank must be a list of plain values"),
        (lambda: RunSettings({"tank": [0.0] * 65}), "tank must have at most 64 values"),
        (lambda: RunSettings({"flow": object()}), "flow must be plain data, got object"),
        (
            lambda: RunSettings({"behavior_settings": {"gain": {"x": 1.0}}}),
            "behavior_settings must be a table of plain values, not of lists or tables",
        ),
        (
            lambda: RunSettings({"behavior_settings": {"gain": [1.0]}}),
            "behavior_settings must be a table of plain values, not of lists or tables",
        ),
        (
            lambda: RunSettings({"behavior_settings": {"": 1.0}}),
            "a name in behavior_settings must have 1 to",
        ),
        (
            lambda: RunSettings({"behavior_settings": {"gain": math.inf}}),
            "behavior_settings.gain must be finite",
        ),
        (
            lambda: RunSettings({"behavior_settings": {f"s{i}": 1 for i in range(65)}}),
            "behavior_settings must have at most 64 entries",
        ),
        (lambda: RunSettings({f"s{n}": 0 for n in range(201)}), "at most 200 settings"),
        (lambda: _perception(heading=-7.0), "heading must be in"),
        (lambda: _perception(inbox_count=MAX_ROWS + 1), "inbox_count must be in"),
        (lambda: _perception(formation="blob"), "formation must be one of"),
        (lambda: Command(0, 1, np.array([0.5, -0.1, 0.0, 0.0])), "fins must be gains in"),
        (
            lambda: PerceptionBatch(
                **_perception_batch_fields(inbox_counts=np.array([0, MAX_ROWS + 1]))  # type: ignore[arg-type]
            ),
            "inbox_counts must be in",
        ),
        (
            lambda: PerceptionBatch(
                **_perception_batch_fields(heading=np.array([0.0, -7.0]))  # type: ignore[arg-type]
            ),
            "heading must be in",
        ),
        (
            lambda: CommandBatch(
                **_command_batch_fields(broadcasts=np.array([0, MAX_ROWS + 1]))  # type: ignore[arg-type]
            ),
            "broadcasts must be in",
        ),
        (lambda: FormationFlag(0, 0, 1, 0, 0, 0), "joined must be a bool, got int"),  # type: ignore[arg-type]
        (
            lambda: FormationFlag.from_values(np.array([1, 0, 1, 0, 0])),
            "a formation flag has 6 to 8 numbers, got 5",
        ),
        (lambda: ControlRequest("formation"), "only one, names a formation"),
        (lambda: ControlRequest("formation", "blob"), "formation must be one of"),
        (lambda: ControlReply("running", 0, 0.0, MAX_ROWS + 1), "live_fish must be in"),
        (
            lambda: _robot_status(fin_frequencies=np.array([2.0, -0.5, 0.0, 0.0])),
            "fin_frequencies must not be negative",
        ),
        (lambda: _robot_status(cpu_temperature=250.0), "cpu_temperature must be in"),
        (lambda: _robot_status(cpu_temperature=-150.0), "cpu_temperature must be in"),
        (lambda: _robot_status(link=1), "link must be a bool, got int"),
        (lambda: _robot_status(uptime=-1.0), "uptime must be in"),
        (lambda: RunSettings({"offset": -(2**62) - 1}), "offset must be in"),
    ],
)
def test_each_field_check_refuses_what_it_is_there_for(
    build: Callable[[], object], reason: str
) -> None:
    with pytest.raises((ValueError, TypeError), match=reason):
        build()


def test_a_message_with_a_key_beyond_v_t_f_is_not_a_fishswarm_message() -> None:
    fields = {"action": "stop", "formation": None}
    good = msgpack.packb({"v": SCHEMA_VERSION, "t": "control_request", "f": fields})
    assert decode(good, ControlRequest).action == "stop"
    extra = msgpack.packb({"v": SCHEMA_VERSION, "t": "control_request", "f": fields, "x": 1})
    with pytest.raises(MessageError, match="expected a map with keys v, t, f"):
        decode(extra, ControlRequest)


def test_a_robot_order_addresses_its_robots_or_all() -> None:
    assert RobotOrder("stop").addresses(7)
    assert RobotOrder("stop", np.array([2, 7])).addresses(7)
    assert not RobotOrder("stop", np.array([2, 8])).addresses(7)


def test_a_formation_flag_round_trips_through_a_broadcast() -> None:
    flag = FormationFlag(7, -1, False, 3, 179_999, 2**40)
    message = decode(encode(Broadcast(2, 5, "formation", flag.values())), Broadcast)
    assert FormationFlag.from_values(message.values) == flag
    # Effort and a swap request travel too; a swap with slot 0 is not "none" on the wire.
    tired = FormationFlag(1, 0, True, 0, 0, 9, effort=412, swap=0)
    assert tired.values().tolist() == [1, 0, 1, 0, 0, 9, 412, 1]
    assert FormationFlag.from_values(tired.values()) == tired
    # A flag of six numbers (before effort sharing), even zero-padded, asks for no swap.
    older = np.array([1, 2, 1, 1, 0, 3, 0, 0])
    assert FormationFlag.from_values(older[:6]) == FormationFlag.from_values(older)
    assert FormationFlag.from_values(older).swap == -1
    with pytest.raises(ValueError, match="swap must be in"):
        FormationFlag(1, 0, True, 0, 0, 9, swap=-2)


def test_messages_that_differ_only_in_an_array_are_not_equal() -> None:
    near = _perception(neighbors=np.array([[0.1, 0.2, 0.3]]))
    assert near == _perception(neighbors=np.array([[0.1, 0.2, 0.3]]))
    assert near != _perception(neighbors=np.array([[0.1, 0.2, 0.4]]))
    assert Command(1, 2, np.array([1.0, 0.0, 0.0, 0.0])) != Command(1, 2, np.zeros(4))


def test_a_flag_of_seven_numbers_carries_its_effort_and_asks_for_no_swap() -> None:
    flag = FormationFlag.from_values(np.array([1, 2, 1, 1, 0, 3, 412]))
    assert flag == FormationFlag(1, 2, True, 1, 0, 3, effort=412, swap=-1)


def test_a_fish_that_has_not_tired_yet_has_effort_zero() -> None:
    snapshot = _snapshot(effort=np.array([0.0, 2.5]))
    assert snapshot.effort is not None
    assert snapshot.effort.tolist() == [0.0, 2.5]


def test_settings_may_be_negative_integers_down_to_minus_two_to_the_62() -> None:
    settings = RunSettings({"offset": -3, "floor": -(2**62)})
    assert decode(encode(settings), RunSettings).scenario == {"offset": -3, "floor": -(2**62)}


def test_fields_added_later_stay_off_the_wire_while_unset() -> None:
    """A stop order and a robot's status without a formation carry only the fields the
    first version of each had, so that a robot or base station not yet upgraded still
    reads them; with a formation, the field goes along and comes back."""
    import msgpack

    def wire_fields(message: Message) -> set[str]:
        return set(msgpack.unpackb(encode(message), raw=False, ext_hook=lambda c, d: d)["f"])

    stop = RobotOrder("stop")
    assert wire_fields(stop) == {"action", "robot_ids"} and decode(encode(stop)) == stop
    status = RobotStatus(3, "1.0", "dispersion", "swimming", 0.4, np.zeros(4), True, None, 9.0)
    assert "formation" not in wire_fields(status) and decode(encode(status)) == status
    ordered = RobotOrder("formation", formation="column")
    assert "formation" in wire_fields(ordered) and decode(encode(ordered)) == ordered
    # The runs of broadcasts and deliveries, and what a fish says of its period and
    # parameters, came later too.
    sent = Broadcast(1, 2, "signal", np.array([3]))
    assert wire_fields(sent) == {"sender_id", "tick", "kind", "values"}
    named = Broadcast(1, 2, "signal", np.array([3]), 77)
    assert "run" in wire_fields(named) and decode(encode(named), Broadcast).run == 77
    heard = Delivery(1, 2, "signal", np.array([3]), np.zeros(3))
    assert "run" not in wire_fields(heard) and decode(encode(heard)) == heard
    about = FishAbout(np.array([4]), "formation", "0.1.0")
    assert wire_fields(about) == {"ids", "behavior", "version", "run", "rules"}
    told = FishAbout(np.array([4]), "formation", "0.1.0", 1, "paper", 0.5, "0123456789abcdef")
    assert "parts" not in wire_fields(told) and decode(encode(told), FishAbout) == told
    parted = FishAbout(np.array([4]), "formation", "0.1.0", 1, "paper", 0.5, "01", {"a": "b"})
    assert "parts" in wire_fields(parted) and decode(encode(parted), FishAbout) == parted
    assert decode(encode(parted), FishAbout) != told


def test_which_leds_flash_stays_off_the_wire_until_a_robot_flashes() -> None:
    """A command carries ``flashing``, a snapshot ``lights``, only when a robot flashes its
    LEDs (its formation flag by light) or darkens them: every other run sends what it sent
    before."""
    import msgpack

    def wire_fields(message: Message) -> set[str]:
        return set(msgpack.unpackb(encode(message), raw=False, ext_hook=lambda c, d: d)["f"])

    steady = Command(2, 5, np.zeros(4))
    assert "flashing" not in wire_fields(steady) and decode(encode(steady)) == steady
    flashing = Command(2, 5, np.zeros(4), flashing=True)
    assert "flashing" in wire_fields(flashing)
    assert decode(encode(flashing), Command).flashing is True
    assert "lights" not in wire_fields(_snapshot())
    snapshot = _snapshot(lights=np.array([STEADY, FLASHING]))
    lights = decode(encode(snapshot), Snapshot).lights
    assert lights is not None and lights.tolist() == [STEADY, FLASHING]
    with pytest.raises(ValueError, match="lights must have 2 rows"):
        _snapshot(lights=np.array([DARK]))
    with pytest.raises(ValueError, match="lights must be indices into"):
        _snapshot(lights=np.array([0, 3]))
    with pytest.raises(ValueError, match="lights must be indices into"):
        _snapshot(lights=np.array([-1, 0]))
    with pytest.raises(TypeError, match="flashing must be a bool or None"):
        Command(2, 5, np.zeros(4), flashing=1)  # type: ignore[arg-type]
    # A robot's status: whether it flashes and how many flags it saw, once it has.
    quiet = RobotStatus(3, "1.0", "formation", "swimming", 0.4, np.zeros(4), True, None, 9.0)
    assert not {"flashing", "flags_seen"} & wire_fields(quiet)
    told = dataclasses.replace(quiet, flashing=True, flags_seen=4)
    assert {"flashing", "flags_seen"} <= wire_fields(told) and decode(encode(told)) == told
    with pytest.raises(ValueError, match="flags_seen"):
        dataclasses.replace(quiet, flags_seen=-1)
    with pytest.raises(TypeError, match="flashing must be a bool or None"):
        dataclasses.replace(quiet, flashing=1)  # type: ignore[arg-type]


def test_arrays_of_the_other_byte_order_go_on_the_wire_little_endian() -> None:
    # A message's own arrays are native after its checks; the codec's hook still takes any.
    big = np.array([1.5, -2.0, 3.25], dtype=">f8")
    ext = codec._default(big)
    assert isinstance(ext, msgpack.ExtType)
    assert struct.unpack("<BBI", ext.data[:6]) == (0, 1, 3)  # float64, one dimension of 3
    assert ext.data[6:] == np.array([1.5, -2.0, 3.25], dtype="<f8").tobytes()
    np.testing.assert_array_equal(codec._ext_hook(ext.code, ext.data), big)
    swapped_ints = codec._default(np.array([[3], [4]], dtype=">i8"))
    assert isinstance(swapped_ints, msgpack.ExtType)
    np.testing.assert_array_equal(codec._ext_hook(swapped_ints.code, swapped_ints.data), [[3], [4]])
    with pytest.raises(TypeError, match="cannot encode an array of dtype int32"):
        codec._default(np.array([1], dtype=np.int32))
