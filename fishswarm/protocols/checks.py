"""The checks every message runs on construction: integers, finite numbers, short texts,
arrays of a dtype and shape, ascending ids, counts that add up.

Each raises TypeError or ValueError with what is wrong; the codec turns either into its one
error type. Arrays are stored read-only, and so is all memory they view: a message never
changes after construction. An array the checks copy sits on a bytes object, as a decoded
one does, which nobody can make writable again.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

MAX_ROWS = 100_000
"""Most rows an array of a message may have."""
MAX_TEXT = 64
"""Most characters of a text field."""
MAX_TICK = 2**62
"""Largest tick (and other counter) a message may carry."""

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def _set(obj: object, name: str, value: object) -> None:
    object.__setattr__(obj, name, value)


def unchangeable(array: np.ndarray[Any, Any]) -> bool:
    """Whether nothing writes to ``array``: it is read-only, and so is every array it views,
    down to memory that an array owns or that a bytes object holds.

    (Whoever holds a read-only array that owns its memory could set it writable again, as
    a frozen dataclass can be changed through ``object.__setattr__``: a message's promise
    not to change is one its holders keep. Memory a bytes object holds, numpy lets nobody
    write to.)"""
    viewed: object = array
    while isinstance(viewed, np.ndarray):
        if viewed.flags.writeable:
            return False
        if viewed.base is None:
            return bool(viewed.flags.owndata)
        viewed = viewed.base
    return isinstance(viewed, bytes)


def frozen(array: np.ndarray[Any, Any], dtype: type[np.generic]) -> np.ndarray[Any, Any]:
    """A copy of ``array`` as ``dtype`` (native byte order, C order) that nothing can write
    to: its memory is a bytes object."""
    native = np.dtype(dtype)
    contiguous = np.ascontiguousarray(array, dtype=native)
    return np.frombuffer(contiguous.tobytes(), dtype=native).reshape(contiguous.shape)


def check_int(name: str, value: object, low: int = 0, high: int = MAX_TICK) -> None:
    """Check that field ``name`` is an integer (not a bool) in [``low``, ``high``]."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise TypeError(f"{name} must be an integer, got {type(value).__name__}")
    if not low <= int(value) <= high:
        raise ValueError(f"{name} must be in [{low}, {high}], got {value}")


def check_float(name: str, value: object, low: float = -math.inf, high: float = math.inf) -> None:
    """Check that field ``name`` is a finite number (not a bool) in [``low``, ``high``]."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating):
        raise TypeError(f"{name} must be a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be in [{low}, {high}], got {value}")


def check_text(name: str, value: object) -> None:
    """Check that field ``name`` is text of 1 to MAX_TEXT characters."""
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a string, got {type(value).__name__}")
    if not 0 < len(value) <= MAX_TEXT:
        raise ValueError(f"{name} must have 1 to {MAX_TEXT} characters, got {len(value)}")


def check_array(
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
    # An empty list has no dtype to tell (np.asarray makes it float64): empty is empty.
    if dtype is np.int64 and array.dtype.kind == "f" and array.size:
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
    # Arrays decoded from the wire sit on their bytes already and need no copy; anything the
    # caller could still change, or of an equal dtype of another name (longlong for int64,
    # another byte order), is copied, so that a message never changes after construction.
    if array.dtype is not np.dtype(dtype) or not unchangeable(array):
        array = frozen(array, dtype)
    if dtype is np.float64 and not np.isfinite(array).all():
        raise ValueError(f"{name} must hold finite numbers only")
    _set(obj, name, array)


def check_ids(ids: IntArray) -> None:
    """Check that fish ids are strictly ascending and not negative."""
    if ids.shape[0] > 1 and (ids[1:] <= ids[:-1]).any():
        raise ValueError("ids must be strictly ascending")
    if ids.shape[0] and ids[0] < 0:  # ascending: the first is the least
        raise ValueError("ids must be non-negative")


def check_counts(name: str, counts: IntArray, rows: int, what: str) -> None:
    """Check that per-fish row counts are not negative and add up to the ``rows`` of the
    array ``what``."""
    if (counts < 0).any():
        raise ValueError(f"{name} must be non-negative")
    # Each count bounded first, so that the sum cannot wrap around in int64 and come out
    # right for counts no batch could hold.
    if (counts > rows).any():
        raise ValueError(f"{name} must each be at most the {rows} rows of {what}")
    if int(counts.sum()) != rows:
        raise ValueError(f"{name} add up to {int(counts.sum())}, but {what} has {rows} rows")
