"""Range checks for the simulator's config dataclasses and layout parameters, and the memory budget.

Every numeric field declares its allowed range once, beside its default (``bounded``); ``check_fields``
(called from ``__post_init__``) rejects a value outside it, NaN, inf or a value of the wrong type with a
``ValueError`` that names the class, the field, the value and the range. ``check_memory`` refuses an array
(a raster, a navigation grid) whose size would pass ``MEMORY_BUDGET_BYTES`` before it is allocated.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Final

import numpy as np

MEMORY_BUDGET_BYTES: Final[int] = 1 << 30  # largest layout-derived array set the simulator builds (1 GiB)


class LayoutTooLargeError(ValueError):
    """A layout, raster or grid would need more memory than MEMORY_BUDGET_BYTES."""


@dataclass(frozen=True)
class Bounds:
    """Allowed values of a number: low..high, each end open or closed, optionally integers only."""

    low: float
    high: float
    unit: str = ""
    integer: bool = False
    open_low: bool = False
    open_high: bool = False

    def __str__(self) -> str:
        kind = "an integer" if self.integer else "a finite number"
        left, right = "(" if self.open_low else "[", ")" if self.open_high else "]"
        return f"{kind} in {left}{self.low:g}, {self.high:g}{right}{' ' + self.unit if self.unit else ''}"

    def admits(self, value: Any) -> bool:
        """True if value is a number of the right kind inside the range."""
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            return False
        if self.integer and not isinstance(value, numbers.Integral):
            return False
        value = float(value)
        if not math.isfinite(value):
            return False
        above = value > self.low if self.open_low else value >= self.low
        below = value < self.high if self.open_high else value <= self.high
        return above and below


def bounded(default: Any, low: float, high: float, unit: str = "", *, integer: bool = False,
            open_low: bool = False, open_high: bool = False, optional: bool = False, length: int | None = None) -> Any:
    """A dataclass field whose value lies in low..high: a number, or with length a sequence of that many numbers
    (None allowed if optional)."""
    bounds = Bounds(float(low), float(high), unit, integer, open_low, open_high)
    return field(default=default, metadata={"bounds": bounds, "optional": optional, "length": length})


def check_value(owner: str, name: str, value: Any, bounds: Bounds, optional: bool = False,
                length: int | None = None) -> None:
    """Raise ValueError naming owner.name unless value fits bounds (with length: a sequence of length numbers that
    each fit)."""
    if value is None and optional:
        return
    if length is None:
        ok = bounds.admits(value)
        what = str(bounds)
    else:
        values = np.asarray(value, dtype=object).ravel().tolist() if isinstance(value, (tuple, list, np.ndarray)) \
            else None
        ok = values is not None and len(values) == length and all(bounds.admits(v) for v in values)
        what = f"{length} numbers, each {bounds}"
    if not ok:
        raise ValueError(f"{owner}.{name} = {value!r}: expected {what}{' or None' if optional else ''}")


def check_fields(config: Any) -> None:
    """Check every ``bounded`` field of a dataclass instance; nested dataclasses check themselves."""
    owner = type(config).__name__
    for f in fields(config):
        if "bounds" in f.metadata:
            check_value(owner, f.name, getattr(config, f.name), f.metadata["bounds"], f.metadata["optional"],
                        f.metadata["length"])


def named(value: Any, table: Mapping[str, Any], kind: type, default: str, argument: str, error: type) -> Any:
    """``value`` if it is a ``kind``, the entry of ``table`` it names, ``table[default]`` for None; else ``error``
    naming ``argument`` and the choices (a spec given by name or as an object: the robot's, the sensor's)."""
    if value is None:
        return table[default]
    if isinstance(value, kind):
        return value
    if isinstance(value, str) and value in table:
        return table[value]
    raise error(f"{argument}={value!r}: expected a {kind.__name__} or one of {', '.join(map(repr, table))}")


def check_memory(what: str, n_bytes: float) -> None:
    """Raise LayoutTooLargeError before allocating n_bytes for what, if that passes MEMORY_BUDGET_BYTES."""
    if not n_bytes <= MEMORY_BUDGET_BYTES:
        raise LayoutTooLargeError(f"{what} would take {n_bytes / 2**20:,.0f} MiB, over the simulator's memory budget "
                                  f"of {MEMORY_BUDGET_BYTES / 2**20:,.0f} MiB; use a smaller layout or coarser cells")
