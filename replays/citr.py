"""Recordings of pedestrians and a vehicle in CITR's filtered layout (Yang et al., IV 2019), parsed strictly.

Per experiment ``NAME``, ``NAME_traj_ped_filtered.csv`` holds the pedestrians (columns ``id,frame,label,x_est,y_est,
vx_est,vy_est``: a Kalman-filtered position [m] and velocity [m/s]) and, with a vehicle, ``NAME_traj_veh_filtered.csv``
the vehicle (``id,frame,label,x_est,y_est,psi_est,vel_est``: centre [m], heading [rad], speed [m/s]). Frames are video
frames (CITR: 29.97 per second). Any recording laid out like this is read the same way; ``find_experiments`` reads
every experiment with a vehicle under a folder, subfolders included.

Accepted: UTF-8 text, a header line naming every column (in any order; more columns are ignored), then rows with as
many comma-separated fields as the header; ids and frames whole numbers in [0, 2^53); the label of the file's kind
(``ped`` or ``veh``); finite numbers, positions within +-1000 m, speeds within +-100 m/s; the frames of each id
strictly increasing (gaps allowed). Anything else raises ``RecordingError`` naming the file, the line and the field,
before anything is returned: an experiment is read whole or not at all.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from enum import Enum
from functools import cached_property
from pathlib import Path
from typing import Final

import numpy as np

from replays.constants import ID_LIMIT, POSITION_LIMIT_M
from replays.errors import RecordingError
from replays.files import read_bytes

CITR_FPS: Final[float] = 29.97  # CITR's drone video frame rate [1/s]
CART_LENGTH_M: Final[float] = 2.40  # CITR's EZ-GO golf cart, overall length (E-Z-GO TXT: 94.5 in) [m] ...
CART_WIDTH_M: Final[float] = 1.20  # ... and width (47 in); the tracked position is its centre [m]
MAX_CSV_BYTES: Final[int] = 64 << 20  # largest file read [B]; CITR's largest is 0.3 MB
SPEED_LIMIT_MPS: Final[float] = 100.0  # |velocity| components and speeds beyond this are refused [m/s]
HEADING_LIMIT_RAD: Final[float] = 1000.0  # |heading| beyond this is refused [rad]
PED_SUFFIX: Final[str] = "_traj_ped_filtered.csv"
VEH_SUFFIX: Final[str] = "_traj_veh_filtered.csv"


class TrackKind(Enum):
    """What a filtered CSV holds: its label, and the names of its two state columns after x and y."""

    PEDESTRIAN = ("ped", ("vx_est", "vy_est"))
    VEHICLE = ("veh", ("psi_est", "vel_est"))

    @property
    def label(self) -> str:
        return self.value[0]

    @property
    def columns(self) -> tuple[str, ...]:
        """The columns every file of this kind must name, in the order of ``Tracks``' arrays."""
        return ("id", "frame", "label", "x_est", "y_est", *self.value[1])


@dataclass(frozen=True, eq=False)
class Tracks:
    """The rows of one filtered CSV, sorted by (id, frame).

    Attributes:
        path: the file.  kind: pedestrians or a vehicle.
        id: (R,) int64 object ids.  frame: (R,) int64 video frames.
        xy_m: (R, 2) float64 positions [m].
        state: (R, 2) float64: velocity (vx, vy) [m/s] of pedestrians; heading [rad] and speed [m/s] of vehicles.
    """

    path: Path
    kind: TrackKind
    id: np.ndarray
    frame: np.ndarray
    xy_m: np.ndarray
    state: np.ndarray

    def __repr__(self) -> str:
        return f"Tracks({self.path.name}: {len(self.ids)} {self.kind.label}, {len(self.id)} rows)"

    @cached_property
    def ids(self) -> np.ndarray:
        """(N,) sorted unique object ids."""
        return np.unique(self.id)

    def rows_of(self, object_id: int) -> slice:
        """The rows of one object (contiguous, frames increasing)."""
        first, last = np.searchsorted(self.id, [object_id, object_id + 1])
        return slice(int(first), int(last))


@dataclass(frozen=True, eq=False)
class Experiment:
    """One recorded experiment: its pedestrians and its vehicle(s).

    Attributes:
        name: the file stem without its suffix, relative to the folder searched (``vci_front/front_interaction_01``).
        pedestrians, vehicles: the two files' tracks.
        fps: video frames per second.
    """

    name: str
    pedestrians: Tracks
    vehicles: Tracks
    fps: float

    def __repr__(self) -> str:
        return f"Experiment({self.name}: {len(self.pedestrians.ids)} pedestrians, {len(self.vehicles.ids)} vehicles)"


