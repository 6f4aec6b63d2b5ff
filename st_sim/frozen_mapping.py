"""A read-only mapping for an env's ``info`` entries that gymnasium's vector envs must keep whole."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any


class FrozenMapping(Mapping):
    """Read-only values by name. A mapping but not a dict, on purpose: gymnasium's vector envs batch a dict entry
    into typed arrays, which values of other types or lengths from another sub-env cannot share; a ``FrozenMapping``
    stays whole, one per sub-env in an object array. ``dict(mapping)`` gives a plain dict."""

    def __init__(self, values: Mapping[str, Any]):
        self._values = dict(values)

    def __getitem__(self, name: str) -> Any:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._values})"
