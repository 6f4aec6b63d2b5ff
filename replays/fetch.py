"""Fetch a data set's files (ETH/UCY or CITR) into a data root, checking each against the project's SHA-256 sums.

Sources (``python -m replays fetch [--dataset citr] --from ...``):

- nothing: the public mirrors: for ETH/UCY one row per folder in ``MIRRORS``, for CITR its authors' repository at
  a fixed commit (``CITR_URL``);
- an http(s) URL: one base URL laid out like the data root (same download code as the mirrors);
- a folder laid out like the data root (e.g. ``../shared/datasets/eth_ucy``);
- a ``.zip`` / ``.tar`` / ``.tar.gz`` archive of such a folder, at its top or under one folder.

Each file is written to ``<file>.part`` beside its final name, its SHA-256 is checked, and only then does
``os.replace`` give it its final name, so a final name never holds a partial or unchecked file. Files that
already hold the right bytes are skipped; an interrupted ``.part`` download resumes with an HTTP Range
request when the server honours it and restarts otherwise. Nothing of the user's is deleted: a file at a
final name with other bytes (an edited copy, say) is renamed ``<file>.modified`` once its replacement has
been verified, and the report lists it. Only regular files are read from a source folder, and no file
larger than ``MAX_FILE_BYTES`` is accepted from any source.
"""

from __future__ import annotations

import os
import posixpath
import tarfile
import time
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from http.client import HTTPException, HTTPResponse, IncompleteRead
from pathlib import Path
from typing import IO, Final, NamedTuple, Protocol
from urllib.error import HTTPError, URLError
from urllib.parse import quote
from urllib.request import Request, urlopen

from tqdm import tqdm

from replays.data_root import CITR, ETH_UCY, Dataset, expected_sums, sha256_of
from replays.errors import DataFormatError
from replays.files import open_regular

SOCIAL_STGCNN_URL: Final = "https://raw.githubusercontent.com/abduallahmohamed/Social-STGCNN/master/datasets/"
LMTRAJECTORY_URL: Final = "https://raw.githubusercontent.com/InhwanBae/LMTrajectory/main/datasets/"
MIRRORS: Final[tuple[tuple[str, str, tuple[str, str] | None], ...]] = (
    # (folder of our layout, base URL holding the same relative path, (our suffix, mirror suffix) rename)
    ("raw/", SOCIAL_STGCNN_URL, None),
    ("eth/", SOCIAL_STGCNN_URL, None),
    ("hotel/", SOCIAL_STGCNN_URL, None),
    ("univ/", SOCIAL_STGCNN_URL, None),
    ("zara1/", SOCIAL_STGCNN_URL, None),
    ("zara2/", SOCIAL_STGCNN_URL, None),
    ("homography/", LMTRAJECTORY_URL, None),
    ("image/", LMTRAJECTORY_URL, ("_map.png", "_oracle.png")),  # LMTrajectory calls the maps *_oracle.png
)
CITR_URL: Final = ("https://raw.githubusercontent.com/dongfang-steven-yang/vci-dataset-citr/"
                   "b6a980628f48e7c80c748c3e333979ca3a6b0301/data/trajectories_filtered/")
"""CITR's filtered trajectories at the authors' commit b6a9806 (2019-04-19), laid out as our data root"""
TIMEOUT_S: Final = 30.0  # per connection attempt and per blocking read
RETRY_DELAYS_S: Final = (0.5, 2.0)  # pauses before the 2nd and 3rd attempt at one file
CHUNK_BYTES: Final = 1 << 16
MAX_FILE_BYTES: Final = 64 << 20  # no file of either data set comes near this (the largest is 0.9 MB) [B]
MODIFIED_SUFFIX: Final = ".modified"  # an existing file with other bytes is renamed <file>.modified
USER_AGENT: Final = "stcrowd-fetch/0.1 (python urllib)"
ARCHIVE_ERRORS: Final = (tarfile.TarError, zipfile.BadZipFile, EOFError, zlib.error)  # damaged archive
SOURCE_HINT: Final = "--from takes a folder laid out like the data root, a .zip/.tar(.gz) of one, or an http(s) URL"


class FetchError(RuntimeError):
    """A file could not be fetched or failed its SHA-256 check; the message names the file and the fix."""


