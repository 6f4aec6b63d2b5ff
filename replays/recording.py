"""One recording: rows ``frame_id agent_id x y`` (metres, world frame), parsed strictly and fast.

``read_recording`` is the only parser: every loader, the environments and the simulator's replay
files go through it. ``write_recording`` writes the same format atomically, and refuses what the parser
would refuse.
"""

from __future__ import annotations

import io
import itertools
import os
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import BinaryIO, Final

import numpy as np

from replays.atomic import write_text_atomic
from replays.constants import ID_LIMIT, POSITION_LIMIT_M
from replays.errors import MemoryBudgetError, RecordingError
from replays.files import open_regular, parse_numbers, require_budget

N_COLUMNS: Final = 4  # frame_id, agent_id, x [m], y [m]
FIELDS: Final = ("frame", "agent", "x", "y")
MAX_RECORDING_BYTES: Final = 64 << 20  # largest recording file read [B]; ETH/UCY's largest is 0.9 MB
DENSE_BYTES_PER_CELL: Final = 17  # (x, y) float64 + present bool, per (listed frame, agent) cell


@dataclass(frozen=True, eq=False)
class Recording:
    """Rows of one recording file, sorted by frame.

    Attributes:
        name: file stem, e.g. ``"crowds_zara01_train"``.
        frame: (R,) int64 frame ids (consecutive annotated frames differ by 10 in ETH/UCY).
        agent: (R,) int64 agent ids, >= 0.
        xy_m: (R, 2) float64 positions, metres, world frame.
        path: the file it was read from (None when built in memory).
    """

    name: str
    frame: np.ndarray
    agent: np.ndarray
    xy_m: np.ndarray
    path: Path | None = None

    def __repr__(self) -> str:
        return f"Recording({self.name}: {len(self.frame)} rows, {len(self.frames)} frames, {len(self.agents)} agents)"

    def __len__(self) -> int:
        return len(self.frame)

    @cached_property
    def frames(self) -> np.ndarray:
        """(F,) sorted unique frame ids."""
        return np.unique(self.frame)

    @cached_property
    def agents(self) -> np.ndarray:
        """(A,) sorted unique agent ids."""
        return np.unique(self.agent)

    def grid_budget(self, bytes_per_cell: int, what: str) -> None:
        """Raise ``MemoryBudgetError`` if arrays of ``bytes_per_cell`` per (listed frame, agent) pass the budget."""
        frames, agents = len(self.frames), len(self.agents)
        require_budget(frames * agents * bytes_per_cell,
                       f"{self.path or self.name}: {what} of {frames} listed frames x {agents} agents")

    def dense(self, decimals: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Positions on the (listed frame x agent) grid; refused beyond ``replays.files.MEMORY_BUDGET_BYTES``.

        Args:
            decimals: round the positions to this many decimals (in place), or None.

        Returns:
            xy_m: (F, A, 2) float64 metres, NaN where the agent is absent.
            present: (F, A) bool.

        Raises:
            MemoryBudgetError: F x A x 17 bytes would pass the 1 GiB budget (checked before allocating).
        """
        self.grid_budget(DENSE_BYTES_PER_CELL, "dense grid")
        f_idx = np.searchsorted(self.frames, self.frame)
        a_idx = np.searchsorted(self.agents, self.agent)
        xy = np.full((len(self.frames), len(self.agents), 2), np.nan)
        present = np.zeros((len(self.frames), len(self.agents)), bool)
        xy[f_idx, a_idx] = self.xy_m
        present[f_idx, a_idx] = True
        if decimals is not None:
            np.round(xy, decimals, out=xy)
        return xy, present


def read_recording(path: str | os.PathLike) -> Recording:
    """Parse a whitespace-separated ``frame agent x y`` file (UTF-8 text; blank lines are ignored).

    Accepted: four numbers per row; frame and agent ids whole numbers in [0, 2^53) (float64 holds them
    exactly); finite positions with |x|, |y| <= 1000 m; frames in non-decreasing order; no (frame, agent)
    pair twice. Only regular files of at most ``MAX_RECORDING_BYTES`` (64 MiB) are read; parsing holds
    about 64 bytes per row (about 8x the file at its smallest rows, under 1 GiB).

    Raises:
        RecordingError: any of the above broken, or an empty file; the message names file, line and field.
        NotRegularFileError: a FIFO, device or folder.  MemoryBudgetError: a larger file.
    """
    path = Path(path)
    with open_regular(path, MAX_RECORDING_BYTES, "recording") as stream:
        table = _parse_table(stream, path)
        frame, agent = _checked_ids(table, stream, path)
        xy_m = table[:, 2:4].copy()
        _check_positions(xy_m, stream, path)
        backwards = np.flatnonzero(np.diff(frame) < 0)
        if backwards.size:
            raise _bad_row(stream, path, int(backwards[0]) + 1, "frames not sorted (frame id goes down)", "frame")
        order = np.lexsort((agent, frame))
        same = (np.diff(frame[order]) == 0) & (np.diff(agent[order]) == 0)
        if same.any():
            row = int(np.sort(order[np.flatnonzero(same) + 1])[0])
            raise _bad_row(stream, path, row, "duplicate (frame, agent) row", "agent")
    return Recording(name=path.stem, frame=frame, agent=agent, xy_m=xy_m, path=path)


def _parse_table(stream: BinaryIO, path: Path) -> np.ndarray:
    """(R, 4) float64 rows, parsed by numpy's C reader; on failure the first bad line is found and named."""
    text = io.TextIOWrapper(stream, encoding="utf-8", newline=None)
    try:
        table = parse_numbers(text)
    except MemoryBudgetError:
        raise
    except ValueError as err:  # also UnicodeDecodeError
        raise _first_bad_line(stream, path) or RecordingError(f"{path}: cannot parse ({err})", path=path) from err
    finally:
        text.detach()
    if table.shape[0] == 0:
        raise RecordingError(f"{path}: empty file, expected rows 'frame agent x y'", path=path)
    if table.shape[1] != N_COLUMNS:
        raise _bad_row(stream, path, 0, f"expected {N_COLUMNS} numbers (frame, agent, x, y), got {table.shape[1]}")
    return table


def _checked_ids(table: np.ndarray, stream: BinaryIO, path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(R,) int64 frame and agent ids after checking they are finite whole numbers in [0, ID_LIMIT)."""
    for col, field in enumerate(FIELDS[:2]):
        ids = table[:, col]
        bad = np.flatnonzero(~np.isfinite(ids))
        if bad.size:
            raise _bad_row(stream, path, int(bad[0]), f"{field} id is NaN or infinite", field)
        bad = np.flatnonzero(ids != np.round(ids))
        if bad.size:
            raise _bad_row(stream, path, int(bad[0]), "frame and agent ids must be whole numbers", field)
        bad = np.flatnonzero((ids < 0) | (ids >= ID_LIMIT))
        if bad.size:
            raise _bad_row(stream, path, int(bad[0]), f"{field} id {ids[bad[0]]:.17g} outside [0, 2^53): ids "
                           "must be whole numbers that float64 holds exactly, and -1 marks an empty row", field)
    return table[:, 0].astype(np.int64), table[:, 1].astype(np.int64)


def _check_positions(xy_m: np.ndarray, stream: BinaryIO, path: Path) -> None:
    for col, field in enumerate(FIELDS[2:]):
        values = xy_m[:, col]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise _bad_row(stream, path, int(bad[0]), "NaN or infinite value", field)
        bad = np.flatnonzero(np.abs(values) > POSITION_LIMIT_M)
        if bad.size:
            raise _bad_row(stream, path, int(bad[0]), f"{field} beyond +-{POSITION_LIMIT_M:g} m", field)


def _content_lines(stream: BinaryIO) -> Iterator[tuple[int, str | None, bytes]]:
    """(line number, decoded text or None if not UTF-8, raw bytes) of every line, streamed from the start.

    Lines break at \\n, \\r and \\r\\n, as the text reader used by the parser breaks them.
    """
    stream.seek(0)
    number = 0
    for chunk in stream:
        for raw in chunk.splitlines():
            number += 1
            try:
                yield number, raw.decode("utf-8"), raw
            except UnicodeDecodeError:
                yield number, None, raw


def _first_bad_line(stream: BinaryIO, path: Path) -> RecordingError | None:
    """The error for the first line numpy's reader would refuse, or None if none is found."""
    for number, line, raw in _content_lines(stream):
        if line is None:
            return RecordingError(f"{path}:{number}: not UTF-8 text: {_excerpt(raw)}", path=path, line=number)
        tokens = line.split()
        if tokens and len(tokens) != N_COLUMNS:
            return RecordingError(f"{path}:{number}: expected {N_COLUMNS} numbers (frame, agent, x, y), got "
                                  f"{len(tokens)}: {_excerpt(line)}", path=path, line=number)
        for field, token in zip(FIELDS, tokens, strict=False):
            if not _is_number(token):
                return RecordingError(f"{path}:{number}: {field} is not a number: {_excerpt(line)}",
                                      path=path, line=number, field=field)
    return None


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return "_" not in token  # Python reads 1_000, numpy's reader does not


def _bad_row(stream: BinaryIO, path: Path, row: int, problem: str, field: str | None = None) -> RecordingError:
    """Error naming the line that holds data row ``row`` (0-based, blank lines skipped)."""
    rows = ((number, line) for number, line, _ in _content_lines(stream) if line is not None and line.split())
    number, line = next(itertools.islice(rows, row, None), (None, ""))
    where = f"{path}:{number}" if number is not None else str(path)
    return RecordingError(f"{where}: {problem}: {_excerpt(line)}", path=path, line=number, field=field)


def _excerpt(line: str | bytes, width: int = 80) -> str:
    text = repr(line.strip())
    return text if len(text) <= width else text[:width] + "..."


def write_recording(path: str | os.PathLike, frame: np.ndarray, agent: np.ndarray, xy_m: np.ndarray) -> Path:
    """Write rows in the ETH/UCY text format, sorted by (frame, agent), atomically (temp file + rename).

    Args:
        frame: (R,) int frame ids.  agent: (R,) int agent ids, both in [0, 2^53).
        xy_m: (R, 2) metres, finite, |x|, |y| <= 1000 m.

    Raises:
        ValueError: values ``read_recording`` would refuse; nothing is written.
    """
    path = Path(path)
    frame, agent, xy_m = np.asarray(frame), np.asarray(agent), np.asarray(xy_m, dtype=np.float64)
    if not np.isfinite(xy_m).all():
        raise ValueError(f"{path}: refusing to write NaN/inf positions")
    if np.abs(xy_m).max(initial=0.0) > POSITION_LIMIT_M:
        raise ValueError(f"{path}: refusing to write positions beyond +-{POSITION_LIMIT_M:g} m (unreadable)")
    for name, ids in (("frame", frame), ("agent", agent)):
        if ids.dtype.kind not in "iu" or ids.min(initial=0) < 0 or ids.max(initial=0) >= ID_LIMIT:
            raise ValueError(f"{path}: refusing to write {name} ids that are not whole numbers in [0, 2^53)")
    order = np.lexsort((agent, frame))
    body = "".join(
        f"{f:d}\t{a:d}\t{x:.6f}\t{y:.6f}\n"
        for f, a, (x, y) in zip(frame[order].tolist(), agent[order].tolist(), xy_m[order].tolist(), strict=True)
    )
    write_text_atomic(path, body)
    return path
