"""MkDocs hook: the build fails (a warning, which ``--strict`` turns into an error) when a public class or function
of the four packages is missing from the API reference.

Public: defined at a module's top level, its name and every part of its module path free of a leading underscore.
Rendered: listed in the inventory mkdocstrings writes (``objects.inv`` in the site folder).
"""

from __future__ import annotations

import ast
import logging
import zlib
from pathlib import Path
from typing import Any

PACKAGES = ("envs", "predictor", "replays", "st_sim")
log = logging.getLogger("mkdocs.hooks.api_coverage")  # under "mkdocs": counted by --strict


def public_names(root: Path) -> list[str]:
    """Dotted names of the public module-level classes and functions of ``PACKAGES`` under ``root``."""
    names = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if any(part.startswith("_") and part != "__init__" for part in parts):
                continue
            module = ".".join(part for part in parts if part != "__init__")
            for node in ast.parse(path.read_text(encoding="utf-8"), str(path)).body:
                if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) \
                        and not node.name.startswith("_"):
                    names.append(f"{module}.{node.name}")
    return names


def inventory_names(path: Path) -> set[str]:
    """Object names in a Sphinx-format inventory (four header lines, then zlib-compressed ``name domain ...``)."""
    compressed = path.read_bytes().split(b"\n", 4)[4]
    return {line.split(" ", 1)[0] for line in zlib.decompress(compressed).decode().splitlines()}


def on_post_build(config: Any, **kwargs: Any) -> None:
    inventory = Path(config.site_dir) / "objects.inv"
    if not inventory.is_file():
        log.warning(f"{inventory}: no inventory, so the API reference cannot be checked")
        return
    root = Path(config.config_file_path).parent
    missing = sorted(set(public_names(root)) - inventory_names(inventory))
    if missing:
        log.warning(f"{len(missing)} public names are missing from the API reference (document them, or make them "
                    f"private with a leading underscore): {', '.join(missing[:20])}")