@dataclass(frozen=True)
class FetchReport:
    """What one ``fetch`` run did."""

    dest: Path
    """the data root that was filled"""
    fetched: int
    """files transferred and verified in this run"""
    skipped: int
    """files already present with the right SHA-256"""
    bytes_moved: int
    """bytes transferred in this run [B]"""
    moved_aside: tuple[Path, ...] = ()
    """files that held other bytes under a final name, renamed ``<file>.modified`` (never deleted)"""


class Opened(NamedTuple):
    """A readable stream of one file, opened by a source."""

    stream: IO[bytes]
    start: int
    """byte offset the stream begins at: the ``.part`` length when resuming, else 0"""
    length: int | None
    """bytes the stream should deliver (HTTP Content-Length), None if unknown"""


class Source(Protocol):
    """Where the files come from; ``open`` may honour ``offset`` (resume) or start at 0."""

    def where(self, name: str) -> str: ...

    def order(self, names: list[str]) -> list[str]: ...

    def open(self, name: str, offset: int) -> AbstractContextManager[Opened]: ...


def mirror_url(name: str, dataset: Dataset = ETH_UCY) -> str:
    """Public-mirror URL of one file of our layout (``image/seq_eth_map.png`` -> ``.../seq_eth_oracle.png``)."""
    if dataset is CITR:
        return CITR_URL + quote(name)
    for folder, base_url, rename in MIRRORS:
        if name.startswith(folder):
            if rename is not None and name.endswith(rename[0]):
                name = name.removesuffix(rename[0]) + rename[1]
            return base_url + quote(name)
    raise FetchError(f"{name}: no public mirror holds this folder (see MIRRORS in {__file__})")


class UrlSource:
    """Files over http(s); ``url_of`` maps a relative path to its URL."""

    def __init__(self, url_of: Callable[[str], str]) -> None:
        self.url_of = url_of

    def where(self, name: str) -> str:
        return self.url_of(name)

    def order(self, names: list[str]) -> list[str]:
        return names

    @contextmanager
    def open(self, name: str, offset: int) -> Iterator[Opened]:
        response, start = _request(self.url_of(name), offset)
        length = response.headers.get("Content-Length")
        with response:
            yield Opened(response, start, None if length is None else int(length))


def _request(url: str, offset: int) -> tuple[HTTPResponse, int]:
    """GET ``url``, asking for the bytes from ``offset`` on; returns the response and where it starts."""
    headers = {"User-Agent": USER_AGENT}
    if offset:
        headers["Range"] = f"bytes={offset}-"
    try:
        response = urlopen(Request(url, headers=headers), timeout=TIMEOUT_S)
    except HTTPError as err:
        if err.code != 416 or not offset:
            raise
        err.close()  # 416: the .part is as long as the file or longer, so it cannot be resumed
        return _request(url, 0)
    if response.status != 206:
        return response, 0  # the server ignored the Range header: the body is the whole file
    if response.headers.get("Content-Range", "").startswith(f"bytes {offset}-"):
        return response, offset
    response.close()
    return _request(url, 0)


