"""What a policy spec points at, so a benchmark run knows what it scored: a changed model or changed code behind the
same spec is a different run.

    parts = policy_fingerprint("sb3:runs/my.zip", checked_policy)   # {"file runs/my.zip": "<sha256>"}
    changes = fingerprint_changes(held_parts, parts)              # what differs, in words

The parts of a fingerprint, by spec:
- ``sb3:PATH.zip``: the SHA-256 of the zip;
- ``package.module:name`` (the shipped planners too): the SHA-256 of every ``.py`` file of the package the module
  lies in (the module's own file if it is not in a package), each named by its path inside that package, and the
  installed distribution's version where the package belongs to one;
- whatever the built policy declares: an optional ``fingerprint()`` method returning a string (the model file it
  loads and its hash, say), under the part ``declared``.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
from pathlib import Path
from typing import Any

from st_sim.apps.navigation.planners import PLANNERS
from st_sim.apps.navigation.policies import SB3_PREFIX

DECLARED = "declared"
"""the part holding the string the policy's own ``fingerprint()`` returns"""


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes, read in blocks."""
    digest = hashlib.sha256()
    with path.open("rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def policy_fingerprint(spec: str, policy: Any) -> dict[str, str]:
    """The parts (name -> hash or version) that identify what ``spec`` ran, ``policy`` being what it built (its
    ``fingerprint()``, if it has one, joins them); see the module docstring."""
    if spec.startswith(SB3_PREFIX):
        path = Path(spec.removeprefix(SB3_PREFIX)).expanduser()
        parts = {f"file {path.name}": file_sha256(path)}
    else:
        parts = source_parts(PLANNERS.get(spec, spec).split(":")[0])
    declare = getattr(policy, "fingerprint", None)
    if callable(declare):
        parts[DECLARED] = str(declare())
    return parts


def source_parts(module: str) -> dict[str, str]:
    """``{"source <path in its package>": sha256}`` of every ``.py`` file of the package ``module`` lies in (its own
    file alone for a top-level module), plus ``{"version <distribution>": version}`` if the package is installed as
    a distribution; empty for a module without source files (a builtin)."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
        return {}
    origin = Path(spec.origin)
    package = module.rpartition(".")[0] if spec.submodule_search_locations is None else module
    if not package:
        files, root = [origin], origin.parent
    else:
        root = Path(importlib.util.find_spec(package).origin).parent
        files = sorted(root.rglob("*.py"))
    parts = {f"source {path.relative_to(root).as_posix()}": file_sha256(path) for path in files}
    top = module.partition(".")[0]
    for distribution in importlib.metadata.packages_distributions().get(top, []):
        parts[f"version {distribution}"] = importlib.metadata.version(distribution)
    return parts


def fingerprint_changes(held: dict[str, str], now: dict[str, str]) -> list[str]:
    """What differs between two fingerprints, one phrase per part: changed, gone or new."""
    changes = []
    for part in sorted(set(held) | set(now)):
        if part not in now:
            changes.append(f"{part} is gone")
        elif part not in held:
            changes.append(f"{part} is new")
        elif held[part] != now[part]:
            what = f"{held[part]!r} then, {now[part]!r} now" if part == DECLARED or part.startswith("version") else \
                "changed"
            changes.append(f"{part} {what}")
    return changes
