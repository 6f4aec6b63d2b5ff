"""What README.md, docs/ and benchmarks/README.md promise about the repository itself: the layers of the packages,
what CI runs, the documentation build, the data the repository never holds, the Makefile's set-up, the benchmark
scripts' index, and a missing data root failing the suite. The promises about the envs, the simulator and the tools
are checked beside their code, in the test file of each."""

from __future__ import annotations

import ast
import hashlib
import importlib.util
import json
import logging
import os
import re
import subprocess
import sys
import zlib
from pathlib import Path
from types import SimpleNamespace

import pytest
from test_repository import REPO, tracked_files

# contributing.md, "Layout": each package imports only those above it in this order (st_sim's core is st_sim but
# its apps); benchmarks/ and examples/ use them all
LAYERS = ("replays", "st_sim", "predictor", "envs", "st_sim.apps")
ENTRY_POINT = "st_sim/__main__.py"  # hands `python -m st_sim` over to st_sim.apps.cli (STYLE.md, 16)


def layer_of(module: str) -> int | None:
    """Index in ``LAYERS`` of a dotted module name, or None for a module outside the four packages."""
    if module == "st_sim.apps" or module.startswith("st_sim.apps."):
        return LAYERS.index("st_sim.apps")
    top = module.split(".")[0]
    return LAYERS.index(top) if top in LAYERS else None


