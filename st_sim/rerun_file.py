"""Where a Rerun recording is written: the target check, the path lock, numbered names and a sink that reports
failed writes.

``checked_recording_target`` expands ``~`` and refuses a target that cannot be written (a folder, a special
file, a path under a regular file, a folder that takes no new files) with a ``RecordingPathError`` naming it,
before anything is created. ``claim`` locks ``.<name>.lock`` beside the target, so two live writers to one
path are refused (the lock dies with its process); ``new_file`` creates the target, or the first free
``<stem>-<n><suffix>`` if it exists, so a finished recording is never overwritten.

``RecordingSink`` keeps Rerun off the disk. Rerun's own file sink cannot tell Python that a write failed: it
prints the error, a later flush waits forever and so does the interpreter's exit (seen with a full disk and
with a file-size limit). So Rerun writes into a pipe, handed to it as ``/dev/fd/<n>`` (POSIX), and a daemon
thread copies the pipe into the file. The thread keeps the first ``OSError`` of a write and from then on
drains and discards, so Rerun never blocks and never fails; the next ``flush`` raises ``RecordingWriteError``
naming the file. Rerun writes only when flushed (the logger's batcher never flushes on its own), so the
file's size after a flush is a readable prefix: after a failed write the file is cut back to it, or removed
if nothing had been written.
"""

from __future__ import annotations

import fcntl
import os
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
from pathlib import Path
from typing import Any, Literal

from replays.atomic import try_lock

FLUSH_TIMEOUT_S = 60.0  # a flush that has not reached the file by then is a failed write [s]
COPY_BYTES = 1 << 20  # most bytes copied from the pipe to the file at once
COPY_POLL_S = 0.1  # the copy thread checks this often whether the sink has finished [s]
MAX_NUMBERED = 10_000  # most numbered siblings tried for a new recording name


class RecordingPathError(ValueError):
    """A Rerun recording path is in use by another live writer, or is not a path a file can be written to."""


class RecordingWriteError(OSError):
    """A recording could not be written (disk full, file-size limit, I/O error): the run that logs it must stop."""


def checked_recording_target(target: str | os.PathLike) -> Path | Literal["spawn"]:
    """The recording file ``target`` names, with ``~`` expanded, once it is known to be writable; or "spawn".

    Nothing is created: a probe file is made and removed at once in the nearest folder that exists.

    Raises:
        RecordingPathError: ``target`` is not a str or path, is empty, is a folder or a special file, lies
            under a regular file, or its nearest existing folder does not take new files (permissions, a
            read-only file system); the message names the path and the reason.
    """
    if not isinstance(target, str | os.PathLike):
        raise RecordingPathError(f"rerun={target!r}: expected a .rrd file path or 'spawn'")
    if str(target) == "spawn":
        return "spawn"
    if not str(target):
        raise RecordingPathError("rerun='': expected a .rrd file path or 'spawn'")
    path = Path(os.path.expanduser(os.fspath(target)))
    if path.is_dir() or (path.exists() and not path.is_file()):
        raise RecordingPathError(f"rerun target {path} is a folder or a special file; give a .rrd file path")
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise RecordingPathError(f"rerun target {path}: {folder} is a file, not a folder")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise RecordingPathError(f"rerun target {path}: cannot create files in {folder} "
                                 f"({err.strerror or err})") from err
    return path


