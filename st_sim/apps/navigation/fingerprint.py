"""What decided a benchmark run's episodes, so that a run knows what it scored: a changed model, changed code, a
changed file or another STCrowd behind the same command is a different run.

    with ReadAudit(outside=[out, data_root]) as audit:      # every file opened and module imported in the block
        policy = load_policy(spec, world, predictor); run_episode(env, policy, world, seed)
    parts = policy_fingerprint(spec, policy.policy, audit)   # {"source policy.py": "<sha256>", "read w.npz": ...}
    changes = fingerprint_changes(held_parts, parts)         # what differs, in words
    inputs_changes(ChunkInputs(path).parts)                  # what a chunk's episodes read and is not the same now

The parts of a policy's fingerprint:
- ``sb3:PATH.zip``: the SHA-256 of the zip (``file <name>``);
- ``package.module:name``: the SHA-256 of every ``.py`` file of the package the module lies in (the module's own
  file if it is not in a package; a namespace package's folder alike), named ``source <path in the package>``, and
  the installed distribution's version where the package belongs to one (``version <distribution>``);
- every module loaded once the policy is built and has run its first episode (``module <name>``): whatever the
  policy imports, directly or not, but STCrowd's, the standard library's and the installed distributions';
- every file it opened for reading meanwhile, wherever it lies (``read <path>``: relative to the working folder
  where it lies inside it), but STCrowd's, the standard library's, the kernel's pseudo-files, the C library's
  files about the machine (``MACHINE_FILES``: users, hosts, the loader's cache) and the folders ``outside`` names;
- a module or file that an installed distribution's ``RECORD`` lists: ``version <distribution>`` (nothing for the
  distributions STCrowd needs, whose versions are ``stcrowd_identity``'s), and ``version python``;
- whatever the built policy declares: an optional ``fingerprint()`` method returning a string, as ``declared``.

Every chunk of a run's episodes records the same parts of what its episodes read (``ChunkInputs``), in whichever
process runs it; ``inputs_changes`` says which of them are not the same now. Native code is seen where it maps a
file (``ReadAudit.mapped_files``: a library loaded with ``ctypes``, memory-mapped data) and, where the kernel lets a
process watch its own system calls (``open_watch``: Linux), wherever it opens one: a file read and closed by a native
reader (OpenCV's ``imread``), a program run, in any thread or child process.

A shipped planner's code is STCrowd's own, identified by ``stcrowd_identity`` (its version and a hash of its
source and package data); a shipped predictor by the hashes of its checkpoints (``predictor_fingerprint``).
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import os
import platform
import re
import site
import sys
import sysconfig
from functools import cache
from pathlib import Path
from typing import Any, ClassVar

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.bounded_json import read_json
from replays.data_root import cache_dir
from replays.errors import DataFormatError
from st_sim.apps.navigation import open_watch
from st_sim.apps.navigation.planners import NAMED
from st_sim.apps.navigation.policies import SB3_PREFIX

DECLARED = "declared"
"""the part holding the string the policy's own ``fingerprint()`` returns"""
STCROWD_PACKAGES = ("st_sim", "predictor", "envs", "replays")
"""STCrowd's own packages: their code and data are ``stcrowd_identity``'s"""
SOURCE_SUFFIXES = (".py", ".json", ".pt", ".sha256")
"""files of STCrowd's packages that decide what it does: code, settings, checkpoints, data sums"""
PSEUDO_ROOTS = ("/proc", "/sys", "/dev")
"""the kernel's pseudo-files: interfaces, never a policy's data"""
MACHINE_FILES = frozenset({"/etc/ld.so.cache", "/etc/nsswitch.conf", "/etc/passwd", "/etc/group", "/etc/hosts",
                           "/etc/host.conf", "/etc/resolv.conf", "/etc/gai.conf", "/etc/services", "/etc/protocols",
                           "/etc/localtime"})
