"""JSON that every reader accepts: numbers JSON cannot write are written as ``null``.

Python's ``json`` writes NaN and infinities as the bare words ``NaN`` and ``Infinity``, which
JSON does not have: JavaScript's ``JSON.parse`` (Foxglove, Lichtblick, a browser) and strict
parsers reject the whole text. A metric that is undefined at some moment (the study's
fitness of a local shape, a formation with more fish than slots) is written as ``null``
instead, and read back as NaN where a number is expected (:func:`number_or_nan`).
"""

from __future__ import annotations

import json
import math
from typing import Any


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(item) for item in value]
    return value


def json_text(value: Any, *, indent: int | None = None) -> str:
    """``value`` as strict JSON: NaN and ±infinity (also inside dicts, lists and tuples;
    NumPy's float64 is a float) written as ``null``."""
    return json.dumps(_finite(value), indent=indent, allow_nan=False)


def number_or_nan(value: Any) -> Any:
    """A value read from such JSON: ``null`` back to NaN, anything else as it is."""
    return math.nan if value is None else value