def read_tracks(path: str | os.PathLike, kind: TrackKind) -> Tracks:
    """Parse one filtered CSV of pedestrians or vehicles (rules in the module docstring).

    Raises:
        RecordingError: a malformed header or row, an empty file, frames that repeat or go down within an id; the
            message names the file, the line and the field.  NotRegularFileError: a FIFO, device or folder.
        MemoryBudgetError: a file over 64 MiB.
    """
    path = Path(path)
    lines = _lines(path)
    header_at, header = next(((n, line) for n, line in lines if line.strip()), (None, ""))
    if header_at is None:
        raise RecordingError(f"{path}: empty file, expected a header naming {','.join(kind.columns)}", path=path)
    names = [name.strip() for name in header.split(",")]
    missing = [column for column in kind.columns if column not in names]
    if missing:
        raise RecordingError(f"{path}:{header_at}: missing column(s) {', '.join(missing)}; the header must name "
                             f"{','.join(kind.columns)}: {_excerpt(header)}", path=path, line=header_at,
                             field=missing[0])
    where = [names.index(column) for column in kind.columns]
    ids, frames, values, numbers = [], [], [], []
    for number, line in lines:
        if number <= header_at or not line.strip():
            continue
        fields = [field.strip() for field in line.split(",")]
        if len(fields) != len(names):
            raise RecordingError(f"{path}:{number}: expected {len(names)} comma-separated fields as the header "
                                 f"names, got {len(fields)}: {_excerpt(line)}", path=path, line=number)
        row = [fields[k] for k in where]
        ids.append(_whole(row[0], "id", path, number, line))
        frames.append(_whole(row[1], "frame", path, number, line))
        if row[2] != kind.label:
            raise RecordingError(f"{path}:{number}: label {row[2]!r}, expected {kind.label!r} in a "
                                 f"{kind.name.lower()} file: {_excerpt(line)}", path=path, line=number, field="label")
        values.append([_bounded(token, column, kind, path, number, line)
                       for token, column in zip(row[3:], kind.columns[3:], strict=True)])
        numbers.append(number)
    if not ids:
        raise RecordingError(f"{path}: no rows after the header", path=path)
    return _sorted_tracks(path, kind, np.array(ids, np.int64), np.array(frames, np.int64),
                          np.array(values, np.float64), np.array(numbers))


def _lines(path: Path) -> list[tuple[int, str]]:
    """(1-based line number, text) of every line; a line that is not UTF-8 is refused by number."""
    lines = []
    for number, raw in enumerate(read_bytes(path, MAX_CSV_BYTES, "CSV file").splitlines(), 1):
        try:
            lines.append((number, raw.decode("utf-8")))
        except UnicodeDecodeError as err:
            raise RecordingError(f"{path}:{number}: not UTF-8 text: {_excerpt(raw)}", path=path, line=number) from err
    return lines


def _whole(token: str, field: str, path: Path, number: int, line: str) -> int:
    """An id or frame: a whole number in [0, 2^53) ("12" or "12.0")."""
    value = _number(token, field, path, number, line)
    if not math.isfinite(value) or value != round(value) or not 0 <= value < ID_LIMIT:
        raise RecordingError(f"{path}:{number}: {field} {token!r} is not a whole number in [0, 2^53): "
                             f"{_excerpt(line)}", path=path, line=number, field=field)
    return int(value)


def _bounded(token: str, column: str, kind: TrackKind, path: Path, number: int, line: str) -> float:
    """A finite value within its column's bound (position, speed or heading)."""
    value = _number(token, column, path, number, line)
    limit = POSITION_LIMIT_M if column in ("x_est", "y_est") else \
        HEADING_LIMIT_RAD if column == "psi_est" else SPEED_LIMIT_MPS
    if not math.isfinite(value) or abs(value) > limit:
        raise RecordingError(f"{path}:{number}: {column} {token!r} is NaN, infinite or beyond +-{limit:g}: "
                             f"{_excerpt(line)}", path=path, line=number, field=column)
    return value


def _number(token: str, field: str, path: Path, number: int, line: str) -> float:
    try:
        if "_" in token:  # Python reads 1_000; no CSV writer does
            raise ValueError(token)
        return float(token)
    except ValueError:
        raise RecordingError(f"{path}:{number}: {field} is not a number: {_excerpt(line)}", path=path, line=number,
                             field=field) from None


def _sorted_tracks(path: Path, kind: TrackKind, ids: np.ndarray, frames: np.ndarray, values: np.ndarray,
                   numbers: np.ndarray) -> Tracks:
    """Rows sorted by (id, frame), after refusing frames that repeat or go down within an id (in file order)."""
    order = np.argsort(ids, kind="stable")  # file order within each id
    same = ids[order][1:] == ids[order][:-1]
    step = np.diff(frames[order])
    bad = np.flatnonzero(same & (step <= 0))
    if bad.size:
        row, before = order[bad[0] + 1], frames[order][bad[0]]
        problem = "again" if step[bad[0]] == 0 else f"after frame {before}"
        raise RecordingError(f"{path}:{numbers[row]}: frame {frames[row]} of id {ids[row]} comes {problem}: the "
                             "frames of an id must increase", path=path, line=int(numbers[row]), field="frame")
    return Tracks(path, kind, ids[order], frames[order], values[order, :2].copy(), values[order, 2:].copy())


def _excerpt(line: str | bytes, width: int = 80) -> str:
    text = repr(line.strip())
    return text if len(text) <= width else text[:width] + "..."


