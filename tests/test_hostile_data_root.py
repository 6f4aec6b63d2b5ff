"""Hostile data roots, fetches and interrupted writes: modified copies are refused (or loudly accepted on request),
user files are never deleted, temp files of killed writes are cleaned up, and the CLI prints one error line.
"""

from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_data_root import linked_layout  # a data root of symlinks into the shared folder

from replays import DataRootError, load_windows
from replays.atomic import atomic_path, write_text_atomic
from replays.cli import main
from replays.data_root import ALLOW_MODIFIED_ENV_VAR, data_root, expected_sums, modified_files, sha256_of
from replays.fetch import MAX_FILE_BYTES, FetchError, fetch

data_root_module = importlib.import_module("replays.data_root")  # the package exports a function of that name
SHARED = data_root()
SUMS = expected_sums()
ZARA1_TEST = "zara1/test/crowds_zara01.txt"


def scale_recording(root: Path, name: str, factor: float) -> None:
    """Replace ``name`` by a copy with every position scaled by ``factor`` (the attack on ZARA1's test set)."""
    rows = np.loadtxt(SHARED / name)
    (root / name).unlink()
    (root / name).write_text("".join(f"{int(f)}\t{int(a)}\t{x * factor:.6f}\t{y * factor:.6f}\n"
                                     for f, a, x, y in rows))


@pytest.fixture
def scaled_root(tmp_path: Path) -> Path:
    root = linked_layout(tmp_path / "root")
    scale_recording(root, ZARA1_TEST, 1.5)
    return root


