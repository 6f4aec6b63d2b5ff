"""Where a data set's files live (argument > its environment variable > per-user cache), and whether they are the
real ones.

Two data sets are known (``DATASETS``): ETH/UCY (``STCROWD_DATA``, ``~/.cache/stcrowd/eth_ucy``), which every
replay, window and checkpoint reads, and CITR (``STCROWD_CITR``, ``~/.cache/stcrowd/citr``): pedestrians reacting to
a vehicle, which validates the reactive pedestrians (``replays.citr``). The project keeps the SHA-256 sum of every
file of each (``replays/eth_ucy.sha256``, ``replays/citr.sha256``). The first time a process uses a data root,
``data_root`` checks that every listed file is present and holds the listed bytes, and that no unlisted data file sits
in a listed folder (the loaders read those folders whole). Digests are cached on disk (``$STCROWD_CACHE``), keyed by
each file's size, mtime and ctime, so only new or changed files are hashed again; after the first use in a process
the root is not looked at again.

A root that differs is refused with the names of the files and the fix. People who edit their own copy on
purpose opt out with ``STCROWD_ALLOW_MODIFIED_DATA=1`` or ``data_root(root, verify=False)``; a warning naming
the modified files is then printed once per process.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Final

from replays import strict_json
from replays.atomic import atomic_path
from replays.errors import DataRootError
from replays.files import open_regular


@dataclass(frozen=True)
class Dataset:
    """A data set the project fetches and checks: its name, where its root is looked for, what its loaders read."""

    key: str
    """short name: the ``--dataset`` value, the cache folder and the sums file's stem (``eth_ucy``, ``citr``)"""
    title: str
    """name in messages (``ETH/UCY``)"""
    env_var: str
    """environment variable naming the data root"""
    data_suffix: str
    """files with this suffix in a listed folder are read whole by the loaders: an unlisted one counts as a change"""

    @property
    def default_cache(self) -> Path:
        """The per-user data root, ``~/.cache/stcrowd/<key>`` (not expanded)."""
        return Path(f"~/.cache/stcrowd/{self.key}")

    @property
    def fetch_command(self) -> str:
        """The command that fetches this data set (``python -m replays fetch [--dataset KEY]``)."""
        return "python -m replays fetch" + ("" if self is ETH_UCY else f" --dataset {self.key}")

    @property
    def fix_hint(self) -> str:
        """How to get the files, for error messages."""
        return (f"Fetch the data with `{self.fetch_command}` (or `{self.fetch_command} --from DIR_OR_ARCHIVE`), or "
                f"point {self.env_var} at a folder holding the {self.title} files.")


ETH_UCY: Final = Dataset("eth_ucy", "ETH/UCY", "STCROWD_DATA", ".txt")
CITR: Final = Dataset("citr", "CITR", "STCROWD_CITR", ".csv")
DATASETS: Final[dict[str, Dataset]] = {dataset.key: dataset for dataset in (ETH_UCY, CITR)}
ENV_VAR: Final = ETH_UCY.env_var
ALLOW_MODIFIED_ENV_VAR: Final = "STCROWD_ALLOW_MODIFIED_DATA"
CACHE_ENV_VAR: Final = "STCROWD_CACHE"
DEFAULT_CACHE: Final = ETH_UCY.default_cache
FIX_HINT: Final = ETH_UCY.fix_hint


@cache
def expected_sums(dataset: Dataset = ETH_UCY) -> dict[str, str]:
    """Relative path (``eth/test/biwi_eth.txt``) -> SHA-256 hex digest, for every file of the data set."""
    text = resources.files("replays").joinpath(f"{dataset.key}.sha256").read_text()
    sums = {}
    for line in text.splitlines():
        digest, name = line.split(maxsplit=1)
        sums[name.strip().removeprefix("./")] = digest
    return sums