def read_experiment(vehicle_path: str | os.PathLike, fps: float = CITR_FPS, name: str | None = None) -> Experiment:
    """Read an experiment from its vehicle file and the pedestrian file beside it (``..._traj_ped_filtered.csv``).

    Raises:
        RecordingError: the pedestrian file is missing, or either file is malformed.  ValueError: ``fps`` not a
            positive finite number.
    """
    vehicle_path = Path(vehicle_path)
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps={fps!r}: expected a positive frame rate [1/s]")
    if not vehicle_path.name.endswith(VEH_SUFFIX):
        raise RecordingError(f"{vehicle_path}: a vehicle file's name ends with {VEH_SUFFIX}", path=vehicle_path)
    pedestrian_path = vehicle_path.with_name(vehicle_path.name.removesuffix(VEH_SUFFIX) + PED_SUFFIX)
    if not pedestrian_path.is_file():
        raise RecordingError(f"{vehicle_path}: vehicle file without its pedestrian file {pedestrian_path.name}",
                             path=vehicle_path)
    vehicles = read_tracks(vehicle_path, TrackKind.VEHICLE)
    pedestrians = read_tracks(pedestrian_path, TrackKind.PEDESTRIAN)
    return Experiment(name or vehicle_path.name.removesuffix(VEH_SUFFIX), pedestrians, vehicles, float(fps))


def find_experiments(root: str | os.PathLike, fps: float = CITR_FPS) -> list[Experiment]:
    """Every experiment with a vehicle under ``root`` (subfolders included), sorted by name; all read or none.

    Raises:
        RecordingError: no vehicle file under ``root``, or any experiment's files malformed (the first one found).
        NotADirectoryError: ``root`` is not a folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise NotADirectoryError(f"{root}: not a folder of recordings (expected files *{VEH_SUFFIX} and "
                                 f"*{PED_SUFFIX}, in it or in its subfolders)")
    paths = sorted(root.rglob(f"*{VEH_SUFFIX}"))
    if not paths:
        raise RecordingError(f"{root}: no vehicle recording (*{VEH_SUFFIX}) in it or its subfolders", path=root)
    return [read_experiment(path, fps, path.relative_to(root).as_posix().removesuffix(VEH_SUFFIX)) for path in paths]


@dataclass(frozen=True, eq=False)
class Grid:
    """An experiment resampled every ``step_s`` seconds over its vehicle's recording (linear interpolation between
    frames; a pedestrian is on the grid between its first and its last frame).

    Attributes:
        times_s: (T,) seconds since the vehicle's first frame.
        pedestrian_ids: (N,) int64.
        xy_m: (T, N, 2) pedestrian positions [m], NaN where not recorded.  present: (T, N) bool.
        vehicle_xy_m: (T, 2) the vehicle's centre [m].  vehicle_heading_rad: (T,) its heading, unwrapped [rad].
        vehicle_speed_mps: (T,) its speed [m/s].
    """

    times_s: np.ndarray
    pedestrian_ids: np.ndarray
    xy_m: np.ndarray
    present: np.ndarray
    vehicle_xy_m: np.ndarray
    vehicle_heading_rad: np.ndarray
    vehicle_speed_mps: np.ndarray


def on_grid(experiment: Experiment, step_s: float) -> Grid:
    """``experiment`` resampled every ``step_s`` seconds from its vehicle's first frame to its last.

    Raises:
        RecordingError: the experiment has more than one vehicle, or its vehicle spans less than two steps.
    """
    vehicles = experiment.vehicles
    if len(vehicles.ids) != 1:
        raise RecordingError(f"{vehicles.path}: {len(vehicles.ids)} vehicles (ids {vehicles.ids.tolist()[:5]}); "
                             "an experiment is validated with one vehicle", path=vehicles.path)
    frames_per_step = step_s * experiment.fps
    first, last = vehicles.frame[0], vehicles.frame[-1]
    steps = int((last - first) / frames_per_step) + 1
    if steps < 2:
        raise RecordingError(f"{vehicles.path}: the vehicle is recorded for {last - first + 1} frames, less than two "
                             f"steps of {step_s:g} s", path=vehicles.path)
    frames = first + frames_per_step * np.arange(steps)
    columns = (*vehicles.xy_m.T, np.unwrap(vehicles.state[:, 0]), vehicles.state[:, 1])
    vehicle = [np.interp(frames, vehicles.frame, values) for values in columns]
    pedestrians = experiment.pedestrians
    xy = np.full((steps, len(pedestrians.ids), 2), np.nan)
    for column, object_id in enumerate(pedestrians.ids):
        rows = pedestrians.rows_of(int(object_id))
        own = pedestrians.frame[rows]
        inside = (frames >= own[0]) & (frames <= own[-1])
        for axis in range(2):
            xy[inside, column, axis] = np.interp(frames[inside], own, pedestrians.xy_m[rows, axis])
    return Grid(step_s * np.arange(steps), pedestrians.ids.copy(), xy, ~np.isnan(xy[..., 0]),
                np.stack(vehicle[:2], axis=-1), vehicle[2], vehicle[3])
