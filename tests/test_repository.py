"""What the repository itself holds: only the files that belong at its root, and no file that names a folder of the
machine that wrote it."""

from __future__ import annotations

import gzip
import json
import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BINARY_SUFFIXES = {".png", ".pt", ".npz", ".rrd", ".zip", ".gz", ".pkl"}
# absolute folders of a build machine: a home, a scratch or work area, a temporary folder (documentation may still
# name example folders such as /data/eth_ucy or /shared/stcrowd/runs)
MACHINE_PATH = re.compile(r"(?<![\w.~-])/(?:work|root|home|tmp|Users|mnt|scratch)/[\w.-]+")


def tracked_files() -> list[Path]:
    """The files git tracks (or, outside a git checkout, every file but the ignored folders)."""
    try:
        names = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
        return [REPO / name for name in names.decode().split("\0") if name]
    except (OSError, subprocess.CalledProcessError):
        skip = {".git", ".venv", "runs", "build", "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis"}
        return [p for p in REPO.rglob("*") if p.is_file() and not skip & set(p.relative_to(REPO).parts)
                and not any(part.endswith(".egg-info") for part in p.relative_to(REPO).parts)]


# what belongs at the root: the packages and their companions, the project files; anything else (a log, a scratch
# script, an output) goes in a folder of its own or in runs/ (git-ignored)
ROOT_ALLOWED = {
    ".ci", ".gitignore", "CITATION.cff", "LICENSE", "Makefile", "README.md", "RESULTS.md", "mkdocs.yml",
    "pyproject.toml", "benchmarks", "docs", "envs", "examples", "predictor", "replays", "results", "st_sim", "tests",
}


def test_the_root_holds_only_what_belongs_there() -> None:
    stray = sorted({p.relative_to(REPO).parts[0] for p in tracked_files()} - ROOT_ALLOWED)
    assert not stray, (f"stray entries at the repository root: {stray}; move them into a folder (runs/ for outputs, "
                       "benchmarks/ for scripts) or, if they belong, add them to ROOT_ALLOWED in this test")


def test_the_readme_stays_a_five_minute_read() -> None:
    """What a stranger needs first (the commands CI and the Makefile keep true) in under 200 lines; the rest is
    in docs/."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) < 200, f"README.md has {len(readme.splitlines())} lines; move detail to docs/"
    for command in ("make demo", "make test", "OMP_NUM_THREADS=1 python -m pytest", "python -m st_sim demo"):
        assert command in readme, f"README.md no longer shows `{command}`"
    for page in ("docs/getting-started.md", "docs/environments.md", "docs/navigation.md", "docs/contributing.md"):
        assert f"]({page}" in readme and (REPO / page).is_file(), f"README.md does not link {page}"


def test_the_file_list_is_the_repository() -> None:
    files = {p.relative_to(REPO).as_posix() for p in tracked_files()}
    assert {"README.md", "RESULTS.md", "pyproject.toml", ".ci/run"} <= files


def test_no_tracked_text_file_names_an_absolute_folder_of_a_build_machine() -> None:
    own = {str(REPO), str(REPO.parent), str(Path.home())}
    found = []
    for path in tracked_files():
        if path.suffix in BINARY_SUFFIXES or not path.is_file():
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            hits = MACHINE_PATH.findall(line) + [folder for folder in own if len(folder) > 1 and folder + "/" in line]
            found += [f"{path.relative_to(REPO)}:{number}: {hit}" for hit in hits]
    assert not found, ("files name folders of the machine that wrote them (use paths relative to the repository "
                       "or a run folder):\n" + "\n".join(found[:20]))


def _refuse_constant(token: str) -> None:
    raise ValueError(f"{token} is not JSON (write null)")


def test_every_tracked_json_file_is_strict_json() -> None:
    """Committed figures are read by strict parsers (a browser's, jq's): no NaN or Infinity, in plain or gzipped
    JSON (``replays.strict_json`` writes null for them)."""
    loose = []
    for path in tracked_files():
        if not path.name.endswith((".json", ".json.gz")) or not path.is_file():
            continue
        raw = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
        try:
            json.loads(raw, parse_constant=_refuse_constant)
        except ValueError as err:
            loose.append(f"{path.relative_to(REPO)}: {err}")
    assert not loose, "tracked JSON files that are not strict JSON:\n" + "\n".join(loose)