def imported_modules(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every absolute import in a file, those inside functions included."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
    return found


def test_each_package_imports_only_the_layers_above_it() -> None:
    """docs/contributing.md, "Layout"; and docs/data.md: nothing in the envs depends on the CITR reader."""
    upward, citr = [], []
    for package in ("replays", "st_sim", "predictor", "envs"):
        for path in sorted((REPO / package).rglob("*.py")):
            where = path.relative_to(REPO).as_posix()
            own = layer_of(".".join(path.relative_to(REPO).with_suffix("").parts))
            for line, module in imported_modules(path):
                other = layer_of(module)
                if other is not None and other > own and where != ENTRY_POINT:
                    upward.append(f"{where}:{line} imports {module} ({LAYERS[own]} may not import {LAYERS[other]})")
                if package == "envs" and module.startswith("replays.citr"):
                    citr.append(f"{where}:{line}")
    assert not upward, "imports against the layering of docs/contributing.md:\n" + "\n".join(upward)
    assert not citr, f"the envs import the CITR reader: {citr}"


def test_ci_lints_builds_the_strict_site_then_runs_the_suite_and_the_perturbed_suite() -> None:
    """README.md and docs/getting-started.md, "Tests"; docs/contributing.md, "Tests and CI"."""
    script = (REPO / ".ci/run").read_text(encoding="utf-8")
    steps = [line.strip() for line in script.splitlines() if line.strip() and not line.strip().startswith("#")]
    ordered = ['pip install --quiet -e ".[dev]"', "ruff check .", "mkdocs build --strict",
               "OMP_NUM_THREADS=1 python -m pytest", "OMP_NUM_THREADS=1 python -m pytest --perturb"]
    at = [next((i for i, step in enumerate(steps) if step == want or (want.startswith("mkdocs") and want in step)),
               None) for want in ordered]
    assert None not in at, dict(zip(ordered, at, strict=True))
    assert at == sorted(at), f"CI runs its steps in another order: {dict(zip(ordered, at, strict=True))}"
    assert "STCROWD_DATA" in script and "STCROWD_CITR" in script, "CI points the suite at its own copies of the data"
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "OMP_NUM_THREADS=1 python -m pytest\n" in readme and "OMP_NUM_THREADS=1 python -m pytest --perturb" in readme
    config = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    assert re.search(r"^strict: true$", config, re.M), "mkdocs.yml: every warning must fail the build"
    assert "docs/hooks/api_coverage.py" in config, "mkdocs.yml: the API coverage hook must run"


def load_hook() -> object:
    spec = importlib.util.spec_from_file_location("api_coverage", REPO / "docs/hooks/api_coverage.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def write_inventory(path: Path, names: list[str]) -> None:
    """A Sphinx-format inventory as mkdocstrings writes it: four header lines, then zlib-compressed entries."""
    body = "".join(f"{name} py:function 1 api/#{name} -\n" for name in names)
    header = b"# Sphinx inventory version 2\n# Project: STCrowd\n# Version: 0.0.0\n# compressed with zlib\n"
    path.write_bytes(header + zlib.compress(body.encode()))


def test_the_site_build_fails_when_a_public_name_is_missing_from_the_api_reference(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """README.md, "Documentation" (the build fails if one is missing); docs/contributing.md: every public module,
    class and function is on the API pages. The hook warns under "mkdocs", which --strict turns into a failure."""
    hook = load_hook()
    names = hook.public_names(REPO)
    assert "envs.view.wall_readings_m" in names and not any(n.split(".")[-1].startswith("_") for n in names)
    config = SimpleNamespace(site_dir=str(tmp_path), config_file_path=str(REPO / "mkdocs.yml"))
    write_inventory(tmp_path / "objects.inv", names)
    with caplog.at_level(logging.WARNING, logger=hook.log.name):
        hook.on_post_build(config)
    assert not caplog.records, "every public name is in the inventory"
    write_inventory(tmp_path / "objects.inv", [name for name in names if name != "envs.view.wall_readings_m"])
    with caplog.at_level(logging.WARNING, logger=hook.log.name):
        hook.on_post_build(config)
    assert hook.log.name.startswith("mkdocs.")
    assert [r.levelno for r in caplog.records] == [logging.WARNING]
    assert "envs.view.wall_readings_m" in caplog.records[0].getMessage()


READ_STATICALLY = """
import json, sys
import griffe
for package in ("envs", "predictor", "replays", "st_sim"):
    griffe.load(package, search_paths=[sys.argv[1]])
watched = {"envs", "predictor", "replays", "st_sim", "torch", "numpy", "gymnasium", "pymunk", "cv2"}
print(json.dumps(sorted(name for name in sys.modules if name.split(".")[0] in watched)))
"""


def test_the_api_reference_reads_the_packages_without_importing_them() -> None:
    """docs/contributing.md: mkdocstrings reads the docstrings statically (its loader, griffe, with the site's
    search path), so building the site imports none of the packages, torch or the data."""
    done = subprocess.run([sys.executable, "-c", READ_STATICALLY, str(REPO)], cwd=REPO, capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": ""})
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout) == [], f"reading the API imported {done.stdout.strip()}"


def test_no_data_file_of_eth_ucy_or_citr_is_in_the_repository() -> None:
    """docs/data.md: the ETH/UCY files are never part of the repository; STCrowd neither ships nor relicenses them
    (nor CITR). A tracked file of a data file's size is hashed: none may be one of them, under any name."""
    sums: dict[str, str] = {}
    for listing in ("replays/eth_ucy.sha256", "replays/citr.sha256"):
        for line in (REPO / listing).read_text(encoding="utf-8").splitlines():
            if line.strip():
                digest, name = line.split(maxsplit=1)
                sums[digest] = name
    shipped = []
    for path in tracked_files():
        if path.is_file() and path.stat().st_size < 4 << 20:  # every data file is under 1 MB
            digest = hashlib.sha256(path.read_bytes()).hexdigest()
            if digest in sums:
                shipped.append(f"{path.relative_to(REPO)} is {sums[digest]}")
    assert not shipped, shipped


def test_every_benchmark_script_has_main_and_a_line_in_the_index() -> None:
    """benchmarks/README.md: every script has ``main()`` and runs as a script, takes its flags through argparse
    (``--help``) unless the page names it as one without flags, and has one line in the index."""
    index = (REPO / "benchmarks/README.md").read_text(encoding="utf-8")
    named = re.search(r"\(([^()]*?) take none", index)
    without_flags = set(re.findall(r"`([\w.]+\.py)`", named.group(1))) if named else set()
    missing_main, unlisted, no_help = [], [], []
    for path in sorted((REPO / "benchmarks").glob("*.py")):
        source = path.read_text(encoding="utf-8")
        if '__name__ == "__main__"' not in source:
            continue  # a module the scripts or the benchmark import (study_models.py, hl_from_docs.py)
        tree = ast.parse(source, str(path))
        if not any(isinstance(node, ast.FunctionDef) and node.name == "main" for node in tree.body):
            missing_main.append(path.name)
        if f"| `{path.name}` |" not in index:
            unlisted.append(path.name)
        if "argparse" not in source and path.name not in without_flags:
            no_help.append(path.name)
    assert not missing_main, f"scripts without main(): {missing_main}"
    assert not no_help, f"scripts without --help that the page does not name as taking no flags: {no_help}"
    assert not unlisted, f"scripts without a line in benchmarks/README.md: {unlisted}"


def test_the_pin_shown_in_contributing_is_on_its_test() -> None:
    """docs/contributing.md, "Property tests": tests/test_sim_contacts.py holds the pin the page shows."""
    page = (REPO / "docs/contributing.md").read_text(encoding="utf-8")
    block = re.search(r"holds one such pin:\n\n```python\n(.*?)```", page, re.S)
    assert block, "docs/contributing.md no longer shows the pin"
    shown = block.group(1)
    source = (REPO / "tests/test_sim_contacts.py").read_text(encoding="utf-8")
    assert shown in source, f"tests/test_sim_contacts.py does not hold the lines the page shows:\n{shown}"
    assert "@example(" in shown


def make_dry_run(target: str, venv: Path) -> str:
    done = subprocess.run(["make", "-n", "-C", str(REPO), target, f"VENV={venv}", f"PYTHON={sys.executable}"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_make_sets_up_only_what_is_missing(tmp_path: Path) -> None:
    """README.md and docs/getting-started.md: `make demo` and `make test` skip what is already there, so running
    them again only runs the demo or the tests (the data fetch skips checked files: tests/test_fetch.py)."""
    venv = tmp_path / "venv"
    fresh = make_dry_run("demo", venv)
    assert "-m venv" in fresh and "pip install" in fresh and "-m st_sim demo" in fresh, fresh
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").symlink_to(sys.executable)
    (venv / ".installed").touch()
    later = (REPO / "pyproject.toml").stat().st_mtime + 10
    os.utime(venv / ".installed", (later, later))
    for target, runs in (("demo", "-m st_sim demo"), ("test", "-m pytest")):
        again = make_dry_run(target, venv)
        assert "-m venv" not in again and "pip install" not in again, f"make {target} sets up again:\n{again}"
        assert runs in again, again


@pytest.mark.parametrize(("variable", "test"), [
    ("STCROWD_DATA", "tests/test_windows.py::test_test_split_counts_match_social_gan_loader"),
    ("STCROWD_CITR", "tests/test_citr.py::test_citr_reads_every_experiment_with_a_vehicle")],
    ids=["eth_ucy", "citr"])
def test_a_missing_data_root_fails_the_suite_and_skips_nothing(tmp_path: Path, variable: str, test: str) -> None:
    """README.md and docs/getting-started.md: the suite needs both data roots, and a missing root is a failure,
    not a skip."""
    env = {**os.environ, variable: str(tmp_path / "no-data-here"), "STCROWD_CACHE": str(tmp_path / "cache"),
           "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-m", "pytest", "-o", "addopts=", "-q", "-p", "no:cacheprovider", test],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    summary = done.stdout.strip().splitlines()[-1] if done.stdout.strip() else ""
    assert done.returncode != 0, f"the suite passed without {variable}:\n{done.stdout[-2000:]}"
    assert "skipped" not in summary and ("failed" in summary or "error" in summary), summary
    assert "no-data-here" in done.stdout, "the failure names the missing folder"
