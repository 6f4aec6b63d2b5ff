"""Field checks for the predictor's configuration dataclasses: every bad value is a ValueError naming the field."""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any


def check_config(cfg: Any, ranges: dict[str, tuple[float, float]], choices: dict[str, tuple] | None = None) -> None:
    """Raise ``ValueError`` naming the field, its value and what is allowed.

    Args:
        cfg: a dataclass instance.
        ranges: field -> inclusive (low, high) for numeric fields; ``None`` values are allowed where the
            field's default is None. Fields annotated ``int`` must hold integers (not bools or floats).
        choices: field -> allowed values.

    Fields annotated ``bool`` must hold a bool, fields annotated ``str`` a non-empty string (or None where
    the annotation allows it).
    """
    name = type(cfg).__name__
    defaults = {f.name: f.default for f in fields(cfg)}
    types = {f.name: str(f.type) for f in fields(cfg)}
    for field_name, (low, high) in ranges.items():
        value = getattr(cfg, field_name)
        if value is None and defaults[field_name] is None:
            continue
        wants_int = "int" in types[field_name] and "float" not in types[field_name]
        if isinstance(value, bool) or not isinstance(value, int if wants_int else (int, float)):
            kind = "an integer" if wants_int else "a number"
            raise ValueError(f"{name}.{field_name}={value!r}: must be {kind} in [{low}, {high}]")
        if not (math.isfinite(value) and low <= value <= high):
            raise ValueError(f"{name}.{field_name}={value!r}: must be in [{low}, {high}]")
    for field_name, kind in types.items():
        value = getattr(cfg, field_name)
        if kind == "bool" and not isinstance(value, bool):
            raise ValueError(f"{name}.{field_name}={value!r}: must be True or False")
        allowed_none = value is None and "None" in kind
        if kind in ("str", "str | None") and not ((isinstance(value, str) and value) or allowed_none):
            raise ValueError(f"{name}.{field_name}={value!r}: must be a non-empty string")
    for field_name, allowed in (choices or {}).items():
        if getattr(cfg, field_name) not in allowed:
            raise ValueError(f"{name}.{field_name}={getattr(cfg, field_name)!r}: must be one of {', '.join(allowed)}")
