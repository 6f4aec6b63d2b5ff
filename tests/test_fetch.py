"""``python -m replays fetch`` / ``verify``: folder, archive and HTTP sources, resume, corrupt and unreachable sources.

The HTTP tests serve a temporary copy of the shared data folder from 127.0.0.1 (``http.server`` in a thread).
"""

from __future__ import annotations

import io
import os
import re
import shutil
import socket
import subprocess
import sys
import tarfile
import threading
import zipfile
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

import replays.fetch as fetch_module
from replays.cli import main
from replays.data_root import data_root, expected_sums, sha256_of, verify_data_root
from replays.fetch import LMTRAJECTORY_URL, SOCIAL_STGCNN_URL, FetchError, fetch, mirror_url

SHARED = data_root()  # $STCROWD_DATA in CI: the read-only reference copy
SUMS = expected_sums()
BIG = "image/seq_hotel_reference.png"  # largest file (~580 kB), for resume tests
VICTIM = "zara1/test/crowds_zara01.txt"


class QuietHandler(SimpleHTTPRequestHandler):
    """Static files like the standard server (no Range support), without request logging."""

    def log_message(self, *args) -> None:
        pass


class RangeHandler(QuietHandler):
    """Honours ``Range: bytes=N-`` as GitHub's raw server does; logs (path, Range header) per request."""

    requests: list[tuple[str, str | None]]
    cut_first_bytes: int | None = None
    """if set, the first full-file answer stops after this many bytes (a dropped connection)"""

    def send_head(self):
        self.requests.append((self.path, self.headers.get("Range")))
        data = Path(self.translate_path(self.path)).read_bytes()
        start = int(self.headers.get("Range", "bytes=0-").removeprefix("bytes=").removesuffix("-"))
        if start >= len(data):
            self.send_error(416)
            return None
        self.send_response(206 if start else 200)
        if start:
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        self.send_header("Content-Length", str(len(data) - start))
        self.end_headers()
        if not start and self.cut_first_bytes is not None:
            data, type(self).cut_first_bytes = data[: self.cut_first_bytes], None
        return io.BytesIO(data[start:])


def range_handler(cut_first_bytes: int | None = None) -> type[RangeHandler]:
    """A fresh RangeHandler class with its own request log."""
    return type("LoggedRangeHandler", (RangeHandler,), {"requests": [], "cut_first_bytes": cut_first_bytes})