"""the C library's own files: the dynamic loader's index of the system's libraries and the databases it reads to
look up a user, a group, a host, a service or the time zone (``getpass.getuser``, ``socket.getaddrinfo``): they
describe the machine, never a policy's data, and differ from one machine to the next"""


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
    STCrowd's packages with a suffix of SOURCE_SUFFIXES, "version <distribution>": the version of each distribution
    STCrowd needs (``_dependencies``)}``: a change of STCrowd's code, settings or checkpoints changes the hash, an
    upgrade under it a version (computed once per process)."""
    digest = hashlib.sha256()
    for root in _stcrowd_roots():
        for path in sorted(root.rglob("*")):
            if path.suffix in SOURCE_SUFFIXES and "__pycache__" not in path.parts and path.is_file():
                digest.update(f"{path.relative_to(root.parent).as_posix()}\0{file_sha256(path)}\n".encode())
    try:
        version = importlib.metadata.version("stcrowd")
    except importlib.metadata.PackageNotFoundError:
        version = "unknown"
    return {"version": version, "source_sha256": digest.hexdigest(),
            **{f"version {name}": value for name, value in sorted(_dependencies().items())}}


@cache
def _dependencies() -> dict[str, str]:
    """The installed versions of the distributions STCrowd needs, directly or not (its requirements without an
    extra, followed through theirs), by normalised name; empty where STCrowd is not installed as a distribution."""
    found: dict[str, str] = {}
    todo = ["stcrowd"]
    while todo:
        try:
            requires = importlib.metadata.requires(todo.pop()) or []
        except importlib.metadata.PackageNotFoundError:
            continue
        for requirement in requires:
            match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement)
            name = _normalised(match.group(1)) if match else ""
            if not name or "extra" in requirement.partition(";")[2] or name in found:
                continue
            try:
                found[name] = importlib.metadata.version(name)
            except importlib.metadata.PackageNotFoundError:
                continue
            todo.append(name)
    return found


def _normalised(name: str) -> str:
    """A distribution's name as PEP 503 compares it (``Stable_Baselines3`` -> ``stable-baselines3``)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _stcrowd_roots() -> list[Path]:
    return [Path(importlib.util.find_spec(name).origin).parent for name in STCROWD_PACKAGES]