class FolderSource:
    """Files copied from a local folder laid out like the data root."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def where(self, name: str) -> str:
        return str(self.root / name)

    def order(self, names: list[str]) -> list[str]:
        return names

    @contextmanager
    def open(self, name: str, offset: int) -> Iterator[Opened]:
        path = self.root / name
        if not path.exists():
            raise FetchError(f"{path}: missing from the source folder {self.root}. {SOURCE_HINT}.")
        try:
            with open_regular(path, MAX_FILE_BYTES, "data-set file") as stream:
                stream.seek(offset)
                yield Opened(stream, offset, None)
        except DataFormatError as err:  # a FIFO, device or folder, or a huge file
            raise FetchError(f"{err}. {SOURCE_HINT}.") from err


class ArchiveSource:
    """Files read from a zip or tar archive holding the data-root layout at its top or under one folder."""

    def __init__(self, path: Path, members: dict, open_member: Callable, position: Callable,
                 names: Iterable[str]) -> None:
        self.path = path
        self._members = {posixpath.normpath(name): member for name, member in members.items()}
        self._open_member = open_member
        self._position = position
        self.prefix = _layout_prefix(self._members, names)

    def where(self, name: str) -> str:
        return f"{self.path}:{self.prefix + name}"

    def order(self, names: list[str]) -> list[str]:
        """Archive order, so a compressed tar is read front to back once."""
        return sorted(names, key=lambda n: self._position(self._members[self.prefix + n])
                      if self.prefix + n in self._members else -1)

    @contextmanager
    def open(self, name: str, offset: int) -> Iterator[Opened]:
        member = self._members.get(self.prefix + name)
        if member is None:
            raise FetchError(f"{self.path}: the archive has no file {self.prefix + name}. {SOURCE_HINT}.")
        with self._open_member(member) as stream:
            yield Opened(stream, 0, None)


def _layout_prefix(members: Iterable[str], names: Iterable[str]) -> str:
    """The folder of the archive holding the layout: '' or e.g. 'eth_ucy/' (found from the first match)."""
    for name in names:
        for member in members:
            if member == name or member.endswith("/" + name):
                return member[: len(member) - len(name)]
    return ""


@contextmanager
def open_source(spec: str | os.PathLike | None, dataset: Dataset = ETH_UCY) -> Iterator[Source]:
    """Open the source named by ``--from``: None (the data set's public mirrors), an http(s) URL, a folder or an
    archive."""
    if spec is None:
        yield UrlSource(lambda name: mirror_url(name, dataset))
        return
    text = os.fspath(spec)
    if text.startswith(("http://", "https://")):
        base_url = text if text.endswith("/") else text + "/"
        yield UrlSource(lambda name: base_url + quote(name))
        return
    path = Path(text).expanduser()
    if path.is_dir():
        yield FolderSource(path)
    elif path.is_file() and (zipfile.is_zipfile(path) or tarfile.is_tarfile(path)):
        try:
            with _open_archive(path, expected_sums(dataset)) as archive_source:
                yield archive_source
        except ARCHIVE_ERRORS as err:  # raised while listing; per-file read errors are reported by _transfer
            raise FetchError(f"{path}: damaged or truncated archive ({err}). Get a fresh copy of it.") from err
    else:
        raise FetchError(f"{text}: no such folder, not a zip or tar archive, and not an http(s) URL. {SOURCE_HINT}.")


@contextmanager
def _open_archive(path: Path, names: Iterable[str]) -> Iterator[ArchiveSource]:
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as archive:
            members = {info.filename: info for info in archive.infolist() if not info.is_dir()}
            yield ArchiveSource(path, members, archive.open, lambda info: info.header_offset, names)
    else:
        with tarfile.open(path, "r:*") as archive:
            members = {m.name: m for m in archive.getmembers() if m.isfile()}
            yield ArchiveSource(path, members, archive.extractfile, lambda m: m.offset, names)


def fetch(source: str | os.PathLike | None = None, dest: str | os.PathLike | None = None, *,
          quiet: bool = False, dataset: Dataset = ETH_UCY) -> FetchReport:
    """Fill ``dest`` with every file of the data set's SHA-256 list, verified.

    Args:
        source: None for the public mirrors, an http(s) base URL, a folder or an archive (see module doc).
        dest: data root to fill; default the data set's cache (``~/.cache/stcrowd/eth_ucy``, ``.../citr``).
        quiet: no progress bar.
        dataset: which data set (``replays.data_root.ETH_UCY`` or ``CITR``).

    Returns:
        Counts of fetched and skipped files.

    Raises:
        FetchError: on the first file that cannot be fetched or fails its check; files verified so far stay.
    """
    dest = Path(dest if dest is not None else dataset.default_cache).expanduser().resolve()
    if source is not None and Path(source).expanduser().resolve() == dest:
        raise FetchError(f"--from and --dest are the same folder ({dest}): nothing can be fetched from a folder "
                         f"into itself. Fetch from another copy, or check it with `python -m replays verify`.")
    sums = expected_sums(dataset)
    fetched = skipped = moved = 0
    aside: list[Path] = []
    with open_source(source, dataset) as src, tqdm(total=len(sums), unit="file", desc="fetch", disable=quiet) as bar:
        for name in src.order(list(sums)):
            final = dest / name
            if _holds(final, sums[name]):
                skipped += 1
            else:
                more, moved_aside = _fetch_file(src, name, sums[name], final)
                moved, fetched = moved + more, fetched + 1
                aside += [moved_aside] if moved_aside else []
            bar.update(1)
            bar.set_postfix_str(f"{moved / 1e6:.1f} MB", refresh=False)
    return FetchReport(dest, fetched, skipped, moved, tuple(aside))


def _holds(final: Path, digest: str) -> bool:
    """True if ``final`` already holds the right bytes (a stale ``.part`` beside it is then removed)."""
    if not final.is_file() or sha256_of(final) != digest:
        return False
    _part_of(final).unlink(missing_ok=True)  # stale leftover of an earlier run
    return True


def _move_aside(final: Path) -> Path | None:
    """Rename whatever sits at ``final`` to ``<final>.modified`` (numbered if taken); None if nothing is there."""
    if not os.path.lexists(final):
        return None
    target = final.with_name(final.name + MODIFIED_SUFFIX)
    number = 0
    while os.path.lexists(target):
        number += 1
        target = final.with_name(f"{final.name}{MODIFIED_SUFFIX}.{number}")
    os.rename(final, target)
    return target


def _part_of(final: Path) -> Path:
    return final.with_name(final.name + ".part")


def _fetch_file(src: Source, name: str, digest: str, final: Path) -> tuple[int, Path | None]:
    """Transfer one file into its ``.part``, check its SHA-256, move it into place.

    Returns:
        Bytes moved, and where a different file that sat at ``final`` was moved (None if there was none).
    """
    part = _part_of(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    moved, start = _transfer(src, name, part)
    got = sha256_of(part)
    if got != digest and start > 0:  # the kept prefix may belong to another copy: start over once
        part.unlink()
        more, start = _transfer(src, name, part)
        moved, got = moved + more, sha256_of(part)
    if got != digest:
        part.unlink()
        raise FetchError(
            f"{name}: SHA-256 mismatch for {src.where(name)}: expected {digest}, got {got}. "
            f"The download was deleted and {final} was not written; the source copy is corrupt or a different "
            "version. Run the command again, or fetch from another copy with --from DIR_OR_ARCHIVE_OR_URL."
        )
    aside = _move_aside(final)
    os.replace(part, final)
    return moved, aside


def _transfer(src: Source, name: str, part: Path) -> tuple[int, int]:
    """Append the missing bytes of ``name`` to ``part``, retrying network errors; returns (bytes, start)."""
    delays_s = iter(RETRY_DELAYS_S)
    while True:
        offset = part.stat().st_size if part.is_file() else 0
        try:
            with src.open(name, offset) as opened, open(part, "ab" if opened.start else "wb") as out:
                while block := opened.stream.read(CHUNK_BYTES):
                    if out.tell() + len(block) > MAX_FILE_BYTES:
                        part.unlink()
                        raise FetchError(f"{name}: {src.where(name)} is larger than {MAX_FILE_BYTES:,} bytes, far "
                                         "more than any file of the data set: not the ETH/UCY file. " + SOURCE_HINT)
                    out.write(block)
                out.flush()
                os.fsync(out.fileno())
                moved = out.tell() - opened.start
                if opened.length is not None and moved < opened.length:  # urllib does not notice a cut body
                    raise IncompleteRead(b"", opened.length - moved)
                return moved, opened.start
        except (OSError, HTTPException, *ARCHIVE_ERRORS) as err:
            delay_s = next(delays_s, None)
            if delay_s is None or not _is_transient(err):
                raise FetchError(_describe(err, name, src)) from err
            time.sleep(delay_s)


def _is_transient(err: Exception) -> bool:
    """Network trouble worth another attempt (timeouts, refused or dropped connections, HTTP 5xx and 429)."""
    if isinstance(err, HTTPError):
        return err.code >= 500 or err.code == 429
    return isinstance(err, URLError | TimeoutError | ConnectionError | HTTPException)


def _describe(err: Exception, name: str, src: Source) -> str:
    attempts = len(RETRY_DELAYS_S) + 1
    if isinstance(err, HTTPError):
        return f"{name}: {err.url} answered HTTP {err.code} {err.reason}. {SOURCE_HINT}."
    if _is_transient(err):
        reason = err.reason if isinstance(err, URLError) else err
        return (f"{name}: could not download {src.where(name)} after {attempts} attempts ({reason}). "
                "Check the network connection and run the command again (finished files are kept), "
                "or fetch from a local copy with --from DIR_OR_ARCHIVE.")
    if isinstance(err, ARCHIVE_ERRORS):
        return f"{name}: cannot read {src.where(name)} ({err}): the archive is damaged. Get a fresh copy of it."
    return f"{name}: {err}"
