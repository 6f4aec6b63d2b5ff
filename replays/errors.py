"""Exceptions for bad data: each names the file (and line or field) and says what is wrong or how to fix it.

Every class takes the message as its only positional argument, so it pickles and survives gymnasium's async
vector env, which re-raises a worker's error as ``type(err)(err)``.
"""

from __future__ import annotations

import os


class DataFormatError(ValueError):
    """A recording, homography or map file is malformed (message names the file and line)."""


class RecordingError(DataFormatError):
    """A recording file is malformed or unusable.

    Attributes:
        path: the file ("" if unknown).
        line: 1-based line number, or None when the problem is not one line's.
        field: the column at fault (``frame``, ``agent``, ``x``, ``y``), or None.
    """

    def __init__(self, message: str, *, path: str | os.PathLike = "", line: int | None = None,
                 field: str | None = None):
        super().__init__(str(message))
        self.path, self.line, self.field = os.fspath(path), line, field


class MemoryBudgetError(DataFormatError):
    """An array built from a file would need more memory than ``replays.files.MEMORY_BUDGET_BYTES``.

    Raised before anything is allocated; the message names the file, the array's shape and both sizes.
    """


class NotRegularFileError(DataFormatError):
    """A path that should hold data is a FIFO, device, socket or folder; only regular files are read."""


class DataRootError(FileNotFoundError):
    """The ETH/UCY data root is missing, incomplete or corrupt (message says how to fix it)."""


class UnknownNameError(ValueError, KeyError):
    """An unknown scene, recording or layout name (also a KeyError, as such lookups used to raise)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""