def test_scaled_copy_is_refused_with_the_file_name_and_the_fix(scaled_root: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(ALLOW_MODIFIED_ENV_VAR, raising=False)
    with pytest.raises(DataRootError) as err:
        load_windows("stochastic", "zara1", "test", root=scaled_root)
    message = str(err.value)
    for needed in (ZARA1_TEST, "SHA-256", "python -m replays fetch", ALLOW_MODIFIED_ENV_VAR, "verify=False"):
        assert needed in message, (needed, message)


@pytest.mark.parametrize("how", ["env", "argument"])
def test_modified_copy_opt_out_loads_it_and_warns_naming_the_file(
        scaled_root: Path, how: str, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture) -> None:
    if how == "env":
        monkeypatch.setenv(ALLOW_MODIFIED_ENV_VAR, "1")
    else:
        monkeypatch.delenv(ALLOW_MODIFIED_ENV_VAR, raising=False)
        data_root(scaled_root, verify=False)
    scaled = load_windows("stochastic", "zara1", "test", root=scaled_root)
    err = capfd.readouterr().err
    assert "MODIFIED" in err and ZARA1_TEST in err, err
    original = load_windows("stochastic", "zara1", "test")
    np.testing.assert_allclose(scaled.obs, 1.5 * original.obs, atol=1e-3)


def test_extra_recording_in_a_split_folder_is_refused(tmp_path: Path) -> None:
    root = linked_layout(tmp_path / "root")
    (root / "zara1/test/extra.txt").write_text("0\t1\t1.0\t1.0\n")
    with pytest.raises(DataRootError, match=r"zara1/test/extra\.txt \(extra file"):
        data_root(root)


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(victim=st.sampled_from(sorted(SUMS)), edit=st.sampled_from(["append", "truncate", "flip"]))
def test_any_edited_file_is_named(tmp_path_factory, victim: str, edit: str) -> None:
    root = linked_layout(tmp_path_factory.mktemp("edit") / "root")
    data = (SHARED / victim).read_bytes()
    (root / victim).unlink()
    edited = {"append": data + b"\n", "truncate": data[: len(data) // 2], "flip": bytes([data[0] ^ 1]) + data[1:]}
    (root / victim).write_bytes(edited[edit])
    assert list(modified_files(root)) == [victim]
    with pytest.raises(DataRootError, match=re.escape(victim)):
        data_root(root)


def test_digests_are_cached_by_size_and_times(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STCROWD_CACHE", str(tmp_path / "cache"))
    root = linked_layout(tmp_path / "root")
    hashed: list[Path] = []
    monkeypatch.setattr(data_root_module, "sha256_of", lambda path: hashed.append(path) or sha256_of(path))
    assert modified_files(root) == {} and len(hashed) == len(SUMS)
    hashed.clear()
    assert modified_files(root) == {} and hashed == [], "unchanged files were hashed again"
    (root / ZARA1_TEST).unlink()
    (root / ZARA1_TEST).write_bytes((SHARED / ZARA1_TEST).read_bytes())  # same bytes, new file
    assert modified_files(root) == {} and hashed == [root / ZARA1_TEST]


def test_fetch_from_a_folder_into_itself_is_refused_and_touches_nothing(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture) -> None:
    dest = tmp_path / "dest"
    fetch(SHARED, dest, quiet=True)
    edited = (dest / ZARA1_TEST).read_bytes() + b"99999\t1\t0.0\t0.0\n"
    (dest / ZARA1_TEST).write_bytes(edited)
    assert main(["fetch", "--from", str(dest), "--dest", str(dest), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "same folder" in err and err.count("\n") == 1, err
    assert (dest / ZARA1_TEST).read_bytes() == edited


def test_fetch_moves_an_edited_file_aside_and_says_so(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    dest = tmp_path / "dest"
    fetch(SHARED, dest, quiet=True)
    for round_ in range(2):  # a second edit does not overwrite the first kept copy
        (dest / ZARA1_TEST).write_bytes(f"edit {round_}\n".encode())
        assert main(["fetch", "--from", str(SHARED), "--dest", str(dest), "--quiet"]) == 0
        assert "kept as" in capsys.readouterr().err
    assert sha256_of(dest / ZARA1_TEST) == SUMS[ZARA1_TEST]
    assert (dest / (ZARA1_TEST + ".modified")).read_bytes() == b"edit 0\n"
    assert (dest / (ZARA1_TEST + ".modified.1")).read_bytes() == b"edit 1\n"
    data_root(dest)  # the kept copies are not recordings the loaders would read


def test_fetch_refuses_special_and_oversized_source_files(tmp_path: Path) -> None:
    source = linked_layout(tmp_path / "source")
    (source / ZARA1_TEST).unlink()
    os.mkfifo(source / ZARA1_TEST)
    with pytest.raises(FetchError, match=re.escape(ZARA1_TEST) + ".*FIFO"):
        fetch(source, tmp_path / "dest", quiet=True)
    (source / ZARA1_TEST).unlink()
    with open(source / ZARA1_TEST, "wb") as f:
        f.truncate(MAX_FILE_BYTES + 1)
    with pytest.raises(FetchError, match=re.escape(ZARA1_TEST)):
        fetch(source, tmp_path / "dest", quiet=True)
    assert not list((tmp_path / "dest").rglob("*.part")), "a refused transfer left its partial file"


KILLED_WRITE = """
import os, sys
from replays.atomic import atomic_path
with atomic_path(sys.argv[1]) as tmp:
    tmp.write_text("half")
    os._exit(9)
"""

HELD_WRITE = """
import sys, time
from replays.atomic import atomic_path
with atomic_path(sys.argv[1]) as tmp:
    tmp.write_text("busy")
    print("writing", flush=True)
    time.sleep(60)
"""


def temp_files(target: Path) -> list[Path]:
    return sorted(target.parent.glob(f".{target.name}.*.tmp{target.suffix}"))


def test_temp_files_of_killed_writes_are_removed_by_the_next_write(tmp_path: Path) -> None:
    target = tmp_path / "out.json"
    subprocess.run([sys.executable, "-c", KILLED_WRITE, str(target)], check=False)
    first = temp_files(target)
    subprocess.run([sys.executable, "-c", KILLED_WRITE, str(target)], check=False)
    assert len(first) == 1 and first[0] not in temp_files(target) and len(temp_files(target)) == 1
    live = subprocess.Popen([sys.executable, "-c", HELD_WRITE, str(target)], stdout=subprocess.PIPE, text=True)
    try:
        assert live.stdout.readline().strip() == "writing"
        write_text_atomic(target, "done")
        assert target.read_text() == "done"
        remaining = temp_files(target)
        assert len(remaining) == 1 and remaining[0].read_text() == "busy", "a live writer's file was removed"
    finally:
        live.kill()
        live.wait()
    with atomic_path(target) as tmp:
        tmp.write_text("again")
    assert temp_files(target) == [] and target.read_text() == "again"


@pytest.mark.parametrize("args, needle", [
    (["verify", "--root", "{fifo_root}"], "missing"),
    (["verify", "--root", "{scaled}"], "SHA-256"),
    (["fetch", "--from", "{fifo_root}", "--dest", "{dest}", "--quiet"], "FIFO"),
], ids=["verify-missing", "verify-modified", "fetch-fifo"])
def test_cli_errors_are_one_line_and_debug_shows_the_traceback(
        args: list[str], needle: str, tmp_path: Path, scaled_root: Path, capsys: pytest.CaptureFixture) -> None:
    fifo_root = linked_layout(tmp_path / "fifo_root")
    (fifo_root / ZARA1_TEST).unlink()
    os.mkfifo(fifo_root / ZARA1_TEST)
    paths = {"fifo_root": fifo_root, "scaled": scaled_root, "dest": tmp_path / "dest"}
    argv = [a.format(**paths) for a in args]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and needle in err and err.count("\n") == 1 and "Traceback" not in err, err
    with pytest.raises((DataRootError, FetchError)):
        main([*argv, "--debug"])
