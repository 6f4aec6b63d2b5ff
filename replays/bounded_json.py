"""Reading JSON that others wrote, within bounds: the file's size, its decompressed size, its nesting depth and its
count of tokens are capped before anything is parsed.

Python's ``json`` has no limits: a 400 KB gzip bomb decompresses into gigabytes, ``[[[[...`` a thousand levels deep
raises RecursionError, and a long flat array of small values takes 10 to 30 times its text in memory. ``read_json``
reads a JSON file, or a gzipped one (name ending ``.gz``), block by block and stops past ``MAX_JSON_BYTES``; one
regular-expression pass over the text (strings skipped, no recursion) then counts its tokens and measures its depth;
only then is it parsed, strictly (no NaN, no Infinity: the project's writers never write them):

    summary = read_json("results/benchmark/mpc-singular/summary.json.gz", "benchmark summary")

``parse_json`` holds JSON text already in memory (a zip's member, say) to the same caps:

    data = parse_json(archive.read("data"), f"{path}: data", "stable-baselines3 model's data")

The caps are set so that reading any file, parsed values included, takes less than 100 MB more memory than reading
a committed benchmark summary (1.5 MB of JSON), and a file past a cap is refused in under a second
(``benchmarks/hostile_results.py`` measures both). Every refusal is a ``DataFormatError`` (``MemoryBudgetError`` for
the sizes) naming the file and the limit.
"""

from __future__ import annotations

import gzip
import json
import os
import re
import zlib
from contextlib import nullcontext
from pathlib import Path
from typing import Any, BinaryIO, Final

from replays.errors import DataFormatError, MemoryBudgetError
from replays.files import open_regular

MAX_FILE_BYTES: Final[int] = 16 << 20  # largest file read, gzipped or not [B]
MAX_JSON_BYTES: Final[int] = 16 << 20  # largest JSON text, after decompression [B]; a committed summary: 1.5 MB
MAX_DEPTH: Final[int] = 32  # deepest nesting of arrays and objects [levels]; a benchmark summary: 5
MAX_TOKENS: Final[int] = 2_000_000  # strings, brackets, commas and colons [-]; a committed summary: 205,000
BLOCK_BYTES: Final[int] = 1 << 20  # decompressed per read [B]
_TOKEN: Final = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"?|[][{},:]', re.DOTALL)
"""a string (one left open runs to the end: the scan stays linear, and the parser refuses it) or a structural
character"""


def read_json(path: str | os.PathLike, what: str = "JSON file") -> Any:
    """The value of the JSON file ``path`` (gzipped if its name ends with ``.gz``), read within the module's caps.

    Args:
        what: what the file should hold, for messages ("benchmark summary").

    Raises:
        MemoryBudgetError: the file, or its decompressed text, is larger than its cap.
        NotRegularFileError: a FIFO, device, socket or folder.
        DataFormatError: nested too deep, too many tokens, not gzip, not UTF-8, not strict JSON, or unreadable.
    """
    path = Path(path)
    gzipped = path.suffix == ".gz"
    with open_regular(path, MAX_FILE_BYTES, what) as raw, \
            (gzip.GzipFile(fileobj=raw) if gzipped else nullcontext(raw)) as stream:
        data = _read_capped(stream, path, what, gzipped)
    check_shape(data, path, what)
    text = _utf8(data, path)
    del data  # the parse holds the text and the values only
    return _strict(text, path)


def parse_json(data: bytes | bytearray, path: str | os.PathLike, what: str = "JSON text") -> Any:
    """The value of the JSON text ``data`` (UTF-8 bytes), held to ``read_json``'s caps (``MAX_JSON_BYTES``,
    ``MAX_DEPTH``, ``MAX_TOKENS``, strict: no NaN, no Infinity) and refused with the same errors.

    Args:
        path: where the text comes from, for messages (``"model.zip: data"``).  what: what it should hold.
    """
    if len(data) > MAX_JSON_BYTES:
        raise MemoryBudgetError(f"{path}: {len(data):,} bytes, more than the {MAX_JSON_BYTES:,} bytes of JSON a "
                                f"{what} may hold (replays.bounded_json.MAX_JSON_BYTES)")
    check_shape(data, path, what)
    return _strict(_utf8(data, path), path)


def _utf8(data: bytes | bytearray, path: str | os.PathLike) -> str:
    """``data`` decoded as UTF-8 (``DataFormatError`` naming ``path`` otherwise)."""
    try:
        return data.decode()
    except UnicodeDecodeError as err:
        raise DataFormatError(f"{path}: not UTF-8 text ({err})") from None


def _strict(text: str, path: str | os.PathLike) -> Any:
    """``text`` parsed as strict JSON (``DataFormatError`` naming ``path`` otherwise)."""
    try:
        return json.loads(text, parse_constant=_refuse_constant)
    except ValueError as err:  # malformed, NaN or Infinity, an integer of more digits than Python converts
        raise DataFormatError(f"{path}: not strict JSON ({err})") from None


def _read_capped(stream: BinaryIO, path: Path, what: str, gzipped: bool) -> bytearray:
    """The bytes of ``stream``, read a block at a time; ``MemoryBudgetError`` as soon as they pass
    ``MAX_JSON_BYTES``."""
    data = bytearray()
    try:
        while block := stream.read(BLOCK_BYTES):
            data += block
            if len(data) > MAX_JSON_BYTES:
                raise MemoryBudgetError(f"{path}: {'decompresses to ' if gzipped else ''}more than the "
                                        f"{MAX_JSON_BYTES:,} bytes of JSON a {what} may hold "
                                        "(replays.bounded_json.MAX_JSON_BYTES)")
    except (OSError, EOFError, zlib.error) as err:
        raise DataFormatError(f"{path}: cannot read{' its gzip stream' if gzipped else ''} ({err})") from None
    return data


def check_shape(text: bytes | bytearray, path: str | os.PathLike, what: str = "JSON file") -> None:
    """Refuse JSON text nested deeper than ``MAX_DEPTH`` or of more than ``MAX_TOKENS`` tokens (``DataFormatError``
    naming ``path`` and the limit), without parsing it: brackets are counted outside strings."""
    depth = 0
    for count, token in enumerate(_TOKEN.finditer(text), 1):
        if count > MAX_TOKENS:
            raise DataFormatError(f"{path}: more than {MAX_TOKENS:,} JSON tokens (strings, brackets, commas, colons), "
                                  f"more than a {what} may hold (replays.bounded_json.MAX_TOKENS)")
        char = text[token.start()]
        if char in b"[{":
            depth += 1
            if depth > MAX_DEPTH:
                raise DataFormatError(f"{path}: JSON nested more than {MAX_DEPTH} levels deep, deeper than a {what} "
                                      "may be (replays.bounded_json.MAX_DEPTH)")
        elif char in b"]}":
            depth -= 1


def _refuse_constant(name: str) -> None:
    raise ValueError(f"{name} is not JSON")
