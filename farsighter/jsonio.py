"""Strict JSON (RFC 8259) for everything the library writes or prints: Python's ``json.dumps``
writes a non-finite float as a bare ``NaN`` or ``Infinity``, which strict parsers (JavaScript's
``JSON.parse``, ``jq``, most other languages) refuse; here it is written ``null``."""

from __future__ import annotations

import json
import math
from typing import Any


def finite(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, +-inf; NumPy's float64 included) in its
    dicts, lists and tuples replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [finite(item) for item in value]
    return value


def dumps(value: Any, indent: int | None = 2) -> str:
    """``value`` as strict JSON: non-finite floats as ``null`` (:func:`finite`)."""
    return json.dumps(finite(value), indent=indent, allow_nan=False)