class ReadAudit:
    """A context that records what the code run inside it reads: the files it opens for reading (Python's audit
    event ``open``: ``open``, ``np.load``, ``torch.load``, ``os.open``, ...), and every module loaded by the time
    ``loaded_modules`` is called or the context left (a module imported before the context counts too, so a second
    run in one process sees what the first did). Where ``open_watch`` runs (started by the first audit of a process),
    every file the process and its children open meanwhile counts too, whatever opened it, but those of the dynamic
    loader's library folders (``_system_roots``). Nothing is skipped for where it lies (the home
    folder's caches, ``/usr``, the interpreter's prefix are read like any folder) but STCrowd's own packages,
    Python's standard library, the kernel's pseudo-files, the C library's files about the machine
    (``MACHINE_FILES``), STCrowd's cache of what it derives from the data (``cache_dir``: keyed by the data files it
    derives from) and the folders ``outside``; a file or module that an
    installed distribution's ``RECORD`` lists is identified by that distribution's version (``audit_parts``).

    Attributes:
        files: resolved paths of the regular files opened for reading.  modules: names of the modules loaded from
            outside the skipped folders (set on leaving).  mapped: files mapped into the process from outside them
            and the system's libraries (``mapped_files``, set on leaving): what native code loaded or mapped.
            unidentified: opens whose path the kernel watch could not read (``open_watch``; a run refuses them).
    """

    _active: ClassVar[list[ReadAudit]] = []  # the audits recording now (the hook is installed once, for good)
    _installed: ClassVar[bool] = False

    def __init__(self, outside: list[str | os.PathLike | None] = ()):
        roots = [*outside, cache_dir()]
        self.skip = tuple(str(Path(root).expanduser().resolve()) for root in roots if root is not None)
        self.files: set[Path] = set()
        self.modules: set[str] = set()
        self.mapped: set[Path] = set()
        self.written: set[Path] = set()
        self.unidentified = 0
        self._watched = 0  # the kernel watch's opens taken so far (its count when the audit began, then on)

    def __enter__(self) -> ReadAudit:
        if not ReadAudit._installed:
            sys.addaudithook(_on_event)
            ReadAudit._installed = True
        if open_watch.start():
            self._watched = open_watch.mark()
        ReadAudit._active.append(self)
        return self

    def __exit__(self, *exc: Any) -> None:
        ReadAudit._active.remove(self)
        self.snapshot()

    def snapshot(self) -> ReadAudit:
        """``modules`` and ``mapped`` set to what is loaded and mapped now, ``files`` grown by what the kernel watch saw
        opened, inside the context (returns the audit)."""
        seen = open_watch.opened_since(self._watched)
        self._watched += len(seen)
        for path, access in seen:
            if path == open_watch.UNREAD:
                self.unidentified += 1
            elif not _under(Path(path), _system_roots()):
                self.opened(path, access)
        self.modules, self.mapped = self.loaded_modules(), self.mapped_files()
        return self

    def mapped_files(self) -> set[Path]:
        """The regular files the process has mapped now (``/proc/self/maps``: shared libraries loaded by native code,
        such as ``ctypes.CDLL``, and memory-mapped data, such as ``torch.load(mmap=True)``), but those of the
        dynamic loader's library folders, the interpreter's own, STCrowd's, the folders ``outside`` and the files the
        audited code wrote; empty where the kernel offers no such list."""
        try:
            lines = Path("/proc/self/maps").read_text().splitlines()
        except OSError:
            return set()
        found = set()
        for line in lines:
            fields = line.split(None, 5)
            if len(fields) == 6 and fields[5].startswith("/"):  # a file replaced since: the one at its path now
                found.add(fields[5].removesuffix(" (deleted)"))
        return {path for path in map(_foreign_mapping, found) if path is not None and not _under(path, self.skip)
                and path not in self.written and path.is_file()}

    def loaded_modules(self) -> set[str]:
        """Names of the modules loaded now from outside the skipped folders."""
        return {name for name, module in list(sys.modules.items()) if _module_file(module) is not None}

    def opened(self, path: Any, mode: Any) -> None:
        """Record ``path`` if it is a regular file outside the skipped folders, opened for reading; a file the audited
        code writes is its output (a cache), never its input, and is dropped."""
        if isinstance(path, int):
            return
        try:
            given = os.path.abspath(os.fsdecode(path))
            resolved = Path(given).expanduser().resolve()
        except (OSError, ValueError, TypeError):
            return
        if given in MACHINE_FILES or str(resolved) in MACHINE_FILES:
            return
        if isinstance(mode, str) and set(mode) & {"w", "a", "x"}:  # "r+" reads what the file held: an input
            self.written.add(resolved)
            self.files.discard(resolved)
            return
        if resolved in self.written or resolved.suffix in (".pyc", ".py") or _own(resolved) or \
                _under(resolved, self.skip):
            return  # modules are hashed as modules
        if resolved.is_file():
            self.files.add(resolved)


def _on_event(event: str, args: tuple) -> None:
    if event == "open" and ReadAudit._active:
        for audit in ReadAudit._active:
            audit.opened(args[0], args[1] if len(args) > 1 else None)


def _under(path: Path, roots: tuple[str, ...]) -> bool:
    text = str(path)
    return any(text == root or text.startswith(root.rstrip(os.sep) + os.sep) for root in roots)


def _own(path: Path) -> bool:
    """Whether ``path`` is one whose files never identify a policy: in STCrowd's packages (``stcrowd_identity``),
    Python's standard library (its version is ``version python``; the installed packages' folders inside it are not
    part of it), the kernel's pseudo-files, or an installed distribution's metadata (``*.dist-info``,
    ``*.egg-info``: what the distribution's version says)."""
    if path.parent.suffix in (".dist-info", ".egg-info"):
        return True
    roots, packages = _own_roots()
    return _under(path, roots) and not _under(path, packages)


