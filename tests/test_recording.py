from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from replays import DataFormatError, read_recording, write_recording

GOOD = "0\t1\t1.0\t2.0\n0\t2\t3.0\t4.0\n10\t1\t1.5\t2.5\n"

BAD_FILES = {
    "wrong_columns": ("0\t1\t1.0\t2.0\n10\t1\t1.5\n", 2, "expected 4 numbers"),
    "not_a_number": ("0\t1\t1.0\t2.0\n10\t1\tabc\t2.5\n", 2, "not a number"),
    "nan": ("0\t1\t1.0\t2.0\n10\t1\tnan\t2.5\n", 2, "NaN or infinite"),
    "inf": ("0\t1\tinf\t2.0\n", 1, "NaN or infinite"),
    "duplicate": ("0\t1\t1.0\t2.0\n0\t2\t1.0\t2.0\n0\t1\t5.0\t5.0\n", 3, "duplicate"),
    "unsorted": ("10\t1\t1.0\t2.0\n0\t1\t1.0\t2.0\n", 2, "not sorted"),
    "fractional_id": ("0\t1.5\t1.0\t2.0\n", 1, "whole numbers"),
}


@pytest.mark.parametrize("case", list(BAD_FILES), ids=list(BAD_FILES))
def test_read_recording_bad_row_names_file_and_line(tmp_path, case):
    text, line, problem = BAD_FILES[case]
    path = tmp_path / f"{case}.txt"
    path.write_text(text)
    with pytest.raises(DataFormatError) as err:
        read_recording(path)
    assert f"{path}:{line}:" in str(err.value), str(err.value)
    assert problem in str(err.value)


@pytest.mark.parametrize("text", ["", "\n\n  \n"], ids=["empty", "blank_lines"])
def test_read_recording_empty_file_is_rejected(tmp_path, text):
    path = tmp_path / "empty.txt"
    path.write_text(text)
    with pytest.raises(DataFormatError, match="empty file"):
        read_recording(path)


def test_read_recording_missing_file_names_it(tmp_path):
    with pytest.raises(DataFormatError, match=r"nope\.txt"):
        read_recording(tmp_path / "nope.txt")


def test_read_recording_parses_columns(tmp_path):
    path = tmp_path / "good.txt"
    path.write_text(GOOD)
    rec = read_recording(path)
    assert rec.name == "good"
    assert rec.frame.tolist() == [0, 0, 10]
    assert rec.agent.tolist() == [1, 2, 1]
    np.testing.assert_array_equal(rec.xy_m, [[1.0, 2.0], [3.0, 4.0], [1.5, 2.5]])
    xy, present = rec.dense()
    assert present.tolist() == [[True, True], [True, False]]
    assert np.isnan(xy[1, 1]).all()


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 50), st.integers(0, 20),
                          st.floats(-50, 50, allow_nan=False), st.floats(-50, 50, allow_nan=False)),
                min_size=1, max_size=60, unique_by=lambda r: (r[0], r[1])))
def test_write_then_read_recording_round_trips(tmp_path_factory, rows):
    path = tmp_path_factory.mktemp("rt") / "rec.txt"
    frame, agent = np.array([r[0] for r in rows]) * 10, np.array([r[1] for r in rows])
    xy = np.array([[r[2], r[3]] for r in rows])
    write_recording(path, frame, agent, xy)
    rec = read_recording(path)
    order = np.lexsort((agent, frame))
    assert rec.frame.tolist() == frame[order].tolist()
    assert rec.agent.tolist() == agent[order].tolist()
    np.testing.assert_allclose(rec.xy_m, xy[order], atol=1e-6)


def test_write_recording_refuses_nan(tmp_path):
    with pytest.raises(ValueError, match="NaN"):
        write_recording(tmp_path / "x.txt", np.array([0]), np.array([1]), np.array([[np.nan, 0.0]]))
    assert not (tmp_path / "x.txt").exists()
