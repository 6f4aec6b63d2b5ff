"""Hostile recording, homography and image files: each one parses correctly or raises the project's own error.

Classes of attack: malformed rows, NaN/inf, unsorted and duplicate frames, empty files, ids beyond what float64
holds exactly, negative ids (-1 is the observation's empty-row marker), coordinates beyond the position limit,
arbitrary bytes, non-regular files (FIFOs, devices, folders) and files whose arrays would pass the memory budget.
"""

from __future__ import annotations

import os
import re
import socket
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import replays.files
from replays import (
    DataFormatError,
    MemoryBudgetError,
    NotRegularFileError,
    RecordingError,
    read_recording,
    write_recording,
)
from replays.constants import ID_LIMIT, POSITION_LIMIT_M
from replays.recording import MAX_RECORDING_BYTES
from replays.scenes import PNG_SIGNATURE, read_homography, read_image
from replays.windows import cut_windows

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def write(tmp_path: Path, data: str | bytes, name: str = "rec.txt") -> Path:
    path = tmp_path / name
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


@st.composite
def valid_rows(draw) -> list[tuple[int, int, float, float]]:
    """Rows sorted by frame with unique (frame, agent) pairs, ids and positions inside the accepted ranges."""
    pairs = draw(st.lists(st.tuples(st.integers(0, 40), st.integers(0, 30)), min_size=2, max_size=30, unique=True))
    coord = st.floats(-POSITION_LIMIT_M, POSITION_LIMIT_M, allow_nan=False)
    return [(10 * (f + 1), a, draw(coord), draw(coord)) for f, a in sorted(pairs)]


@st.composite
def formatted(draw, rows: list[tuple]) -> tuple[list[str], list[int]]:
    """Lines of the rows in any accepted layout (tabs or spaces, '1.0' ids, blank lines); their line numbers."""
    lines, numbers = [], []
    for frame, agent, x, y in rows:
        while draw(st.integers(0, 5)) == 5:  # shrinks to no blank line
            lines.append(draw(st.sampled_from(["", "  ", "\t"])))
        sep = draw(st.sampled_from(["\t", " ", "  ", " \t"]))
        ids = [str(frame), f"{agent}.0" if draw(st.booleans()) else str(agent)]
        lines.append(sep.join([*ids, repr(x), repr(y)]))
        numbers.append(len(lines))
    return lines, numbers


def join(lines: list[str], newline: str) -> str:
    return newline.join(lines) + newline


@FAST
@given(data=st.data(), newline=st.sampled_from(["\n", "\r\n", "\r"]))
def test_valid_recordings_parse_exactly(tmp_path_factory, data, newline: str) -> None:
    rows = data.draw(valid_rows())
    lines, _ = data.draw(formatted(rows))
    rec = read_recording(write(tmp_path_factory.mktemp("ok"), join(lines, newline)))
    assert rec.frame.tolist() == [r[0] for r in rows]
    assert rec.agent.tolist() == [r[1] for r in rows]
    assert rec.xy_m.tolist() == [[r[2], r[3]] for r in rows]


