"""The msgpack codec of fishswarm messages, numpy arrays carried as raw bytes.

A message goes over the wire as a msgpack map ``{"v": version, "t": type, "f": fields}``.
Numpy arrays travel as msgpack extension type 1: a header of one byte for the dtype
(0 = little-endian float64, 1 = int64, 2 = bool), one byte for the number of dimensions and a
little-endian uint32 per dimension, then the raw little-endian bytes — a copy of memory, not
a list of Python numbers (DESIGN.md §4: ``tolist()`` is 100× slower).

Actors of one process talk through Zenoh like any others, and each reader decodes what it
gets. A sender whose readers are mostly in its own process (the world's tick, with the fish,
the observer and the channel beside it; a robot's driver and its fish actor) encodes with
``reuse=True``: a decode in this process of those very bytes then returns the message
already built, frozen and validated when it was, instead of decoding it again (as ROS 2's
intra-process communication hands a message over without serializing it). Any other bytes,
from anywhere, are decoded and validated in full.
"""

from __future__ import annotations

import math
import struct
from typing import Any, TypeVar

import msgpack
import numpy as np

from fishswarm.protocols.checks import MAX_ROWS, unchangeable
from fishswarm.protocols.messages import (
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    Message,
    fields_of,
)

MAX_MESSAGE_BYTES = 16 * 1024 * 1024
REUSED_PER_TYPE = 4
"""How many messages of each type encoded with ``reuse=True`` this process keeps, last
first: enough for a tick's snapshot, perception batch (or the parts of a large one) and
command batch, or for a robot's one perception and one command a tick."""
_ARRAY_EXT = 1
_DTYPES = (np.dtype("<f8"), np.dtype("<i8"), np.dtype("|b1"))
_CODES = {dtype: code for code, dtype in enumerate(_DTYPES)}
_HEADERS = tuple(struct.Struct(f"<BB{ndim}I") for ndim in range(3))

M = TypeVar("M", bound=Message)

_reused: dict[type[Message], tuple[tuple[bytes, Message], ...]] = {}
"""The messages last encoded with ``reuse=True``, by type, each beside its bytes. A type's
entries are replaced by a new tuple, never changed in place: a thread that reads them
meanwhile sees the old or the new ones (two threads encoding one type at once may drop an
entry, which only costs a full decode)."""


class MessageError(ValueError):
    """A payload is not a valid fishswarm message (garbage, wrong types, NaN, size, version)."""


def _default(value: object) -> object:
    if isinstance(value, np.ndarray):
        code = _CODES.get(value.dtype)  # the usual case: already one of the wire's dtypes
        if code is None:
            swapped = value.dtype.newbyteorder("<") if value.dtype.kind != "b" else value.dtype
            code = _CODES.get(swapped)
        if code is None or value.ndim > 2:
            raise TypeError(f"cannot encode an array of dtype {value.dtype} and {value.ndim} dims")
        array = np.ascontiguousarray(value, dtype=_DTYPES[code])
        header = _HEADERS[array.ndim].pack(code, array.ndim, *array.shape)
        # The header joined straight to the array's memory: through tobytes() a large array
        # is copied twice (0.48 ms against 0.013 ms for 0.5 MB, a 1 000-fish perception).
        return msgpack.ExtType(_ARRAY_EXT, header + array.reshape(-1).data.cast("B"))
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
    if len(data) < 2:
        raise MessageError("array header is truncated")
    dtype_code, ndim = data[0], data[1]
    if dtype_code >= len(_DTYPES):
        raise MessageError(f"array dtype code {dtype_code} is not one of 0 (f8), 1 (i8), 2 (bool)")
    if ndim > 2 or len(data) < 2 + 4 * ndim:
        raise MessageError(f"array header is malformed ({ndim} dimensions, {len(data)} bytes)")
    shape = struct.unpack_from(f"<{ndim}I", data, 2)
    if any(n > MAX_ROWS for n in shape):
        raise MessageError(f"array shape {shape} exceeds {MAX_ROWS} rows")
    dtype = _DTYPES[dtype_code]
    offset = 2 + 4 * ndim
    expected = math.prod(shape) * dtype.itemsize
    if len(data) - offset != expected:
        raise MessageError(
            f"array of shape {shape} {dtype} needs {expected} bytes, got {len(data) - offset}"
        )
    return np.frombuffer(data, dtype=dtype, offset=offset).reshape(shape)


def encode(message: Message, *, reuse: bool = False) -> bytes:
    """Encode a message to bytes for the wire.

    Args:
        message: the message.
        reuse: keep the message, so that :func:`decode` in this process returns it for these
            bytes (its readers are mostly here). Kept only when it decodes to itself: its
            fields plain numbers, texts and arrays nothing can write to.
    """
    fields = fields_of(message)
    packed: bytes = msgpack.packb(
        {"v": SCHEMA_VERSION, "t": message.type_name, "f": fields},
        default=_default,
        use_bin_type=True,
    )
    if reuse and all(map(_decodes_to_itself, fields.values())):
        kind = type(message)
        _reused[kind] = ((packed, message), *_reused.get(kind, ())[: REUSED_PER_TYPE - 1])
    return packed


def _decodes_to_itself(value: object) -> bool:
    """Whether a field's value comes back from the wire as it is: a number, text or None of
    the very type msgpack decodes it to (not a NumPy number), or a C-ordered array of one
    of the wire's dtypes (by name, too: not longlong for int64) that nothing writes to, so
    that it stays what was encoded."""
    if type(value) in (int, float, str, bool) or value is None:
        return True
    return (
        type(value) is np.ndarray
        and any(value.dtype is wire for wire in _DTYPES)
        and value.flags.c_contiguous
        and unchangeable(value)
    )


def _reused_message(payload: bytes | bytearray | memoryview, expected: type[M]) -> M | None:
    """The message encoded here with ``reuse=True`` as exactly ``payload``, if kept."""
    if type(payload) is not bytes:
        return None
    for kept, message in _reused.get(expected, ()):
        if kept == payload:  # bytes compare their lengths first
            return message  # type: ignore[return-value]
    return None


def decode(payload: bytes | bytearray | memoryview, expected: type[M] | None = None) -> M:
    """Decode and validate a message.

    Args:
        payload: bytes from the wire.
        expected: the message type this key carries; anything else is rejected.

    Returns:
        The message, validated on construction: the very message encoded with
        ``reuse=True`` in this process, when ``payload`` is its bytes and ``expected`` its type.

    Raises:
        MessageError: the payload is not a valid message of the expected type, with the reason.
    """
    if len(payload) > MAX_MESSAGE_BYTES:
        raise MessageError(f"message of {len(payload)} bytes exceeds {MAX_MESSAGE_BYTES}")
    if expected is not None and (reused := _reused_message(payload, expected)) is not None:
        return reused
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
    # Compared only once known to be a plain integer: an array would compare element-wise.
    if type(raw["v"]) is not int or raw["v"] != SCHEMA_VERSION:
        shown = raw["v"] if isinstance(raw["v"], int | str) else type(raw["v"]).__name__
        raise MessageError(
            f"schema version {shown!r} is not supported (this fishswarm speaks {SCHEMA_VERSION})"
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
    except Exception as error:  # whatever hostile fields make a check raise
        raise MessageError(f"invalid {cls.type_name}: {error}") from None