def sha256_of(path: Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a regular file, read in chunks (a FIFO or device raises ``NotRegularFileError``)."""
    digest = hashlib.sha256()
    with open_regular(path) as f:
        while block := f.read(chunk_bytes):
            digest.update(block)
    return digest.hexdigest()


def cache_dir() -> Path:
    """Folder of derived files (cut windows, data-root digests): ``$STCROWD_CACHE`` or ``~/.cache/stcrowd/windows``."""
    return Path(os.environ.get(CACHE_ENV_VAR) or "~/.cache/stcrowd/windows").expanduser()


def data_root(path: str | os.PathLike | None = None, *, check: bool = True, verify: bool | None = None,
              dataset: Dataset = ETH_UCY) -> Path:
    """Resolve a data root: ``path`` if given, else the data set's variable (``$STCROWD_DATA`` for ETH/UCY), else its
    cache (``~/.cache/stcrowd/eth_ucy``).

    Args:
        path: explicit folder, highest priority.
        check: on the first use in this process, raise ``DataRootError`` if a listed file is missing or
            differs from the project's SHA-256 sums (cached; see the module docstring).
        verify: False accepts a modified root for the rest of the process (a warning names the modified
            files); None (default) does the same only when ``$STCROWD_ALLOW_MODIFIED_DATA=1``.
        dataset: which data set (``ETH_UCY`` or ``CITR``).

    Returns:
        The absolute folder.
    """
    if path is not None:
        root, source = Path(path), "the path argument"
    elif os.environ.get(dataset.env_var):
        root, source = Path(os.environ[dataset.env_var]), f"${dataset.env_var}"
    else:
        root, source = dataset.default_cache, "the default cache"
    root = root.expanduser().resolve()
    if check and (dataset.key, root) not in _ACCEPTED_ROOTS:
        sums = expected_sums(dataset)
        missing = [name for name in sums if not (root / name).is_file()]
        if missing:
            raise DataRootError(
                f"{dataset.title} data root {root} (from {source}) is missing {len(missing)} of "
                f"{len(sums)} files, first: {missing[0]}. {dataset.fix_hint}"
            )
        _accept_or_refuse(root, source, modified_files(root, dataset=dataset), verify, dataset)
        _ACCEPTED_ROOTS.add((dataset.key, root))
    return root


_ACCEPTED_ROOTS: set[tuple[str, Path]] = set()  # (data set, root) checked (or accepted as modified) in this process


def _accept_or_refuse(root: Path, source: str, modified: dict[str, str], verify: bool | None,
                      dataset: Dataset) -> None:
    if not modified:
        return
    listed = ", ".join(f"{name} ({why})" for name, why in list(modified.items())[:5])
    more = f" and {len(modified) - 5} more" if len(modified) > 5 else ""
    allowed = verify is False or (verify is None and os.environ.get(ALLOW_MODIFIED_ENV_VAR) == "1")
    if not allowed:
        raise DataRootError(
            f"{dataset.title} data root {root} (from {source}) differs from the project's SHA-256 sums in "
            f"{len(modified)} file(s): {listed}{more}. Results from it would not be the benchmark's. Restore the "
            f"files with `{dataset.fetch_command} --dest {root}` (edited files are kept as NAME.modified), or, to "
            f"use an edited copy on purpose, set {ALLOW_MODIFIED_ENV_VAR}=1 or pass verify=False."
        )
    print(f"WARNING: using the MODIFIED {dataset.title} data root {root}: {len(modified)} file(s) differ from the "
          f"project's SHA-256 sums: {listed}{more}. Results are not comparable with published numbers.",
          file=sys.stderr, flush=True)


def modified_files(root: Path, use_cache: bool = True, dataset: Dataset = ETH_UCY) -> dict[str, str]:
    """Files of ``root`` that are not the project's: relative path -> reason, in the sums file's order.

    Reasons: the SHA-256 of a listed file differs, or an extra data file (``*.txt`` of ETH/UCY, ``*.csv`` of CITR)
    sits in a folder the loaders read whole. Missing listed files are not reported here (``data_root`` does that).
    With ``use_cache`` a file whose size, mtime and ctime match the cached entry is not hashed again.
    """
    sums = expected_sums(dataset)
    key = str(root) if dataset is ETH_UCY else f"{dataset.key}:{root}"
    cache_file = cache_dir() / f"sums-{hashlib.sha1(key.encode()).hexdigest()[:16]}.json"
    cached = _read_digest_cache(cache_file) if use_cache else {}
    fresh: dict[str, list] = {}
    modified: dict[str, str] = {}
    for name, digest in sums.items():
        file = root / name
        if not file.is_file():
            continue
        info = file.stat()
        key = [info.st_size, info.st_mtime_ns, info.st_ctime_ns]
        entry = cached.get(name)
        got = entry[3] if entry and entry[:3] == key else sha256_of(file)
        fresh[name] = [*key, got]
        if got != digest:
            modified[name] = "SHA-256 differs from the project's sum"
    folders = {str(Path(name).parent) for name in sums if name.endswith(dataset.data_suffix)}
    for folder in sorted(folders):
        for extra in sorted((root / folder).glob(f"*{dataset.data_suffix}")):
            name = f"{folder}/{extra.name}"
            if name not in sums:
                modified[name] = "extra file, not in the project's list"
    if fresh != cached:
        _write_digest_cache(cache_file, fresh)
    return modified


def _read_digest_cache(path: Path) -> dict[str, list]:
    try:
        files = json.loads(path.read_text())["files"]
        return {str(k): list(v) for k, v in files.items() if isinstance(v, list) and len(v) == 4}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}  # no or unreadable cache: hash again


def _write_digest_cache(path: Path, files: dict[str, list]) -> None:
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(strict_json.dumps({"files": files}))
    except OSError:
        pass  # a read-only cache only costs speed


def verify_data_root(root: Path, dataset: Dataset = ETH_UCY) -> None:
    """Hash every file under ``root`` again and raise ``DataRootError`` naming the first missing or modified one."""
    for name in expected_sums(dataset):
        if not (root / name).is_file():
            raise DataRootError(f"{root / name}: missing. {dataset.fix_hint}")
    modified = modified_files(root, use_cache=False, dataset=dataset)
    if modified:
        name, why = next(iter(modified.items()))
        raise DataRootError(f"{root / name}: {why} (corrupt or altered). {dataset.fix_hint}")