# one corruption of one row: (text of the bad row from a good one, expected problem, field)
CORRUPTIONS = {
    "too_few_columns": (lambda f, a, x, y: f"{f}\t{a}\t{x}", "expected 4 numbers", None),
    "too_many_columns": (lambda f, a, x, y: f"{f}\t{a}\t{x}\t{y}\t0", "expected 4 numbers", None),
    "word": (lambda f, a, x, y: f"{f}\t{a}\tabc\t{y}", "not a number", "x"),
    "comment": (lambda f, a, x, y: f"{f}\t{a}\t{x}\t{y} # note", "expected 4 numbers", None),
    "underscore": (lambda f, a, x, y: f"{f}\t{a}\t1_0\t{y}", "not a number", "x"),
    "nan": (lambda f, a, x, y: f"{f}\t{a}\tnan\t{y}", "NaN or infinite", "x"),
    "inf": (lambda f, a, x, y: f"{f}\t{a}\t{x}\t-inf", "NaN or infinite", "y"),
    "overflow": (lambda f, a, x, y: f"{f}\t{a}\t{x}\t1e400", "NaN or infinite", "y"),
    "far_away": (lambda f, a, x, y: f"{f}\t{a}\t{2 * POSITION_LIMIT_M}\t{y}", "beyond", "x"),
    "fractional_id": (lambda f, a, x, y: f"{f}\t{a}.5\t{x}\t{y}", "whole numbers", "agent"),
    "minus_one_agent": (lambda f, a, x, y: f"{f}\t-1\t{x}\t{y}", "outside [0, 2^53)", "agent"),
    "huge_agent": (lambda f, a, x, y: f"{f}\t1e20\t{x}\t{y}", "outside [0, 2^53)", "agent"),
    "agent_2p53_plus_1": (lambda f, a, x, y: f"{f}\t{ID_LIMIT + 1}\t{x}\t{y}", "outside [0, 2^53)", "agent"),
    "nan_frame": (lambda f, a, x, y: f"nan\t{a}\t{x}\t{y}", "NaN or infinite", "frame"),
    "huge_frame": (lambda f, a, x, y: f"{10**30}\t{a}\t{x}\t{y}", "outside [0, 2^53)", "frame"),
    "negative_frame": (lambda f, a, x, y: f"-10\t{a}\t{x}\t{y}", "outside [0, 2^53)", "frame"),
    "not_utf8": (lambda f, a, x, y: f"{f}\t{a}\t\udcff\t{y}", "not UTF-8", None),
}


@pytest.mark.parametrize("kind", list(CORRUPTIONS), ids=list(CORRUPTIONS))
@FAST
@given(data=st.data())
def test_one_bad_row_names_file_line_and_field(tmp_path_factory, kind: str, data) -> None:
    rows = data.draw(valid_rows())
    lines, numbers = data.draw(formatted(rows))
    victim = data.draw(st.integers(0, len(rows) - 1))
    make, problem, field = CORRUPTIONS[kind]
    lines[numbers[victim] - 1] = make(*rows[victim])
    path = write(tmp_path_factory.mktemp(kind), join(lines, "\n").encode("utf-8", "surrogateescape"))
    with pytest.raises(RecordingError) as err:
        read_recording(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{numbers[victim]}: ") and problem in message, message
    assert (err.value.line, err.value.field, err.value.path) == (numbers[victim], field, str(path)), message


@FAST
@given(data=st.data())
def test_unsorted_and_duplicate_frames_name_the_line(tmp_path_factory, data) -> None:
    rows = data.draw(valid_rows())
    lines, numbers = data.draw(formatted(rows))
    i = data.draw(st.integers(0, len(rows) - 2))
    later = [j for j in range(i + 1, len(rows)) if rows[j][0] > rows[i][0]]
    frame, agent, x, y = rows[i]
    if later:  # a later row jumps back before row i: unsorted
        j, problem = later[0], "not sorted"
        lines[numbers[j] - 1] = f"{frame - 10}\t{rows[j][1]}\t{x}\t{y}"
    else:  # the rows after i share its frame: repeat row i's agent
        j, problem = i + 1, "duplicate (frame, agent)"
        lines[numbers[j] - 1] = f"{frame}\t{agent}\t{x}\t{y}"
    path = write(tmp_path_factory.mktemp("order"), join(lines, "\n"))
    with pytest.raises(RecordingError, match=re.escape(problem)) as err:
        read_recording(path)
    assert str(err.value).startswith(f"{path}:{numbers[j]}: "), str(err.value)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(
    st.binary(max_size=300),
    st.lists(st.lists(st.one_of(
        st.sampled_from(["nan", "inf", "-inf", "1e400", "-1", "1.5", "0", "10", "1e20", "9007199254740993", "#", "",
                         "0x10", "1_0", "+5", ".5", "5.", "\u00a0", "\x00", "Infinity", "-0"]),
        st.integers(-(2**70), 2**70).map(str), st.floats().map(repr)), min_size=0, max_size=6).map(" ".join),
        max_size=8).map("\n".join)))
