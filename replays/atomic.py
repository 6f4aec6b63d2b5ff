"""Atomic file writes: write beside the target, then rename over it, so no half-written file is ever seen.

A writer holds an exclusive ``flock`` on its temporary file while it writes. The lock dies with the process,
so a temporary file nobody holds is the leftover of a killed write: the next write to the same target
deletes such leftovers first.
"""

from __future__ import annotations

import glob
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: no locks, so leftovers are never known to be stale and are kept
    fcntl = None


def try_lock(fd: int) -> bool:
    """Take an exclusive advisory lock on an open file without waiting; False if someone else holds it."""
    if fcntl is None:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def remove_stale(pattern: str) -> list[Path]:
    """Delete the files matching the glob ``pattern`` that no live process holds locked; returns them."""
    removed = []
    for name in glob.glob(pattern):
        try:
            fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        except OSError:
            continue  # gone already, or not ours to open
        try:
            if try_lock(fd) and os.path.isfile(name):
                os.unlink(name)
                removed.append(Path(name))
        finally:
            os.close(fd)
    return removed


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path in ``path``'s folder; it replaces ``path`` when the block succeeds.

    The temporary name ends with the target's suffix (writers that pick a format by extension work) and is
    deleted if the block raises. Leftovers of killed writes to the same target are deleted first. The final
    file is readable by everyone (mode 644).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix, suffix = f".{path.name}.", f".tmp{path.suffix}"
    remove_stale(os.path.join(glob.escape(str(path.parent)), glob.escape(prefix) + "*" + glob.escape(suffix)))
    while True:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=prefix, suffix=suffix)
        if fcntl is not None:
            fcntl.flock(fd, fcntl.LOCK_EX)  # waits if a cleaner holds it for a moment
        if os.fstat(fd).st_nlink:
            break
        os.close(fd)  # a cleaner deleted it between creation and locking: take another name
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
        os.close(fd)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)
