"""The CITR reader (``replays.citr``): CITR itself reads whole, valid files parse exactly, and every class of hostile
file (malformed rows, NaN/inf, frames that repeat or go down, empty files, missing columns, a wrong label, bytes that
are not text, a vehicle file without its pedestrian file) raises ``RecordingError`` naming the file and the line,
with nothing returned."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from replays.citr import (
    CITR_FPS,
    PED_SUFFIX,
    VEH_SUFFIX,
    TrackKind,
    find_experiments,
    on_grid,
    read_experiment,
    read_tracks,
)
from replays.constants import POSITION_LIMIT_M
from replays.data_root import CITR, data_root
from replays.errors import RecordingError

CITR_ROOT = data_root(dataset=CITR)  # $STCROWD_CITR in CI (../shared/datasets/citr); missing: a failure
DRAWS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
HEADER = {TrackKind.PEDESTRIAN: "id,frame,label,x_est,y_est,vx_est,vy_est",
          TrackKind.VEHICLE: "id,frame,label,x_est,y_est,psi_est,vel_est"}


def test_citr_reads_every_experiment_with_a_vehicle() -> None:
    experiments = find_experiments(CITR_ROOT)
    folders = {e.name.split("/")[0] for e in experiments}
    assert len(experiments) == 26 and folders == {"vci_front", "vci_back", "vci_lat_uni", "vci_lat_bi"}
    for experiment in experiments:
        assert len(experiment.vehicles.ids) == 1 and len(experiment.pedestrians.ids) == 8, experiment
        assert experiment.fps == CITR_FPS
        peds = experiment.pedestrians
        for object_id in peds.ids:
            frames = peds.frame[peds.rows_of(int(object_id))]
            assert (np.diff(frames) > 0).all(), f"{experiment}: frames of {object_id} not increasing"


@st.composite
def tables(draw, kind: TrackKind) -> list[tuple]:
    """Rows of a valid file: ids interleaved in any order, each with increasing frames (gaps allowed), finite values
    within their bounds."""
    tracks = []
    for object_id in draw(st.lists(st.integers(0, 2**40), min_size=1, max_size=4, unique=True)):
        frames = sorted(draw(st.lists(st.integers(10, 10**6), min_size=1, max_size=8, unique=True)))
        track = []
        for frame in frames:
            values = draw(st.lists(st.floats(-POSITION_LIMIT_M, POSITION_LIMIT_M), min_size=2, max_size=2))
            state = draw(st.lists(st.floats(-50, 50), min_size=2, max_size=2))
            track.append((object_id, frame, kind.label, *values, *state))
        tracks.append(track)
    order = draw(st.permutations([k for k, track in enumerate(tracks) for _ in track]))  # ids interleaved
    queues = [iter(track) for track in tracks]
    return [next(queues[k]) for k in order]


def text_of(kind: TrackKind, rows: list[tuple], newline: str = "\n") -> str:
    return newline.join([HEADER[kind], *(",".join(str(v) if isinstance(v, str | int) else repr(v) for v in row)
                                         for row in rows)]) + newline


@DRAWS
@given(data=st.data(), kind=st.sampled_from(list(TrackKind)), newline=st.sampled_from(["\n", "\r\n"]))
def test_valid_files_parse_exactly_sorted_by_id_and_frame(tmp_path: Path, data, kind: TrackKind, newline: str) -> None:
    rows = data.draw(tables(kind))
    path = tmp_path / "t.csv"
    path.write_text(text_of(kind, rows, newline))
    tracks = read_tracks(path, kind)
    expected = sorted(rows, key=lambda r: (r[0], r[1]))
    assert tracks.id.tolist() == [r[0] for r in expected] and tracks.frame.tolist() == [r[1] for r in expected]
    assert tracks.xy_m.tolist() == [[r[3], r[4]] for r in expected]
    assert tracks.state.tolist() == [[r[5], r[6]] for r in expected]


BAD_TOKENS = ["nan", "inf", "-inf", "NaN", "x", "", "1_0", "1e999", "0x10"]
HOSTILE = {
    "a field too many": lambda row: row + ",1",
    "a field too few": lambda row: row.rsplit(",", 1)[0],
    "a bad x": lambda row: _replace_field(row, 3, "nan"),
    "an infinite velocity or speed": lambda row: _replace_field(row, 6, "inf"),
    "a position beyond 1000 m": lambda row: _replace_field(row, 4, "1000.5"),
    "a negative id": lambda row: _replace_field(row, 0, "-1"),
    "a fractional frame": lambda row: _replace_field(row, 1, "3.5"),
    "another label": lambda row: _replace_field(row, 2, "dog"),
    "bytes that are not UTF-8": lambda row: row + "\udcff",
}


def _replace_field(row: str, index: int, value: str) -> str:
    fields = row.split(",")
    fields[index] = value
    return ",".join(fields)


@DRAWS
@given(data=st.data(), kind=st.sampled_from(list(TrackKind)), attack=st.sampled_from(sorted(HOSTILE)),
       token=st.sampled_from(BAD_TOKENS))
def test_a_hostile_row_is_refused_naming_the_file_and_its_line(tmp_path: Path, data, kind: TrackKind, attack: str,
                                                               token: str) -> None:
    lines = text_of(kind, data.draw(tables(kind))).splitlines()
    victim = data.draw(st.integers(1, len(lines) - 1))  # a data row (line victim + 1)
    lines[victim] = HOSTILE[attack](lines[victim]) if attack != "a bad x" else _replace_field(lines[victim], 3, token)
    path = tmp_path / "t.csv"
    path.write_bytes("\n".join(lines).encode("utf-8", "surrogateescape"))
    with pytest.raises(RecordingError, match=re.escape(f"{path}:{victim + 1}:")) as err:
        read_tracks(path, kind)
    assert err.value.line == victim + 1


@DRAWS
@given(data=st.data(), kind=st.sampled_from(list(TrackKind)), repeat=st.booleans())
def test_frames_that_repeat_or_go_down_within_an_id_are_refused_at_their_line(tmp_path: Path, data, kind: TrackKind,
                                                                              repeat: bool) -> None:
    rows = sorted(data.draw(tables(kind)), key=lambda r: (r[0], r[1]))
    pick = data.draw(st.integers(0, len(rows) - 1))
    object_id, frame = rows[pick][0], rows[pick][1]
    bad = (object_id, frame if repeat else frame - 1 - data.draw(st.integers(0, 5)), *rows[pick][2:])
    rows.insert(pick + 1, bad)  # right after the row it repeats or undercuts
    path = tmp_path / "t.csv"
    path.write_text(text_of(kind, rows))
    with pytest.raises(RecordingError, match=re.escape(f"{path}:{pick + 3}:") + ".*frames of an id must increase"):
        read_tracks(path, kind)


@pytest.mark.parametrize("content", ["", "\n\n  \n", HEADER[TrackKind.PEDESTRIAN] + "\n"],
                         ids=["empty", "blank lines", "header only"])
def test_a_file_without_rows_is_refused(tmp_path: Path, content: str) -> None:
    path = tmp_path / "t.csv"
    path.write_text(content)
    with pytest.raises(RecordingError, match=re.escape(str(path))):
        read_tracks(path, TrackKind.PEDESTRIAN)


@DRAWS
@given(kind=st.sampled_from(list(TrackKind)), data=st.data())
def test_a_header_missing_a_column_names_it(tmp_path: Path, kind: TrackKind, data) -> None:
    names = HEADER[kind].split(",")
    missing = data.draw(st.sampled_from(names))
    path = tmp_path / "t.csv"
    path.write_text(",".join(n for n in names if n != missing) + "\n1,2,3,4,5,6\n")
    with pytest.raises(RecordingError, match=re.escape(f"{path}:1: missing column(s) {missing}")):
        read_tracks(path, kind)


def test_columns_in_another_order_and_extra_columns_are_read_by_name(tmp_path: Path) -> None:
    path = tmp_path / "t.csv"
    path.write_text("note,vy_est,vx_est,y_est,x_est,label,frame,id\nA,0.5,0.25,2.0,1.0,ped,7,3\n")
    tracks = read_tracks(path, TrackKind.PEDESTRIAN)
    assert tracks.id.tolist() == [3] and tracks.frame.tolist() == [7]
    assert tracks.xy_m.tolist() == [[1.0, 2.0]] and tracks.state.tolist() == [[0.25, 0.5]]


def _experiment(folder: Path, name: str) -> Path:
    """A small valid experiment NAME in ``folder``; returns its vehicle file."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}{PED_SUFFIX}").write_text(HEADER[TrackKind.PEDESTRIAN] + "\n1,0,ped,0,0,1,0\n1,30,ped,1,0,1,0\n")
    vehicle = folder / f"{name}{VEH_SUFFIX}"
    vehicle.write_text(HEADER[TrackKind.VEHICLE] + "\n1,0,veh,5,1,3.14,2\n1,30,veh,3,1,3.14,2\n")
    return vehicle


