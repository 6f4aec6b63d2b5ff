"""What the repository itself holds: no file names a folder of the machine that wrote it."""

from __future__ import annotations

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
                and not p.name.endswith(".egg-info")]


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