@cache
def _own_roots() -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(STCrowd's packages, the interpreter's standard library and the pseudo-files; the folders of installed packages,
    which may lie inside the standard library's)."""
    base = {"base": sys.base_prefix, "platbase": sys.base_exec_prefix, "installed_base": sys.base_prefix,
            "installed_platbase": sys.base_exec_prefix}
    stdlib = {sysconfig.get_paths(vars=base)[key] for key in ("stdlib", "platstdlib")}
    packages = {*site.getsitepackages(), site.getusersitepackages(),
                *(sysconfig.get_paths(vars=base)[key] for key in ("purelib", "platlib"))}
    return (tuple(sorted({str(Path(p).resolve()) for p in (*stdlib, *PSEUDO_ROOTS)} |
                         {str(r) for r in _stcrowd_roots()})),
            tuple(sorted(str(Path(p).resolve()) for p in packages)))


@cache
def _foreign_mapping(name: str) -> Path | None:
    """The resolved path of a file named in the process's memory map, None if it is STCrowd's, the standard
    library's, the system's or the interpreter's own (once per name in a process: every episode reads the map)."""
    path = Path(name).resolve()
    return None if _own(path) or _under(path, _system_roots()) else path


@cache
def _system_roots() -> tuple[str, ...]:
    """The dynamic loader's library folders (writable by the administrator only), the interpreter's executable and
    its ``libpython``: their mapped files are the system's and Python's, not a policy's."""
    library = Path(str(sysconfig.get_config_var("LIBDIR") or "/")) / str(sysconfig.get_config_var("LDLIBRARY") or "")
    interpreter = {str(Path(sys.executable).resolve()), str(library.resolve())}
    loader = {str(Path(p).resolve()) for p in ("/lib", "/lib64", "/usr/lib", "/usr/lib64", "/usr/libexec")}
    return tuple(sorted(loader | interpreter))


@cache
def _recorded_files() -> dict[str, tuple[str, str]]:
    """Every file the installed distributions' ``RECORD`` files list, as an absolute path -> (distribution,
    version); read from the ``*.dist-info`` folders on ``sys.path`` once per process."""
    owners: dict[str, tuple[str, str]] = {}
    for folder in dict.fromkeys(Path(entry or ".").resolve() for entry in sys.path):
        for record in sorted(folder.glob("*.dist-info/RECORD")) if folder.is_dir() else ():
            name, _, version = record.parent.name.removesuffix(".dist-info").rpartition("-")
            try:
                lines = record.read_text(errors="replace").splitlines()
            except OSError:
                continue
            for line in lines:
                listed = line.rpartition(",")[0].rpartition(",")[0]  # path,hash,size: the path may hold commas
                if listed:
                    owners[os.path.normpath(folder / listed)] = (name, version)
    return owners


def _module_file(module: Any) -> Path | None:
    """The file ``module`` was loaded from if it lies outside STCrowd, the standard library and the pseudo-files, else
    None (a builtin, a namespace package, one of STCrowd's)."""
    origin = getattr(module, "__file__", None)
    return _outside_file(origin) if isinstance(origin, str) else None


@cache
def _outside_file(origin: str) -> Path | None:
    path = Path(origin).resolve()
    if _own(path):
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
    """What ``audit`` saw, as named parts: ``module <name>``: the SHA-256 of each module it saw loaded (unless not
    ``modules``) and ``read <path>``: of each file it saw read, or mapped (unless not ``modules``; the path relative
    to the working folder where it lies inside it); a module or file that an installed distribution's ``RECORD``
    lists is ``version <distribution>`` instead (pip checks those files against the record's hashes), and ``version
    python`` is the interpreter's."""
    parts = {"version python": platform.python_version()}
    for name in sorted(audit.modules if modules else ()):
        path = _module_file(sys.modules.get(name))
        if path is not None:
            parts.update(_part(f"module {name}", path))
    cwd = Path.cwd().resolve()
    files = audit.files | (audit.mapped if modules else set())
    for path in sorted(path for path in files if path.is_file()):  # a temporary file may be gone
        shown = path.relative_to(cwd).as_posix() if path.is_relative_to(cwd) else path.as_posix()
        parts.update(_part(f"read {shown}", path))
    return dict(sorted(parts.items()))


def _part(name: str, path: Path) -> dict[str, str]:
    """``{name: SHA-256 of path}``, or ``{"version <distribution>": version}`` if a distribution lists the file."""
    owner = _recorded_files().get(str(path))
    if owner is not None:  # a distribution STCrowd needs is STCrowd's (``stcrowd_identity``), any other the policy's
        return {} if _normalised(owner[0]) in _dependencies() else {f"version {_normalised(owner[0])}": owner[1]}
    return {name: _cached_sha256(path, *_stamp(path))}


def _stamp(path: Path) -> tuple[int, int]:
    stat = path.stat()
    return stat.st_mtime_ns, stat.st_size


@cache
def _cached_sha256(path: Path, mtime_ns: int, size: int) -> str:
    """``file_sha256``, once per file version in a process (a run hashes what it read after every episode)."""
    return file_sha256(path)


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


def current_part(part: str) -> str | None:
    """What an ``audit_parts`` part (``read``, ``module``, ``version``) is on this machine now: the file's or the
    module's SHA-256, the distribution's version; None if it is gone."""
    kind, _, name = part.partition(" ")
    try:
        if kind == "read":
            path = Path(name)
            return file_sha256(path) if path.is_file() else None
        if kind == "module":
            module = sys.modules.get(name)
            origin = getattr(module, "__file__", None) if module is not None else importlib.util.find_spec(name).origin
            return file_sha256(Path(origin)) if origin and Path(origin).is_file() else None
        if kind == "version":
            return platform.python_version() if name == "python" else importlib.metadata.version(name)
    except (ImportError, ValueError, AttributeError, OSError, importlib.metadata.PackageNotFoundError):
        return None
    return None


def not_an_input(part: str) -> bool:
    """Whether ``part`` is a ``read`` of a file runs no longer record: one of ``MACHINE_FILES``, or under this
    machine's ``cache_dir`` (a run of an earlier STCrowd may name them; ``migrate_results --drop-machine-reads``)."""
    kind, _, name = part.partition(" ")
    return kind == "read" and (name in MACHINE_FILES or _under(Path(name), (str(cache_dir().resolve()),)))


def inputs_changes(held: dict[str, str]) -> list[str]:
    """The parts of ``held`` (``audit_parts`` of finished episodes) that are not the same on this machine now, one
    phrase each: changed, or gone."""
    changes = []
    for part, value in sorted(held.items()):
        now = current_part(part)
        if now != value:
            what = "is gone" if now is None else f"{value!r} then, {now!r} now" if part.startswith("version") else \
                "changed"
            changes.append(f"{part} {what}")
    return changes


class ChunkInputs:
    """What the episodes of one chunk of a benchmark run read (``audit_parts``), kept in a JSON file beside their lines
    and grown after every episode, so that a resume or ``verify`` can check every input of every finished episode
    (``inputs_changes``). A part whose value changes while the chunk runs is an error (``InputsError``)."""

    def __init__(self, path: Path):
        self.path = path
        self.parts = read_inputs(path) if path.is_file() else {}

    def keep(self, audit: ReadAudit) -> None:
        """Add what ``audit`` has seen so far (inside its context) and write the file if anything is new."""
        now = audit_parts(audit.snapshot())
        if audit.unidentified:
            raise InputsError(f"{self.path}: a process of the run opened {audit.unidentified} file(s) whose path the "
                              "open watch could not read (a child process it may not inspect): their contents are "
                              "unknown to the run")
        changed = sorted(part for part, value in now.items() if self.parts.get(part, value) != value)
        if changed:
            raise InputsError(f"{self.path}: {', '.join(changed)} changed while the run read it")
        if now.keys() - self.parts.keys():
            self.parts |= now
            write_text_atomic(self.path, strict_json.dumps(self.parts, sort_keys=True, indent=0))


class InputsError(RuntimeError):
    """An input of a run's episodes changed during the run, or since episodes of a folder read it."""


def read_inputs(path: Path) -> dict[str, str]:
    """The parts a ``ChunkInputs`` file holds; ``InputsError`` naming the file if it is not an object of strings."""
    try:
        parts = read_json(path, "inputs record")
    except DataFormatError as err:
        raise InputsError(str(err)) from None
    if not isinstance(parts, dict) or not all(isinstance(value, str) for value in parts.values()):
        raise InputsError(f"{path}: not an object of strings (an inputs record of a benchmark chunk)")
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