def test_a_vehicle_file_without_its_pedestrian_file_is_refused_naming_it(tmp_path: Path) -> None:
    vehicle = _experiment(tmp_path / "a", "run_01")
    (tmp_path / "a" / f"run_01{PED_SUFFIX}").unlink()
    with pytest.raises(RecordingError, match=re.escape(str(vehicle)) + ".*without its pedestrian file"):
        find_experiments(tmp_path)


def test_one_bad_experiment_loads_none(tmp_path: Path) -> None:
    _experiment(tmp_path / "a", "run_01")
    bad = _experiment(tmp_path / "b" / "deeper", "run_02")
    bad.write_text(bad.read_text() + "1,30,veh,3,1,3.14,2\n")  # frame 30 again
    with pytest.raises(RecordingError, match=re.escape(f"{bad}:4:")):
        find_experiments(tmp_path)
    bad.unlink()
    (bad.parent / f"run_02{PED_SUFFIX}").unlink()
    assert [e.name for e in find_experiments(tmp_path)] == ["a/run_01"]


def test_a_folder_without_vehicle_files_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no vehicle recording"):
        find_experiments(tmp_path)


@pytest.mark.parametrize("fps", [0.0, -29.97, float("nan"), float("inf")])
def test_a_frame_rate_that_is_not_positive_is_refused(tmp_path: Path, fps: float) -> None:
    with pytest.raises(ValueError, match="fps"):
        read_experiment(_experiment(tmp_path, "run"), fps)


def test_the_grid_interpolates_tracks_at_the_step_and_keeps_the_frames_covered() -> None:
    """On CITR: every pedestrian is on the 0.4 s grid exactly between its first and its last frame, and the grid's
    positions lie on the recorded ones where a step falls on a frame."""
    for experiment in find_experiments(CITR_ROOT)[:6]:
        grid = on_grid(experiment, 0.4)
        frames = experiment.vehicles.frame[0] + grid.times_s * experiment.fps
        peds = experiment.pedestrians
        for column, object_id in enumerate(grid.pedestrian_ids):
            rows = peds.rows_of(int(object_id))
            covered = (frames >= peds.frame[rows][0]) & (frames <= peds.frame[rows][-1])
            assert np.array_equal(grid.present[:, column], covered), f"{experiment} pedestrian {object_id}"
            exact = np.isin(frames, peds.frame[rows])
            recorded = peds.xy_m[rows][np.searchsorted(peds.frame[rows], frames[exact].astype(int))]
            assert np.allclose(grid.xy_m[exact, column], recorded), f"{experiment} pedestrian {object_id}"
