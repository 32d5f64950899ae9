"""A message encoded with ``reuse=True`` is handed, not decoded, to a reader in the same
process — only for its very bytes, and only when that gives what decoding would."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fishswarm.protocols import MessageError, codec, decode, encode
from fishswarm.protocols.messages import (
    CommandBatch,
    Message,
    PerceptionBatch,
    RunSettings,
    Snapshot,
    fields_of,
)


@pytest.fixture(autouse=True)
def _nothing_kept() -> Iterator[None]:
    """Each test starts with no message kept, and leaves none to the next."""
    codec._reused.clear()
    yield
    codec._reused.clear()


def _snapshot(tick: int = 5, position: np.ndarray | None = None) -> Snapshot:
    return Snapshot(
        tick,
        5.0,
        np.array([0, 1, 4]),
        np.arange(9.0).reshape(3, 3) if position is None else position,
        np.zeros((3, 3)),
        np.array([0.0, 1.0, -1.0]),
        np.array([2, 2, 1]),
        np.zeros(3, dtype=np.int64),
        formation="column",
    )


def _decoded_in_full(payload: bytes, kind: type[Message]) -> Message:
    """What decoding the bytes gives, with nothing kept to hand over instead."""
    kept = dict(codec._reused)
    codec._reused.clear()
    try:
        return decode(payload, kind)
    finally:
        codec._reused.update(kept)


def _assert_alike(kept: Message, decoded: Message) -> None:
    """Equal field by field, of the same types, dtypes and shapes, and read-only arrays."""
    assert kept == decoded
    for (name, one), (_, other) in zip(
        fields_of(kept).items(), fields_of(decoded).items(), strict=True
    ):
        assert type(one) is type(other), name
        if isinstance(one, np.ndarray):
            assert (one.dtype, one.shape) == (other.dtype, other.shape), name
            assert not one.flags.writeable


def test_a_reader_of_the_very_bytes_gets_the_message_itself() -> None:
    snapshot = _snapshot()
    payload = encode(snapshot, reuse=True)
    received = bytes(bytearray(payload))  # a copy, as a subscriber gets from Zenoh
    assert received is not payload
    assert decode(received, Snapshot) is snapshot
    decoded = _decoded_in_full(payload, Snapshot)
    assert decoded is not snapshot
    _assert_alike(snapshot, decoded)
    assert decode(received, Snapshot) is snapshot  # still kept after the full decode


def test_only_bytes_are_looked_up() -> None:
    snapshot = _snapshot()
    payload = encode(snapshot, reuse=True)
    for other in (bytearray(payload), memoryview(payload)):
        decoded = decode(other, Snapshot)
        assert decoded is not snapshot
        assert decoded == snapshot


def test_without_reuse_every_reader_decodes_its_own() -> None:
    snapshot = _snapshot()
    payload = encode(snapshot)
    decoded = decode(payload, Snapshot)
    assert decoded is not snapshot
    assert decoded == snapshot


def test_other_bytes_of_the_same_length_and_type_are_decoded() -> None:
    encode(_snapshot(tick=5), reuse=True)
    later = encode(_snapshot(tick=6))
    assert len(later) == len(encode(_snapshot(tick=5)))
    assert decode(later, Snapshot).tick == 6


def test_the_bytes_read_as_another_type_are_refused_as_before() -> None:
    payload = encode(_snapshot(), reuse=True)
    with pytest.raises(MessageError, match="expected a command_batch message, got snapshot"):
        decode(payload, CommandBatch)


def test_bytes_beyond_the_size_limit_are_refused_even_when_kept(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    payload = encode(_snapshot(), reuse=True)
    monkeypatch.setattr(codec, "MAX_MESSAGE_BYTES", len(payload) - 1)
    with pytest.raises(MessageError, match="exceeds"):
        decode(payload, Snapshot)


def test_a_message_built_from_arrays_others_can_change_is_kept_with_its_own_copy() -> None:
    buffer = np.arange(9.0)
    view = buffer.reshape(3, 3)
    view.setflags(write=False)  # read-only itself, but its memory can still change
    snapshot = _snapshot(position=view)
    payload = encode(snapshot, reuse=True)
    buffer[0] = 100.0  # nothing the message or a reader of it sees: the bytes say 0
    assert decode(payload, Snapshot) is snapshot
    assert snapshot.position[0, 0] == 0.0
    with pytest.raises(ValueError, match="WRITEABLE"):
        snapshot.position.setflags(write=True)  # a reader cannot change it for the others


def _view_of_writable() -> np.ndarray:
    view = np.arange(6.0).reshape(2, 3)
    view.setflags(write=False)
    return view


def _owned_read_only() -> np.ndarray:
    owned = np.arange(6.0)
    owned.setflags(write=False)  # kept read-only by whoever holds it, as a message's arrays
    return owned


def _on_a_bytearray() -> np.ndarray:
    array = np.frombuffer(bytearray(48), dtype=np.float64)
    array.setflags(write=False)  # the bytearray itself can still change
    return array


def _on_bytes(dtype: str = "<f8") -> np.ndarray:
    return np.frombuffer(bytes(48), dtype=dtype)


@pytest.mark.parametrize(
    ("value", "kept"),
    [
        (5, True),
        (5.0, True),
        ("column", True),
        (None, True),
        (True, True),
        (np.int64(5), False),  # decodes to int
        (np.float64(5.0), False),  # a float, but decodes to a plain one
        (_on_bytes(), True),
        (_on_bytes().reshape(2, 3)[:, 1:], False),  # not C-ordered, as no decoded array is
        (_on_bytes("<i8"), True),
        (_on_bytes("<q"), False),  # longlong: equal to int64, but not by name
        (_on_bytes(">f8"), False),
        (_view_of_writable(), False),
        (_owned_read_only(), True),
        (_owned_read_only()[::2], False),  # not C-ordered
        (_on_a_bytearray(), False),
        (np.frombuffer(memoryview(bytes(48)), dtype=np.float64), False),
        ((1, 2), False),
        ({"fish": 25}, False),
    ],
)
def test_what_decodes_to_itself(value: object, kept: bool) -> None:
    assert codec._decodes_to_itself(value) is kept


def test_a_message_with_numpy_numbers_is_decoded_to_python_ones() -> None:
    for snapshot in (
        _snapshot(tick=np.int64(5)),  # type: ignore[arg-type]
        dataclasses.replace(_snapshot(), time=np.float64(5.0)),
    ):
        payload = encode(snapshot, reuse=True)
        decoded = decode(payload, Snapshot)
        assert decoded is not snapshot
        assert (type(decoded.tick), type(decoded.time)) == (int, float)


def test_a_message_with_a_map_is_decoded() -> None:
    settings = RunSettings({"fish": 25, "tank": (1.78, 1.78, 1.17)})
    decoded = decode(encode(settings, reuse=True), RunSettings)
    assert decoded is not settings
    assert decoded == RunSettings({"fish": 25, "tank": [1.78, 1.78, 1.17]})


def test_the_last_few_of_a_type_are_kept() -> None:
    snapshots = [_snapshot(tick=tick) for tick in range(codec.REUSED_PER_TYPE + 1)]
    payloads = [encode(snapshot, reuse=True) for snapshot in snapshots]
    assert decode(payloads[0], Snapshot) is not snapshots[0]
    assert decode(payloads[0], Snapshot) == snapshots[0]
    for snapshot, payload in zip(snapshots[1:], payloads[1:], strict=True):
        assert decode(payload, Snapshot) is snapshot


floats = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def _batches(draw: st.DrawFn) -> PerceptionBatch:
    """A perception batch of up to 6 fish, with arrays as the world builds them."""
    fish = draw(st.integers(0, 6))
    counts = draw(hnp.arrays(np.int64, fish, elements=st.integers(0, 4)))
    neighbors = draw(hnp.arrays(np.float64, (int(counts.sum()), 3), elements=floats))
    ids = np.array(sorted(draw(st.sets(st.integers(0, 10_000), min_size=fish, max_size=fish))))
    heading = draw(st.none() | hnp.arrays(np.float64, fish, elements=st.floats(-6.0, 6.0)))
    return PerceptionBatch(
        draw(st.integers(0, 2**40)),
        draw(st.floats(0, 1e9)),
        ids.astype(np.int64),
        draw(hnp.arrays(np.float64, fish, elements=st.floats(0, 10))),
        counts,
        neighbors,
        np.zeros(fish, dtype=np.int64),
        np.zeros((0, 3)),
        draw(hnp.arrays(np.int64, fish, elements=st.integers(0, 3))),
        draw(st.integers(0, 2**40)),
        heading,
        draw(st.none() | st.sampled_from(["column", "pyramid"])),
    )


@given(batch=_batches())
def test_a_kept_batch_is_what_decoding_its_bytes_gives(batch: PerceptionBatch) -> None:
    payload = encode(batch, reuse=True)
    assert decode(bytes(bytearray(payload)), PerceptionBatch) is batch
    decoded = _decoded_in_full(payload, PerceptionBatch)
    _assert_alike(batch, decoded)
    assert encode(decoded) == payload


def test_a_kept_command_batch_is_what_decoding_gives() -> None:
    batch = CommandBatch(
        7,
        np.array([2, 3]),
        np.array([[1.0, 0.0, 0.6, 0.0], [0.0, 1.0, 0.0, 0.0]]),
        np.array([True, False]),
        np.array([0, 1]),
    )
    payload = encode(batch, reuse=True)
    assert decode(payload, CommandBatch) is batch
    _assert_alike(batch, _decoded_in_full(payload, CommandBatch))
    assert dataclasses.replace(batch, tick=8) != decode(payload, CommandBatch)