@contextmanager
def http_server(root: Path, handler: type[SimpleHTTPRequestHandler] = QuietHandler) -> Iterator[str]:
    """Serve ``root`` on 127.0.0.1 (free port) in a thread; yields the base URL."""
    server = ThreadingHTTPServer(("127.0.0.1", 0), partial(handler, directory=str(root)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


def copy_layout(dst: Path, names=SUMS) -> Path:
    """Copy the listed files of the shared folder to ``dst`` (contents only, so the copy is writable)."""
    for name in names:
        (dst / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SHARED / name, dst / name)
    return dst


def mtimes(root: Path) -> dict[str, int]:
    """Modification times [ns] of the listed files present under ``root``."""
    return {name: (root / name).stat().st_mtime_ns for name in SUMS if (root / name).is_file()}


@pytest.fixture
def served(tmp_path: Path) -> Path:
    return copy_layout(tmp_path / "served")


@pytest.fixture
def filled(tmp_path: Path) -> Path:
    """A destination already holding every verified file."""
    dest = tmp_path / "dest"
    fetch(SHARED, dest, quiet=True)
    return dest


def test_fetch_from_folder_verifies_every_file_then_skips_all(tmp_path: Path) -> None:
    dest = tmp_path / "dest"
    first = fetch(SHARED, dest, quiet=True)
    assert (first.fetched, first.skipped, first.dest) == (len(SUMS), 0, dest.resolve())
    assert len(SUMS) == 116
    verify_data_root(dest)
    assert not list(dest.rglob("*.part"))
    before = mtimes(dest)
    second = fetch(SHARED, dest, quiet=True)
    assert (second.fetched, second.skipped, second.bytes_moved) == (0, len(SUMS), 0)
    assert mtimes(dest) == before


def test_fetch_keeps_a_different_existing_file_as_modified(filled: Path, tmp_path: Path) -> None:
    edited = b"1\t2\t3.0\t4.0\n"
    (filled / VICTIM).write_bytes(edited)
    (tmp_path / "empty").mkdir()
    with pytest.raises(FetchError, match="missing from the source folder"):
        fetch(tmp_path / "empty", filled, quiet=True)
    assert (filled / VICTIM).read_bytes() == edited, "a failed fetch touched the user's file"
    report = fetch(SHARED, filled, quiet=True)
    assert (report.fetched, report.skipped) == (1, len(SUMS) - 1)
    assert sha256_of(filled / VICTIM) == SUMS[VICTIM]
    assert report.moved_aside == (filled / (VICTIM + ".modified"),)
    assert (filled / (VICTIM + ".modified")).read_bytes() == edited


def test_fetch_over_http_succeeds_then_fails_on_a_corrupt_served_file(
        tmp_path: Path, served: Path, capsys: pytest.CaptureFixture) -> None:
    dest = tmp_path / "dest"
    with http_server(served) as url:
        assert main(["fetch", "--from", url, "--dest", str(dest), "--quiet"]) == 0
        verify_data_root(dest)
        with open(served / VICTIM, "ab") as f:
            f.write(b"0\t0\t0.0\t0.0\n")
        (dest / VICTIM).unlink()
        others = mtimes(dest)
        capsys.readouterr()
        assert main(["fetch", "--from", url, "--dest", str(dest), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and VICTIM in err and "SHA-256 mismatch" in err, err
    assert SUMS[VICTIM] in err and "Traceback" not in err and err.count("\n") == 1, err
    assert not (dest / VICTIM).exists() and not (dest / (VICTIM + ".part")).exists()
    assert len(others) == len(SUMS) - 1 and mtimes(dest) == others
    for name in others:
        assert sha256_of(dest / name) == SUMS[name], name


def test_fetch_from_tar_gz_with_a_top_folder(tmp_path: Path) -> None:
    archive = tmp_path / "eth_ucy.tar.gz"
    with tarfile.open(archive, "w:gz", compresslevel=1) as tar:
        tar.add(SHARED, arcname="eth_ucy")
    report = fetch(archive, tmp_path / "dest", quiet=True)
    assert report.fetched == len(SUMS)
    verify_data_root(tmp_path / "dest")


def test_fetch_from_zip_names_a_missing_member(tmp_path: Path) -> None:
    archive = tmp_path / "eth_ucy.zip"
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_STORED) as zf:
        for name in SUMS:
            if name != VICTIM:
                zf.write(SHARED / name, name)
    with pytest.raises(FetchError, match=VICTIM):
        fetch(archive, tmp_path / "dest", quiet=True)
    assert not (tmp_path / "dest" / VICTIM).exists()
    with zipfile.ZipFile(archive, "a") as zf:
        zf.write(SHARED / VICTIM, VICTIM)
    assert fetch(archive, tmp_path / "dest", quiet=True).fetched >= 1
    verify_data_root(tmp_path / "dest")


def test_fetch_resumes_a_part_file_with_a_range_request(filled: Path, served: Path) -> None:
    size = (SHARED / BIG).stat().st_size
    (filled / BIG).unlink()
    (filled / (BIG + ".part")).write_bytes((SHARED / BIG).read_bytes()[: size // 2])
    handler = range_handler()
    with http_server(served, handler) as url:
        report = fetch(url, filled, quiet=True)
    assert (report.fetched, report.bytes_moved) == (1, size - size // 2)
    assert handler.requests == [(f"/{BIG}", f"bytes={size // 2}-")]
    assert sha256_of(filled / BIG) == SUMS[BIG] and not (filled / (BIG + ".part")).exists()


def test_fetch_restarts_a_part_file_when_the_server_ignores_range(filled: Path, served: Path) -> None:
    size = (SHARED / BIG).stat().st_size
    (filled / BIG).unlink()
    (filled / (BIG + ".part")).write_bytes(b"\0" * 1000)
    with http_server(served) as url:
        report = fetch(url, filled, quiet=True)
    assert (report.fetched, report.bytes_moved) == (1, size)
    assert sha256_of(filled / BIG) == SUMS[BIG]


def test_fetch_restarts_once_when_a_resumed_part_fails_its_hash(filled: Path, served: Path) -> None:
    size = (SHARED / BIG).stat().st_size
    (filled / BIG).unlink()
    (filled / (BIG + ".part")).write_bytes(b"\0" * 1000)  # wrong bytes: resuming cannot fix them
    handler = range_handler()
    with http_server(served, handler) as url:
        report = fetch(url, filled, quiet=True)
    assert handler.requests == [(f"/{BIG}", "bytes=1000-"), (f"/{BIG}", None)]
    assert report.bytes_moved == (size - 1000) + size
    assert sha256_of(filled / BIG) == SUMS[BIG]


def test_fetch_resumes_after_a_dropped_connection(filled: Path, served: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fetch_module, "RETRY_DELAYS_S", (0.0, 0.0))
    (filled / BIG).unlink()
    handler = range_handler(cut_first_bytes=100_000)
    with http_server(served, handler) as url:
        report = fetch(url, filled, quiet=True)
    assert handler.requests == [(f"/{BIG}", None), (f"/{BIG}", "bytes=100000-")]
    assert report.fetched == 1 and sha256_of(filled / BIG) == SUMS[BIG]


def test_fetch_unreachable_server_exits_1_with_one_message(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fetch_module, "RETRY_DELAYS_S", (0.0, 0.0))
    with socket.socket() as sock:  # a port that was free a moment ago: nothing listens there
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    assert main(["fetch", "--from", f"http://127.0.0.1:{port}", "--dest", str(tmp_path / "d"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "after 3 attempts" in err and err.count("\n") == 1, err
    assert f"http://127.0.0.1:{port}/" in err and "Traceback" not in err, err
    assert not [p for p in (tmp_path / "d").rglob("*") if p.is_file()]


def test_fetch_unknown_source_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["fetch", "--from", str(tmp_path / "nowhere"), "--dest", str(tmp_path / "d"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "nowhere" in err and "--from takes" in err, err


def test_fetch_damaged_archive_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    archive = tmp_path / "images.tar.gz"
    with tarfile.open(archive, "w:gz", compresslevel=1) as tar:
        tar.add(SHARED / "image", arcname="image")
    os.truncate(archive, archive.stat().st_size // 2)
    assert main(["fetch", "--from", str(archive), "--dest", str(tmp_path / "d"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "damaged or truncated archive" in err and "Traceback" not in err, err


def test_fetch_unwritable_destination_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "a_file").write_text("not a folder")
    assert main(["fetch", "--from", str(SHARED), "--dest", str(tmp_path / "a_file"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "a_file" in err and err.count("\n") == 1, err


def test_mirror_url_maps_our_layout_onto_the_two_repositories() -> None:
    assert mirror_url("eth/test/biwi_eth.txt") == SOCIAL_STGCNN_URL + "eth/test/biwi_eth.txt"
    assert mirror_url("raw/all_data/students001.txt") == SOCIAL_STGCNN_URL + "raw/all_data/students001.txt"
    assert mirror_url("homography/biwi_eth_H.txt") == LMTRAJECTORY_URL + "homography/biwi_eth_H.txt"
    assert mirror_url("image/seq_eth_map.png") == LMTRAJECTORY_URL + "image/seq_eth_oracle.png"
    assert mirror_url("image/seq_eth_reference.png") == LMTRAJECTORY_URL + "image/seq_eth_reference.png"
    with pytest.raises(FetchError, match="no public mirror"):
        mirror_url("elsewhere/file.txt")


def test_fetch_default_mirrors_path_against_two_local_repositories(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    # lay the files out as the two mirrors do (maps renamed *_oracle.png), then point MIRRORS at them
    local_base = {SOCIAL_STGCNN_URL: "stgcnn/", LMTRAJECTORY_URL: "lmtraj/"}
    for name in SUMS:
        url = mirror_url(name)
        base = next(b for b in local_base if url.startswith(b))
        remote = tmp_path / "mirrors" / local_base[base] / url.removeprefix(base)
        remote.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(SHARED / name, remote)
    with http_server(tmp_path / "mirrors") as url:
        mirrors = tuple((folder, url + local_base[base], rename) for folder, base, rename in fetch_module.MIRRORS)
        monkeypatch.setattr(fetch_module, "MIRRORS", mirrors)
        report = fetch(None, tmp_path / "dest", quiet=True)
    assert report.fetched == len(SUMS)
    verify_data_root(tmp_path / "dest")


def test_verify_cli_prints_ok_or_the_first_bad_file(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["verify", "--root", str(SHARED)]) == 0
    assert capsys.readouterr().out.startswith("OK")
    copy = copy_layout(tmp_path / "copy")
    os.truncate(copy / VICTIM, 10)
    assert main(["verify", "--root", str(copy)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and VICTIM in err and "python -m replays fetch" in err, err


@pytest.mark.parametrize("source", ["folder", "archive", "http"])
def test_no_source_delivers_a_file_over_the_size_cap(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                     source: str) -> None:
    """docs/data.md: no file over ``MAX_FILE_BYTES`` (64 MiB) is accepted from any source; here the cap is set just
    under the largest file's size, and every kind of source must refuse that file, naming it."""
    largest = max(SUMS, key=lambda name: (SHARED / name).stat().st_size)
    monkeypatch.setattr(fetch_module, "MAX_FILE_BYTES", (SHARED / largest).stat().st_size - 1)
    dest = tmp_path / "dest"
    with ExitStack() as stack:
        if source == "http":
            spec: str | Path = stack.enter_context(http_server(SHARED))
        elif source == "archive":
            spec = tmp_path / "eth_ucy.tar.gz"
            with tarfile.open(spec, "w:gz", compresslevel=1) as tar:
                tar.add(SHARED, arcname="eth_ucy")
        else:
            spec = SHARED
        with pytest.raises(FetchError, match=re.escape(largest)):
            fetch(spec, dest, quiet=True)
    assert not (dest / largest).exists() and not list(dest.rglob("*.part")), "the refused file was kept"


AUDITED_FETCH = """
import sys
from replays.fetch import fetch
source, warm, dest = sys.argv[1:4]
fetch(source, warm, quiet=True)  # every code path once, so that nothing is imported during the audited fetch
RUNS = ("exec", "compile", "subprocess.Popen", "os.system", "os.exec", "os.posix_spawn", "os.spawn", "os.fork",
        "ctypes.dlopen", "pickle.find_class", "marshal.loads", "import")
seen = []
sys.addaudithook(lambda event, args: seen.append(event) if event in RUNS else None)
fetch(source, dest, quiet=True)
print(sorted(set(seen)))
"""


def test_fetch_runs_nothing_it_downloads(tmp_path: Path) -> None:
    """docs/data.md: the fetch runs nothing it downloads: an audit hook sees no code compiled, executed, unpickled,
    imported or spawned while every file is fetched, checked and stored (an archive source: the longest path)."""
    archive = tmp_path / "eth_ucy.tar.gz"
    with tarfile.open(archive, "w:gz", compresslevel=1) as tar:
        tar.add(SHARED, arcname="eth_ucy")
    done = subprocess.run([sys.executable, "-c", AUDITED_FETCH, str(archive), str(tmp_path / "warm"),
                           str(tmp_path / "dest")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() == "[]", f"the fetch ran code: {done.stdout.strip()}"
    verify_data_root(tmp_path / "dest")
