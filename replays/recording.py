"""One recording: rows ``frame_id agent_id x y`` (metres, world frame), parsed strictly and fast.

``read_recording`` is the only parser: every loader, the environments and the simulator's replay
files go through it. ``write_recording`` writes the same format atomically.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from replays.atomic import write_text_atomic
from replays.errors import DataFormatError

N_COLUMNS = 4  # frame_id, agent_id, x [m], y [m]


@dataclass(frozen=True, eq=False)
class Recording:
    """Rows of one recording file, sorted by frame.

    Attributes:
        name: file stem, e.g. ``"crowds_zara01_train"``.
        frame: (R,) int64 frame ids (consecutive annotated frames differ by 10 in ETH/UCY).
        agent: (R,) int64 agent ids.
        xy_m: (R, 2) float64 positions, metres, world frame.
    """

    name: str
    frame: np.ndarray
    agent: np.ndarray
    xy_m: np.ndarray

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

    def dense(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions on the (listed frame x agent) grid.

        Returns:
            xy_m: (F, A, 2) float64 metres, NaN where the agent is absent.
            present: (F, A) bool.
        """
        f_idx = np.searchsorted(self.frames, self.frame)
        a_idx = np.searchsorted(self.agents, self.agent)
        xy = np.full((len(self.frames), len(self.agents), 2), np.nan)
        present = np.zeros((len(self.frames), len(self.agents)), bool)
        xy[f_idx, a_idx] = self.xy_m
        present[f_idx, a_idx] = True
        return xy, present


def _bad_line(path: Path, lines: list[str], problem_rows: np.ndarray, what: str) -> DataFormatError:
    row = int(problem_rows[0])
    return DataFormatError(f"{path}:{row + 1}: {what}: {lines[row].strip()!r}")


def read_recording(path: str | os.PathLike) -> Recording:
    """Parse a whitespace-separated ``frame agent x y`` file.

    Raises:
        DataFormatError: empty file, wrong column count, non-numbers, NaN/inf, non-integer ids,
            unsorted frames or a duplicate (frame, agent) row; the message names file and line.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise DataFormatError(f"{path}: cannot read as text ({err})") from err
    lines = [line for line in text.splitlines()]
    content = [i for i, line in enumerate(lines) if line.strip()]
    if not content:
        raise DataFormatError(f"{path}: empty file, expected rows 'frame agent x y'")
    tokens = [lines[i].split() for i in content]
    counts = np.fromiter((len(t) for t in tokens), int, len(tokens))
    wrong = np.flatnonzero(counts != N_COLUMNS)
    if wrong.size:
        raise _bad_line(path, lines, np.asarray(content)[wrong],
                        f"expected {N_COLUMNS} numbers (frame, agent, x, y), got {counts[wrong[0]]}")
    try:
        table = np.array(tokens, dtype=np.float64)
    except ValueError:
        for i, row_tokens in zip(content, tokens, strict=True):
            try:
                [float(t) for t in row_tokens]
            except ValueError as err:
                raise DataFormatError(f"{path}:{i + 1}: not a number: {lines[i].strip()!r}") from err
        raise
    rows = np.asarray(content)
    finite = np.isfinite(table).all(axis=1)
    if not finite.all():
        raise _bad_line(path, lines, rows[~finite], "NaN or infinite value")
    ids = table[:, :2]
    integral = (ids == np.round(ids)).all(axis=1)
    if not integral.all():
        raise _bad_line(path, lines, rows[~integral], "frame and agent ids must be whole numbers")
    frame = ids[:, 0].astype(np.int64)
    agent = ids[:, 1].astype(np.int64)
    backwards = np.flatnonzero(np.diff(frame) < 0)
    if backwards.size:
        raise _bad_line(path, lines, rows[backwards + 1], "frames not sorted (frame id goes down)")
    order = np.lexsort((agent, frame))
    same = (np.diff(frame[order]) == 0) & (np.diff(agent[order]) == 0)
    if same.any():
        dup = rows[np.sort(order[np.flatnonzero(same) + 1])]
        raise _bad_line(path, lines, dup, "duplicate (frame, agent) row")
    return Recording(name=path.stem, frame=frame, agent=agent, xy_m=table[:, 2:4].copy())


def write_recording(path: str | os.PathLike, frame: np.ndarray, agent: np.ndarray, xy_m: np.ndarray) -> Path:
    """Write rows in the ETH/UCY text format, sorted by (frame, agent), atomically (temp file + rename).

    Args:
        frame: (R,) int frame ids.  agent: (R,) int agent ids.  xy_m: (R, 2) metres.
    """
    path = Path(path)
    frame, agent, xy_m = np.asarray(frame), np.asarray(agent), np.asarray(xy_m, dtype=np.float64)
    if not np.isfinite(xy_m).all():
        raise ValueError(f"{path}: refusing to write NaN/inf positions")
    order = np.lexsort((agent, frame))
    body = "".join(
        f"{f:d}\t{a:d}\t{x:.6f}\t{y:.6f}\n"
        for f, a, (x, y) in zip(frame[order].tolist(), agent[order].tolist(), xy_m[order].tolist(), strict=True)
    )
    write_text_atomic(path, body)
    return path