def test_any_content_parses_to_valid_rows_or_raises_recording_error(tmp_path_factory, data) -> None:
    path = write(tmp_path_factory.mktemp("fuzz"), data)
    try:
        rec = read_recording(path)
    except RecordingError as err:
        assert str(err).startswith(str(path)), str(err)
        return
    assert len(rec) > 0 and rec.xy_m.shape == (len(rec), 2)
    assert (rec.agent >= 0).all() and (rec.frame >= 0).all() and (np.diff(rec.frame) >= 0).all()
    assert np.isfinite(rec.xy_m).all() and (np.abs(rec.xy_m) <= POSITION_LIMIT_M).all()
    assert len({(f, a) for f, a in zip(rec.frame.tolist(), rec.agent.tolist(), strict=True)}) == len(rec)


@pytest.mark.parametrize("text", ["", "\n\n  \n", "\r\n", "\t"], ids=["empty", "blank_lines", "crlf", "tab"])
def test_empty_recording_is_refused(tmp_path, text: str) -> None:
    with pytest.raises(RecordingError, match="empty file"):
        read_recording(write(tmp_path, text))


def read_in_thread(reader, path: Path, timeout_s: float = 60.0) -> BaseException | None:
    """Run ``reader(path)`` in a daemon thread; a hang fails the test instead of blocking the suite."""
    outcome: list[BaseException | None] = []

    def run() -> None:
        try:
            reader(path)
            outcome.append(None)
        except BaseException as err:  # the test inspects it
            outcome.append(err)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(timeout_s)
    assert not thread.is_alive(), f"reading {path} hangs"
    return outcome[0]


def special_files(tmp_path: Path) -> dict[str, Path]:
    """A FIFO, a socket, a folder, devices and symlinks to them."""
    fifo = tmp_path / "fifo.txt"
    os.mkfifo(fifo)
    sock_path = tmp_path / "sock.txt"
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(sock_path))
    (tmp_path / "folder.txt").mkdir()
    (tmp_path / "link_to_fifo.txt").symlink_to(fifo)
    (tmp_path / "link_to_zero.txt").symlink_to("/dev/zero")
    return {"fifo": fifo, "socket": sock_path, "folder": tmp_path / "folder.txt", "dev_zero": Path("/dev/zero"),
            "dev_null": Path("/dev/null"), "dev_urandom": Path("/dev/urandom"),
            "link_to_fifo": tmp_path / "link_to_fifo.txt", "link_to_zero": tmp_path / "link_to_zero.txt"}


READERS = {"recording": read_recording, "homography": read_homography,
           "image": lambda path: read_image(path, grayscale=True)}


@pytest.mark.parametrize("reader", list(READERS), ids=list(READERS))
def test_only_regular_files_are_read(tmp_path, reader: str) -> None:
    for kind, path in special_files(tmp_path).items():
        err = read_in_thread(READERS[reader], path)
        assert isinstance(err, NotRegularFileError), f"[{kind}] {err!r}"
        assert str(path) in str(err), f"[{kind}] {err}"


def test_missing_recording_names_it(tmp_path) -> None:
    with pytest.raises(DataFormatError, match=r"nope\.txt: cannot open"):
        read_recording(tmp_path / "nope.txt")


def test_oversized_recording_is_refused_before_reading(tmp_path) -> None:
    path = tmp_path / "huge.txt"
    with open(path, "wb") as f:  # sparse: 10 M rows' worth of bytes without using the disk
        f.truncate(MAX_RECORDING_BYTES + 1)
    with pytest.raises(MemoryBudgetError, match=r"huge\.txt: 67,108,865 bytes"):
        read_recording(path)


