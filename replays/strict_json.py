"""Strict JSON for every file the project writes: NaN and infinities become ``null``, NumPy values plain numbers.

Python's ``json.dumps`` writes ``NaN`` and ``Infinity`` by default, which no strict parser (a browser's, jq's,
another language's) reads. ``dumps`` never does:

    write_text_atomic(path, dumps({"ade_m": float("nan")}, indent=1))     # {"ade_m": null}
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def plain(value: Any) -> Any:
    """``value`` with every float that is not finite replaced by None, NumPy scalars and arrays turned into Python
    numbers and lists, tuples into lists (recursively through dicts and lists)."""
    if isinstance(value, dict):
        return {key: plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [plain(item) for item in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(value: Any, **options: Any) -> str:
    """``json.dumps(plain(value), allow_nan=False, **options)``: strict JSON text (no NaN, no Infinity)."""
    return json.dumps(plain(value), allow_nan=False, **options)
