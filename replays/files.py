"""Reading data files safely: regular files only, sizes and array memory checked before anything is allocated.

A FIFO would block a reader forever and ``/dev/zero`` never ends, so every loader opens its file with
``open_regular`` (non-blocking open, then ``fstat``) and refuses anything but a regular file; the stream it
gives stops with ``MemoryBudgetError`` past the caller's byte limit, even if the file grows while it is read.
Arrays whose size comes from a file's contents are checked with ``require_budget`` before they are allocated.
"""

from __future__ import annotations

import io
import os
import stat
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, BinaryIO, Final

import numpy as np

from replays.errors import DataFormatError, MemoryBudgetError, NotRegularFileError

MEMORY_BUDGET_BYTES: Final[int] = 1 << 30  # largest array (or parse working set) one loader may allocate [B]
_KINDS: Final = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                 (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


class _Limited(io.RawIOBase):
    """A raw file that raises ``MemoryBudgetError`` once more than ``limit`` bytes have been read."""

    def __init__(self, fd: int, path: Path, limit: int | None, what: str):
        self._file, self._path, self._limit, self._what, self._seen = io.FileIO(fd, "rb"), path, limit, what, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        self._seen = self._file.seek(offset, whence)
        return self._seen

    def readinto(self, buffer) -> int:
        count = self._file.readinto(buffer)
        self._seen += count or 0
        if self._limit is not None and self._seen > self._limit:
            raise MemoryBudgetError(f"{self._path}: more than the {self._limit:,} bytes a {self._what} may hold")
        return count

    def fileno(self) -> int:
        return self._file.fileno()

    def close(self) -> None:
        self._file.close()
        super().close()


@contextmanager
def open_regular(path: str | os.PathLike, max_bytes: int | None = None, what: str = "data file"
                 ) -> Iterator[BinaryIO]:
    """Open ``path`` for buffered binary reading, refusing anything but a regular file (symlinks are followed).

    The open is non-blocking, so a FIFO is refused instead of waiting for a writer.

    Args:
        max_bytes: largest size accepted, checked before reading and again while reading; None = any.
        what: what the file should hold, for messages ("recording", "homography").

    Raises:
        NotRegularFileError: FIFO, device, socket or folder.
        MemoryBudgetError: the file is larger than ``max_bytes``.
        DataFormatError: the file cannot be opened (missing, no permission); the message names it.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as err:
        _refuse_irregular(path, os.stat(path).st_mode if os.path.exists(path) else stat.S_IFREG)
        raise DataFormatError(f"{path}: cannot open ({err.strerror or err})") from err
    try:
        info = os.fstat(fd)
        _refuse_irregular(path, info.st_mode)
        if max_bytes is not None and info.st_size > max_bytes:
            raise MemoryBudgetError(f"{path}: {info.st_size:,} bytes, more than the {max_bytes:,} bytes "
                                    f"a {what} may hold")
        raw = _Limited(fd, path, max_bytes, what)
    except BaseException:
        os.close(fd)
        raise
    with io.BufferedReader(raw) as stream:
        yield stream


def _refuse_irregular(path: Path, mode: int) -> None:
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
        raise NotRegularFileError(f"{path}: is {kind}; only regular files are read")


def parse_numbers(text: IO[str]) -> np.ndarray:
    """(R, C) float64 table of a whitespace-separated text stream (numpy's C reader; blank lines skipped).

    Raises:
        ValueError: a token is not a number or the rows differ in length (numpy's message).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data": callers check the shape
        return np.loadtxt(text, dtype=np.float64, comments=None, ndmin=2)


def read_bytes(path: str | os.PathLike, max_bytes: int, what: str) -> bytes:
    """The whole content of a regular file of at most ``max_bytes`` bytes (see ``open_regular``)."""
    with open_regular(path, max_bytes, what) as stream:
        try:
            return stream.read()
        except OSError as err:
            raise DataFormatError(f"{path}: cannot read ({err.strerror or err})") from err


def require_budget(nbytes: int, what: str) -> None:
    """Raise ``MemoryBudgetError`` if an allocation of ``nbytes`` would pass ``MEMORY_BUDGET_BYTES``.

    Args:
        what: the file and the array, e.g. ``"x.txt: dense grid of 9000 frames x 8000 agents"``.
    """
    if nbytes > MEMORY_BUDGET_BYTES:
        raise MemoryBudgetError(f"{what} needs {nbytes / 2**30:.1f} GiB, over the "
                                f"{MEMORY_BUDGET_BYTES / 2**30:.1f} GiB budget (replays.files.MEMORY_BUDGET_BYTES)")
