"""The msgpack codec of fishswarm messages, numpy arrays carried as raw bytes.

A message goes over the wire as a msgpack map ``{"v": version, "t": type, "f": fields}``.
Numpy arrays travel as msgpack extension type 1 holding ``[dtype, shape, bytes]``: a copy of
memory, not a list of Python numbers (DESIGN.md §4: ``tolist()`` is 100× slower).
"""

from __future__ import annotations

from typing import Any, TypeVar

import msgpack
import numpy as np

from fishswarm.protocols.messages import (
    MAX_ROWS,
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    Message,
    fields_of,
)

MAX_MESSAGE_BYTES = 16 * 1024 * 1024
_ARRAY_EXT = 1
_DTYPES = frozenset({"<f8", "<i8", "|b1"})

M = TypeVar("M", bound=Message)


class MessageError(ValueError):
    """A payload is not a valid fishswarm message (garbage, wrong types, NaN, size, version)."""


def _default(value: object) -> object:
    if isinstance(value, np.ndarray):
        array = np.ascontiguousarray(value)
        header = msgpack.packb([array.dtype.str, list(array.shape)])
        return msgpack.ExtType(_ARRAY_EXT, header + array.tobytes())
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if isinstance(value, np.bool_):
        return bool(value)
    raise TypeError(f"cannot encode {type(value).__name__}")


def _ext_hook(code: int, data: bytes) -> np.ndarray[Any, Any]:
    if code != _ARRAY_EXT:
        raise MessageError(f"unknown msgpack extension type {code}")
    unpacker = msgpack.Unpacker(max_buffer_size=len(data) + 1)
    unpacker.feed(data)
    try:
        dtype, shape = next(unpacker)
    except (StopIteration, ValueError, TypeError) as error:
        raise MessageError(f"malformed array header: {error}") from None
    if dtype not in _DTYPES:
        raise MessageError(f"array dtype {dtype!r} is not allowed; use one of {sorted(_DTYPES)}")
    if (
        not isinstance(shape, list)
        or len(shape) > 2
        or not all(isinstance(n, int) and 0 <= n <= MAX_ROWS for n in shape)
    ):
        raise MessageError(f"array shape {shape!r} is not a list of at most 2 sizes <= {MAX_ROWS}")
    body = data[unpacker.tell() :]
    expected = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    if len(body) != expected:
        raise MessageError(f"array of shape {shape} {dtype} needs {expected} bytes, got {len(body)}")
    return np.frombuffer(body, dtype=dtype).reshape(shape)


def encode(message: Message) -> bytes:
    """Encode a message to bytes for the wire."""
    packed: bytes = msgpack.packb(
        {"v": SCHEMA_VERSION, "t": message.type_name, "f": fields_of(message)},
        default=_default,
        use_bin_type=True,
    )
    return packed


def decode(payload: bytes | bytearray | memoryview, expected: type[M] | None = None) -> M:
    """Decode and validate a message.

    Args:
        payload: bytes from the wire.
        expected: the message type this key carries; anything else is rejected.

    Returns:
        The message, validated on construction.

    Raises:
        MessageError: the payload is not a valid message of the expected type, with the reason.
    """
    if len(payload) > MAX_MESSAGE_BYTES:
        raise MessageError(f"message of {len(payload)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        raw = msgpack.unpackb(
            payload, ext_hook=_ext_hook, raw=False, strict_map_key=True, use_list=True
        )
    except MessageError:
        raise
    except Exception as error:
        raise MessageError(f"not msgpack: {type(error).__name__}: {error}") from None
    if not isinstance(raw, dict) or set(raw) != {"v", "t", "f"}:
        raise MessageError("not a fishswarm message: expected a map with keys v, t, f")
    if raw["v"] != SCHEMA_VERSION:
        raise MessageError(
            f"schema version {raw['v']!r} is not supported (this fishswarm speaks {SCHEMA_VERSION})"
        )
    cls = MESSAGE_TYPES.get(raw["t"]) if isinstance(raw["t"], str) else None
    if cls is None:
        raise MessageError(f"unknown message type {raw['t']!r}")
    if expected is not None and cls is not expected:
        raise MessageError(f"expected a {expected.type_name} message, got {cls.type_name}")
    fields = raw["f"]
    if not isinstance(fields, dict):
        raise MessageError("message fields must be a map")
    try:
        return cls(**fields)  # type: ignore[return-value]
    except (TypeError, ValueError) as error:
        raise MessageError(f"invalid {cls.type_name}: {error}") from None
