"""What decided a benchmark run's episodes, so that a run knows what it scored: a changed model, changed code, a
changed file or another STCrowd behind the same command is a different run.

    with ReadAudit(outside=[out, data_root]) as audit:      # every file opened and module imported in the block
        policy = load_policy(spec, world, predictor); run_episode(env, policy, world, seed)
    parts = policy_fingerprint(spec, policy.policy, audit)   # {"source policy.py": "<sha256>", "read w.npz": ...}
    changes = fingerprint_changes(held_parts, parts)         # what differs, in words

The parts of a policy's fingerprint:
- ``sb3:PATH.zip``: the SHA-256 of the zip (``file <name>``);
- ``package.module:name``: the SHA-256 of every ``.py`` file of the package the module lies in (the module's own
  file if it is not in a package; a namespace package's folder alike), named ``source <path in the package>``, and
  the installed distribution's version where the package belongs to one (``version <distribution>``);
- every module outside STCrowd and the installed packages that is loaded once the policy is built and has run its
  first episode (``module <name>``): whatever the policy imports, directly or not, is among them;
- every file it opened for reading meanwhile, outside STCrowd, the installed packages, the system and the folders
  ``outside`` names (``read <path>``: relative to the working folder where it lies inside it);
- whatever the built policy declares: an optional ``fingerprint()`` method returning a string, as ``declared``.

A shipped planner's code is STCrowd's own, identified by ``stcrowd_identity`` (its version and a hash of its
source and package data); a shipped predictor by the hashes of its checkpoints (``predictor_fingerprint``).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import os
import site
import sys
import sysconfig
from functools import cache
from pathlib import Path
from typing import Any, ClassVar

from replays import strict_json
from st_sim.apps.navigation.planners import NAMED
from st_sim.apps.navigation.policies import SB3_PREFIX

DECLARED = "declared"
"""the part holding the string the policy's own ``fingerprint()`` returns"""
STCROWD_PACKAGES = ("st_sim", "predictor", "envs", "replays")
"""STCrowd's own packages: their code and data are ``stcrowd_identity``'s"""
SOURCE_SUFFIXES = (".py", ".json", ".pt", ".sha256")
"""files of STCrowd's packages that decide what it does: code, settings, checkpoints, data sums"""
SYSTEM_ROOTS = ("/proc", "/sys", "/dev", "/usr", "/etc", "/lib", "/lib64", "/bin", "/sbin")
"""folders whose files are the system's, never a policy's data"""


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes, read in blocks."""
    digest = hashlib.sha256()
    with path.open("rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@cache
def stcrowd_identity() -> dict[str, str]:
    """``{"version": the installed version, "source_sha256": hex SHA-256 over the path and bytes of every file of
    STCrowd's packages with a suffix of SOURCE_SUFFIXES}``: a change of STCrowd's code, settings or checkpoints
    changes the hash (computed once per process)."""
    digest = hashlib.sha256()
    for root in _stcrowd_roots():
        for path in sorted(root.rglob("*")):
            if path.suffix in SOURCE_SUFFIXES and "__pycache__" not in path.parts and path.is_file():
                digest.update(f"{path.relative_to(root.parent).as_posix()}\0{file_sha256(path)}\n".encode())
    try:
        version = importlib.metadata.version("stcrowd")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    return {"version": version, "source_sha256": digest.hexdigest()}


def _stcrowd_roots() -> list[Path]:
    return [Path(importlib.util.find_spec(name).origin).parent for name in STCROWD_PACKAGES]


class ReadAudit:
    """A context that records what the code run inside it reads: the files it opens for reading (Python's audit
    event ``open``), and on leaving, every module loaded by then from outside STCrowd, the installed packages and the
    system (a module imported before the context counts too, so a second run in one process sees what the first
    did). Files under STCrowd, the installed packages, the system and the folders ``outside`` are not recorded.

    Attributes:
        files: resolved paths of the regular files opened for reading.  modules: names of the user modules loaded.
    """

    _active: ClassVar[list[ReadAudit]] = []  # the audits recording now (the hook is installed once, for good)
    _installed: ClassVar[bool] = False

    def __init__(self, outside: list[str | os.PathLike | None] = ()):
        self.skip = tuple(str(Path(root).expanduser().resolve()) for root in [*_installed_roots(), *outside]
                          if root is not None)
        self.files: set[Path] = set()
        self.modules: set[str] = set()
        self.written: set[Path] = set()

    def __enter__(self) -> ReadAudit:
        if not ReadAudit._installed:
            sys.addaudithook(_on_event)
            ReadAudit._installed = True
        ReadAudit._active.append(self)
        return self

    def __exit__(self, *exc: Any) -> None:
        ReadAudit._active.remove(self)
        self.modules = {name for name, module in list(sys.modules.items()) if _local_file(module) is not None}

    def opened(self, path: Any, mode: Any) -> None:
        """Record ``path`` if it is a regular file outside the skipped roots, opened for reading; a file the audited
        code writes is its output (a cache), never its input, and is dropped."""
        if isinstance(path, int):
            return
        try:
            resolved = Path(os.fsdecode(path)).expanduser().resolve()
        except (OSError, ValueError, TypeError):
            return
        if isinstance(mode, str) and set(mode) & {"w", "a", "x", "+"}:
            self.written.add(resolved)
            self.files.discard(resolved)
            return
        text = str(resolved)
        if resolved in self.written or resolved.suffix in (".pyc", ".py") or \
                any(text == root or text.startswith(root + os.sep) for root in self.skip):
            return  # modules are hashed as modules
        if resolved.is_file():
            self.files.add(resolved)


def _on_event(event: str, args: tuple) -> None:
    if event == "open" and ReadAudit._active:
        for audit in ReadAudit._active:
            audit.opened(args[0], args[1] if len(args) > 1 else None)


@cache
def _installed_roots() -> tuple[str, ...]:
    """Folders whose files are not a policy's own: the interpreter's, the installed packages', the user's caches and
    settings, the system's, STCrowd's packages."""
    paths = {sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix, *site.getsitepackages(),
             site.getusersitepackages(), *SYSTEM_ROOTS, "~/.cache", "~/.config",
             *(sysconfig.get_paths()[key] for key in ("stdlib", "platstdlib", "purelib", "platlib"))}
    return tuple(sorted({str(Path(p).expanduser().resolve()) for p in paths} | {str(r) for r in _stcrowd_roots()}))


def _local_file(module: Any) -> Path | None:
    """The source file of ``module`` if it lies outside the interpreter, the installed packages and STCrowd (a
    module of the user's project), else None."""
    origin = getattr(module, "__file__", None)
    if not isinstance(origin, str):
        return None
    path = Path(origin).resolve()
    text = str(path)
    if any(text.startswith(root + os.sep) for root in _installed_roots()):
        return None
    return path if path.is_file() else None


def policy_fingerprint(spec: str, policy: Any, audit: ReadAudit | None = None) -> dict[str, str]:
    """The parts (name -> hash or version) that identify what ``spec`` ran, ``policy`` being what it built and
    ``audit`` what building it and its first episode read; see the module docstring."""
    if spec.startswith(SB3_PREFIX):
        path = Path(spec.removeprefix(SB3_PREFIX)).expanduser()
        parts = {f"file {path.name}": file_sha256(path)}
    elif spec in NAMED:
        parts = {}
    else:
        parts = source_parts(spec.split(":")[0])
    if audit is not None:
        parts |= audit_parts(audit)
    declare = getattr(policy, "fingerprint", None)
    if callable(declare):
        parts[DECLARED] = str(declare())
    return parts


def predictor_fingerprint(predictor: str, audit: ReadAudit | None = None) -> dict[str, str]:
    """What identifies the env's predictor: for ``singular`` the SHA-256 of the shipped checkpoints' manifest (which
    holds every checkpoint's own hash, each checked on load); for a plug-in ``package.module:name`` its package's
    sources and the files it read (``audit``: while the env was made; the user modules it imports are among the
    policy's ``module`` parts, which count every one loaded); nothing for the baselines (their code is STCrowd's)."""
    if predictor == "singular":
        from predictor.checkpoint import pretrained_manifest

        text = strict_json.dumps(pretrained_manifest()["checkpoints"], sort_keys=True)
        return {"checkpoints": hashlib.sha256(text.encode()).hexdigest()}
    if ":" not in predictor:
        return {}
    module = predictor.split(":")[0]
    return source_parts(module) | ({} if audit is None else audit_parts(audit, modules=False))


def audit_parts(audit: ReadAudit, modules: bool = True) -> dict[str, str]:
    """``module <name>``: SHA-256 of each user module ``audit`` saw loaded (unless not ``modules``); ``read
    <path>``: SHA-256 of each file it saw read (the path relative to the working folder where it lies inside it)."""
    parts = {}
    for name in sorted(audit.modules if modules else ()):
        path = _local_file(sys.modules.get(name))
        if path is not None:
            parts[f"module {name}"] = file_sha256(path)
    cwd = Path.cwd().resolve()
    for path in sorted(path for path in audit.files if path.is_file()):  # a temporary file may be gone
        shown = path.relative_to(cwd).as_posix() if path.is_relative_to(cwd) else path.as_posix()
        parts[f"read {shown}"] = file_sha256(path)
    return parts


def source_parts(module: str) -> dict[str, str]:
    """``{"source <path in its package>": sha256}`` of every ``.py`` file of the package ``module`` lies in (its own
    file alone for a top-level module; a namespace package's folders alike), plus ``{"version <distribution>":
    version}`` if the package is installed as a distribution; empty for a module without source files (a builtin)."""
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None or not spec.origin.endswith(".py"):
        return {}
    origin = Path(spec.origin)
    package = module.rpartition(".")[0] if spec.submodule_search_locations is None else module
    if not package:
        roots, files = [origin.parent], [origin]
    else:
        package_spec = importlib.util.find_spec(package)
        roots = [Path(location) for location in package_spec.submodule_search_locations or [origin.parent]]
        files = sorted({path for root in roots for path in root.rglob("*.py") if "__pycache__" not in path.parts})
    parts = {f"source {_inside(path, roots)}": file_sha256(path) for path in files}
    top = module.partition(".")[0]
    for distribution in importlib.metadata.packages_distributions().get(top, []):
        parts[f"version {distribution}"] = importlib.metadata.version(distribution)
    return parts


def _inside(path: Path, roots: list[Path]) -> str:
    """``path`` relative to the first of ``roots`` that holds it."""
    for root in roots:
        if path.is_relative_to(root):
            return path.relative_to(root).as_posix()
    return path.name


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
