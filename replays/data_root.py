"""Where the ETH/UCY files live: argument > ``STCROWD_DATA`` > per-user cache.

The project keeps the SHA-256 sum of every file it uses (``replays/eth_ucy.sha256``); a data root is
valid when every listed file is present. ``verify_data_root`` also checks the sums.
"""

from __future__ import annotations

import hashlib
import os
from functools import cache
from importlib import resources
from pathlib import Path

from replays.errors import DataRootError

ENV_VAR = "STCROWD_DATA"
DEFAULT_CACHE = Path("~/.cache/stcrowd/eth_ucy")
FIX_HINT = (
    "Fetch the data with `python -m replays fetch` (or `python -m replays fetch --from DIR_OR_ARCHIVE`), "
    f"or point {ENV_VAR} at a folder holding the ETH/UCY files."
)


@cache
def expected_sums() -> dict[str, str]:
    """Relative path (``eth/test/biwi_eth.txt``) -> SHA-256 hex digest, for every file of the data set."""
    text = resources.files("replays").joinpath("eth_ucy.sha256").read_text()
    sums = {}
    for line in text.splitlines():
        digest, name = line.split(maxsplit=1)
        sums[name.strip().removeprefix("./")] = digest
    return sums


def sha256_of(path: Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk_bytes):
            digest.update(block)
    return digest.hexdigest()


def data_root(path: str | os.PathLike | None = None, *, check: bool = True) -> Path:
    """Resolve the data root: ``path`` if given, else ``$STCROWD_DATA``, else ``~/.cache/stcrowd/eth_ucy``.

    Args:
        path: explicit folder, highest priority.
        check: raise ``DataRootError`` if a listed file is missing (cheap: existence only).

    Returns:
        The absolute folder.
    """
    if path is not None:
        root, source = Path(path), "the path argument"
    elif os.environ.get(ENV_VAR):
        root, source = Path(os.environ[ENV_VAR]), f"${ENV_VAR}"
    else:
        root, source = DEFAULT_CACHE, "the default cache"
    root = root.expanduser().resolve()
    if check and root not in _COMPLETE_ROOTS:
        missing = [name for name in expected_sums() if not (root / name).is_file()]
        if missing:
            raise DataRootError(
                f"ETH/UCY data root {root} (from {source}) is missing {len(missing)} of "
                f"{len(expected_sums())} files, first: {missing[0]}. {FIX_HINT}"
            )
        _COMPLETE_ROOTS.add(root)
    return root


_COMPLETE_ROOTS: set[Path] = set()  # roots found complete in this process (files are not re-stat'ed)


def verify_data_root(root: Path) -> None:
    """Check every file under ``root`` against the project's SHA-256 sums; raise on the first mismatch."""
    for name, digest in expected_sums().items():
        file = root / name
        if not file.is_file():
            raise DataRootError(f"{file}: missing. {FIX_HINT}")
        if sha256_of(file) != digest:
            raise DataRootError(f"{file}: SHA-256 does not match the project's sum (corrupt or altered). {FIX_HINT}")