class RecordingSink:
    """The receiving end of one ``rr.RecordingStream``: a file (through a pipe and a copy thread) or a viewer.

    Args:
        recording: the stream, already configured; the sink starts it (``save`` or nothing for a viewer).
        path: the file to write (made by ``new_file``), or None when the stream goes to a spawned viewer.
        lock: the path's lock from ``claim``, freed by ``finish``.
        blueprint: the default blueprint written at the start of the file.

    Attributes:
        flushed_at: ``time.monotonic()`` of the last complete flush [s].
        readable_bytes: the file's size at the last complete flush, a readable recording.
        error: the write failure, once there was one; every later ``flush`` raises it again.
    """

    def __init__(self, recording: Any, path: Path | None = None, lock: tuple[int, Path] | None = None,
                 blueprint: Any = None):
        self.recording, self.path, self.lock = recording, path, lock
        self.flushed_at = time.monotonic()
        self.readable_bytes = 0
        self.error: RecordingWriteError | None = None
        self._finished = False
        if path is None:
            return
        self._copied = threading.Condition()  # held while bytes move from the pipe to the file
        self._file_bytes = 0  # bytes in the file
        self._write_error: OSError | None = None
        self._stop = threading.Event()  # set by finish once the pipe is drained
        self._file = os.open(path, os.O_WRONLY | os.O_TRUNC)
        self._pipe, write_end = os.pipe()
        try:
            recording.save(f"/dev/fd/{write_end}", default_blueprint=blueprint, write_footer=False)
        except BaseException:
            os.close(self._pipe)
            os.close(self._file)
            path.unlink(missing_ok=True)
            raise
        finally:
            os.close(write_end)  # Rerun opened its own descriptor of the pipe
        self._thread = threading.Thread(target=self._copy, name=f"rerun {path.name}", daemon=True)
        self._thread.start()

    def _copy(self) -> None:
        """Thread: pipe -> file until the sink finishes (or Rerun closes the pipe); after a failed write, drain and
        discard. (A forked child may hold Rerun's end of the pipe open, so the end is not awaited as end of file.)"""
        while not self._stop.is_set():
            if not select.select([self._pipe], [], [], COPY_POLL_S)[0]:
                continue
            with self._copied:
                data = os.read(self._pipe, COPY_BYTES)
                if data and self._write_error is None:
                    try:
                        view = memoryview(data)
                        while view:
                            written = os.write(self._file, view)
                            self._file_bytes += written
                            view = view[written:]
                    except OSError as err:
                        self._write_error = err
                self._copied.notify_all()
                if not data:
                    return

    def flush(self) -> None:
        """Write everything logged so far; on failure cut the file back to its readable prefix and raise.

        Raises:
            RecordingWriteError: now or earlier, a write failed (the message names the file and the reason).
        """
        if self.error is not None:
            raise self.error
        try:
            self.recording.flush(timeout_sec=FLUSH_TIMEOUT_S)
        except RuntimeError as err:  # Rerun itself failed (a spawned viewer that went away)
            self.error = RecordingWriteError(f"{self.path or 'the Rerun viewer'}: Rerun could not flush ({err})")
            raise self.error from err
        self.flushed_at = time.monotonic()
        if self.path is not None:
            self._check_written(*self._wait_copied())

    def _wait_copied(self) -> tuple[int, OSError | None]:
        """Wait until the pipe is empty; returns (bytes in the file, the write error or None) at that moment."""
        deadline = time.monotonic() + FLUSH_TIMEOUT_S
        with self._copied:
            while _unread_bytes(self._pipe):
                if not self._thread.is_alive() or not self._copied.wait(max(0.0, deadline - time.monotonic())):
                    self.error = RecordingWriteError(f"{self.path}: the recording did not reach the file (its copy "
                                                     f"thread stopped, or took over {FLUSH_TIMEOUT_S:g} s)")
                    raise self.error
            return self._file_bytes, self._write_error

    def _check_written(self, file_bytes: int, write_error: OSError | None) -> None:
        """Move the readable mark, or raise the write error after cutting the file back to the mark."""
        if write_error is None:
            self.readable_bytes = file_bytes
            return
        free_mb = shutil.disk_usage(self.path.parent).free / 2**20
        if self.readable_bytes:
            os.ftruncate(self._file, self.readable_bytes)
            kept = f"it keeps its first {self.readable_bytes} bytes, a readable recording of the steps before"
        else:
            self.path.unlink(missing_ok=True)
            kept = "nothing had been written, so the file is removed"
        self.error = RecordingWriteError(f"{self.path}: writing the Rerun recording failed: "
                                         f"{write_error.strerror or write_error} ({free_mb:.0f} MB free on its disk); "
                                         f"{kept}")
        raise self.error from write_error

    def finish(self) -> None:
        """Flush, end the recording, free the lock (once; later calls do nothing).

        Raises:
            RecordingWriteError: the last steps or the end of the recording could not be written.
        """
        if self._finished:
            return
        self._finished = True
        try:
            if self.error is None:
                self.flush()
        finally:
            self.recording.disconnect()  # writes the end-of-stream marker into the pipe
            if self.path is not None:
                try:
                    copied = self._wait_copied()
                    if self.error is None:
                        self._check_written(*copied)
                finally:
                    self._stop.set()
                    self._thread.join(FLUSH_TIMEOUT_S)
                    os.close(self._pipe)
                    os.close(self._file)
            unlock(self.lock)


def _unread_bytes(fd: int) -> int:
    """Bytes waiting in a pipe."""
    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0\0\0\0"))[0]


def claim(target: Path) -> tuple[int, Path]:
    """Lock ``.<name>.lock`` beside ``target`` for this writer (making its folder); returns (descriptor, lock path).

    Raises:
        RecordingPathError: the folder or the lock file cannot be made, or another live writer holds the lock.
    """
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        lock_path = target.with_name(f".{target.name}.lock")
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as err:
        raise RecordingPathError(f"rerun target {target}: {err.strerror or err}") from err
    if not try_lock(fd):
        os.close(fd)
        raise RecordingPathError(f"{target}: another logger (this process or another) is writing to this path; "
                                 "give each env or run its own rerun= path")
    return fd, lock_path


def new_file(target: Path) -> Path:
    """Create ``target``, or the first free ``<stem>-<n><suffix>`` if it exists, exclusively; returns its path.

    Raises:
        RecordingPathError: the file cannot be created, or ``MAX_NUMBERED`` names are taken.
    """
    for number in range(MAX_NUMBERED):
        path = target if number == 0 else target.with_name(f"{target.stem}-{number}{target.suffix}")
        try:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        except FileExistsError:
            continue
        except OSError as err:
            raise RecordingPathError(f"rerun target {path}: {err.strerror or err}") from err
        return path
    raise RecordingPathError(f"{target}: {MAX_NUMBERED} numbered recordings exist already; choose another name")


def unlock(lock: tuple[int, Path] | None) -> None:
    """Delete and unlock the lock file of ``claim`` (None: nothing to do)."""
    if lock is not None:
        fd, lock_path = lock
        lock_path.unlink(missing_ok=True)
        os.close(fd)