def wide_recording(tmp_path: Path, n: int) -> Path:
    """n rows, each a new frame and a new agent: n x n dense cells from a file of about 15 n bytes."""
    return write(tmp_path, "".join(f"{10 * i}\t{i}\t1.0\t1.0\n" for i in range(n)), "wide.txt")


def test_dense_grid_over_budget_is_refused_before_allocating(tmp_path) -> None:
    rec = read_recording(wide_recording(tmp_path, 60_000))  # 0.9 MB; the grid would take 57 GiB
    with pytest.raises(MemoryBudgetError, match=r"wide\.txt: dense grid of 60000 listed frames x 60000 agents"):
        rec.dense()
    with pytest.raises(MemoryBudgetError, match="windowing grid"):
        cut_windows(rec, 8)


@FAST
@given(rows=valid_rows(), budget=st.integers(0, 20_000))
def test_dense_works_exactly_up_to_the_budget(monkeypatch, tmp_path_factory, rows, budget: int) -> None:
    monkeypatch.setattr(replays.files, "MEMORY_BUDGET_BYTES", budget)
    rec = read_recording(write(tmp_path_factory.mktemp("budget"), "".join(f"{f} {a} {x} {y}\n" for f, a, x, y in rows)))
    cells = len(rec.frames) * len(rec.agents)
    if cells * 17 > budget:
        with pytest.raises(MemoryBudgetError):
            rec.dense()
        return
    xy, present = rec.dense()
    assert present.sum() == len(rows) and np.isnan(xy[~present]).all()


@FAST
@given(frame=st.integers(-5, ID_LIMIT + 5), agent=st.integers(-5, ID_LIMIT + 5),
       xy=st.tuples(st.floats(), st.floats()))
def test_write_recording_refuses_what_read_recording_refuses(tmp_path_factory, frame, agent, xy) -> None:
    path = tmp_path_factory.mktemp("write") / "rec.txt"
    try:
        write_recording(path, np.array([frame]), np.array([agent]), np.array([xy]))
    except ValueError:
        assert not path.exists()
        with pytest.raises(RecordingError):
            read_recording(write(path.parent, f"{frame} {agent} {xy[0]!r} {xy[1]!r}\n", "direct.txt"))
        return
    rec = read_recording(path)
    assert (rec.frame[0], rec.agent[0]) == (frame, agent)
    np.testing.assert_allclose(rec.xy_m[0], xy, atol=1e-6)


HOMOGRAPHIES = ["", "1 0 0\n0 1 0\n", "1 0 0\n0 1 0\n0 0 0\n", "1 0 nan\n0 1 0\n0 0 1\n", "a b c\nd e f\ng h i\n",
                "1 0 0 0\n0 1 0 0\n0 0 1 0\n", "\xff\xfe", "1 0 0\n0 1 0\n0 0 1\n" * 300]


@pytest.mark.parametrize("text", HOMOGRAPHIES, ids=range(len(HOMOGRAPHIES)))
def test_bad_homography_names_the_file(tmp_path, text: str) -> None:
    path = write(tmp_path, text.encode("latin-1"), "H.txt")
    with pytest.raises(DataFormatError, match=r"H\.txt"):
        read_homography(path)


def png_header(width: int, height: int) -> bytes:
    ihdr = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([8, 0, 0, 0, 0])
    return PNG_SIGNATURE + len(ihdr).to_bytes(4, "big") + b"IHDR" + ihdr + b"\0\0\0\0"


@pytest.mark.parametrize("data, error", [
    (png_header(200_000, 200_000), MemoryBudgetError),  # a decompression bomb: 40 G pixels
    (png_header(10, 10), DataFormatError),  # header only: no image data
    (b"GIF89a" + b"\0" * 40, DataFormatError),
    (b"", DataFormatError),
], ids=["bomb", "truncated", "not_png", "empty"])
def test_bad_image_is_refused_before_decoding(tmp_path, data: bytes, error: type) -> None:
    path = write(tmp_path, data, "map.png")
    with pytest.raises(error, match=r"map\.png"):
        read_image(path, grayscale=True)
