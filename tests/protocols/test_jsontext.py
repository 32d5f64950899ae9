"""Strict JSON text: numbers JSON has no words for are written as null."""

from __future__ import annotations

import json
import math
from typing import Any

from hypothesis import given
from hypothesis import strategies as st

from fishswarm.protocols.jsontext import json_text, number_or_nan


def strict(text: str) -> Any:
    """Parse as a browser's JSON.parse would: NaN and Infinity are errors."""

    def refuse(word: str) -> None:
        raise ValueError(f"not JSON: {word}")

    return json.loads(text, parse_constant=refuse)


def test_nan_and_infinities_become_null_wherever_they_are() -> None:
    value = {"fitness": math.nan, "rows": [1.5, math.inf, (-math.inf, 2)], "name": "a"}
    assert strict(json_text(value)) == {
        "fitness": None,
        "rows": [1.5, None, [None, 2]],
        "name": "a",
    }
    assert json.dumps(value) != json_text(value)  # Python's own would write NaN
    assert number_or_nan(None) != number_or_nan(None)  # NaN
    assert number_or_nan(0.25) == 0.25


def test_numpy_floats_are_floats_and_written_alike() -> None:
    import numpy as np

    assert strict(json_text({"x": np.float64("nan"), "y": np.float64(0.5)})) == {
        "x": None,
        "y": 0.5,
    }


@given(
    st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
        lambda inner: (
            st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner, max_size=4)
        ),
        max_leaves=20,
    )
)
def test_any_value_of_plain_types_is_strict_json_with_its_finite_numbers_kept(value: Any) -> None:
    parsed = strict(json_text(value))

    def expected(item: Any) -> Any:
        if isinstance(item, float) and not math.isfinite(item):
            return None
        if isinstance(item, dict):
            return {key: expected(inner) for key, inner in item.items()}
        if isinstance(item, list):
            return [expected(inner) for inner in item]
        return item

    assert parsed == expected(value)
