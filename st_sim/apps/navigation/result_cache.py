"""Benchmark summaries checked once, not on every read: ``result_folder.load_result`` keeps what it checked here,
keyed by the SHA-256 of the summary file's bytes and of STCrowd's code (``fingerprint.stcrowd_identity``).

    key = entry_key(summary_bytes)          # another byte in the file, or other checking code: another key
    entry = cached(key)                     # None, or {"figures_checked": bool, "result": {...}}
    store(key, result, figures_checked=True)

An entry holds the summary as ``load_result`` returned it (fields checked; with ``figures_checked`` its figures
computed again from its episodes too), gzipped JSON in ``$STCROWD_CACHE/checked-results/`` (default
``~/.cache/stcrowd/windows/checked-results``). A file that changes gets another key, so a cached entry never
stands for other bytes; an entry that cannot be read is read as missing and written again. The cache is the
user's own, as the data-root digests beside it are: whoever can write there can change what this machine runs.
"""

from __future__ import annotations

import gzip
import hashlib
import json
from typing import Any

from replays import strict_json
from replays.atomic import atomic_path
from replays.data_root import cache_dir
from st_sim.apps.navigation.fingerprint import stcrowd_identity

CACHE_FOLDER = "checked-results"
"""the cache's folder inside ``replays.data_root.cache_dir()``"""


def entry_key(summary_bytes: bytes) -> str:
    """Hex SHA-256 of a summary file's bytes and of STCrowd's code (which decides what a check finds)."""
    digest = hashlib.sha256(stcrowd_identity()["source_sha256"].encode())
    digest.update(summary_bytes)
    return digest.hexdigest()


def cached(key: str) -> dict[str, Any] | None:
    """The entry stored under ``key`` (``{"figures_checked": bool, "result": summary}``), or None if there is none
    or it cannot be read."""
    path = cache_dir() / CACHE_FOLDER / f"{key}.json.gz"
    try:
        entry = json.loads(gzip.decompress(path.read_bytes()))
    except (OSError, EOFError, ValueError):
        return None
    if not isinstance(entry, dict) or not isinstance(entry.get("figures_checked"), bool) or \
            not isinstance(entry.get("result"), dict):
        return None
    return entry


def store(key: str, result: dict[str, Any], figures_checked: bool) -> None:
    """Keep ``result`` under ``key`` (atomically; a cache that cannot be written is left as it is)."""
    try:
        with atomic_path(cache_dir() / CACHE_FOLDER / f"{key}.json.gz") as tmp:
            text = strict_json.dumps({"figures_checked": figures_checked, "result": result})
            tmp.write_bytes(gzip.compress(text.encode(), compresslevel=1, mtime=0))
    except (OSError, ValueError):  # not writable, or a figure JSON cannot hold
        pass
