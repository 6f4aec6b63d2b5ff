"""The hypothesis profiles of tests/conftest.py: "ci" draws the same examples on every run, "fuzz" draws fresh ones,
FUZZ_FACTOR times as many, and runs only the property tests."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

PROPERTY_TEST = '''
import json, os
from hypothesis import given, settings, strategies as st

@settings(max_examples=7, deadline=None)
@given(st.integers(0, 10**9))
def test_draws(value):
    with open(os.environ["DRAWS"], "a") as out:
        out.write(json.dumps(value) + "\\n")

def test_plain():
    pass
'''


def run_probe(tmp_path: Path, source: str, profile: str, run: int | str, factor: int, returncode: int,
              on_ci: bool = False) -> tuple[list[int], str]:
    """Run the test file ``source`` under ``profile`` (``factor``: the fuzz factor) in a fresh pytest in
    ``tmp_path``, which must exit with ``returncode``, with $CI set (as CI services set it, and Hypothesis reads it)
    if ``on_ci``; returns (the draws it wrote, pytest's output)."""
    test_file = tmp_path / ("test_failing_probe.py" if returncode else "test_profile_probe.py")
    test_file.write_text(source)
    draws = tmp_path / f"{profile}-{run}.jsonl"
    env = {**os.environ, "HYPOTHESIS_PROFILE": profile, "HYPOTHESIS_FUZZ_FACTOR": str(factor), "DRAWS": str(draws),
           "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])}
    env.pop("HYPOTHESIS_STORAGE_DIRECTORY", None)
    env.pop("CI", None)
    env.update({"CI": "true"} if on_ci else {})
    proc = subprocess.run([sys.executable, "-m", "pytest", "-p", "conftest", "-q", "-p", "no:cacheprovider",
                           "--rootdir", str(tmp_path), str(test_file)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == returncode, proc.stdout[-2000:] + proc.stderr[-2000:]
    return [json.loads(line) for line in draws.read_text().splitlines()], proc.stdout


def run_profile(tmp_path: Path, profile: str, run: int) -> tuple[list[int], str]:
    """The passing property test above under ``profile``: (its draws, pytest's output)."""
    return run_probe(tmp_path, PROPERTY_TEST, profile, run, factor=3, returncode=0)


def test_ci_profile_draws_the_same_examples_on_every_run(tmp_path: Path) -> None:
    (first, output), (second, _) = run_profile(tmp_path, "ci", 1), run_profile(tmp_path, "ci", 2)
    assert first == second and len(set(first)) >= 5, (first, second)
    assert "2 passed" in output, output


def test_fuzz_profile_draws_fresh_examples_factor_times_as_many(tmp_path: Path) -> None:
    (first, output), (second, _) = run_profile(tmp_path, "fuzz", 1), run_profile(tmp_path, "fuzz", 2)
    assert len(first) >= 3 * 7 and len(second) >= 3 * 7, "each test draws FUZZ_FACTOR times its max_examples"
    assert set(first) != set(second), "two fuzz runs drew the same examples"
    assert "1 passed, 1 deselected" in output, "only the property tests run under fuzz"


FAILING_TEST = '''
import json, os
from hypothesis import example, given, settings, strategies as st

@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10**9))
@example(-1)
def test_draws(value):
    with open(os.environ["DRAWS"], "a") as out:
        out.write(json.dumps(value) + "\\n")
    assert value < 10**8
'''


def run_failing(tmp_path: Path, profile: str, run: int, on_ci: bool) -> tuple[list[int], str]:
    """The failing property test above under ``profile``, in ``tmp_path``: (its draws, pytest's output)."""
    return run_probe(tmp_path, FAILING_TEST, profile, f"failing-{run}", factor=2, returncode=1, on_ci=on_ci)


@pytest.mark.parametrize("on_ci", [False, True], ids=["no-CI-variable", "CI-variable"])
@pytest.mark.parametrize("profile", ["ci", "fuzz"])
def test_pinned_examples_run_first_and_only_fuzz_keeps_its_failures_for_the_next_run(tmp_path: Path, profile: str,
                                                                                      on_ci: bool) -> None:
    """docs/contributing.md, "Property tests": every profile runs the ``@example`` pins first and prints a failure's
    ``@reproduce_failure`` blob; ``ci`` keeps no example database, ``fuzz`` saves its failures in ``.hypothesis/`` and
    tries them first on the next run; the same with $CI set (Hypothesis then loads a profile of its own)."""
    first, output = run_failing(tmp_path, profile, 1, on_ci)
    assert first[0] == -1, f"{profile}: the pinned example did not run first: {first[:3]}"
    page = (TESTS.parent / "docs/contributing.md").read_text(encoding="utf-8")
    shown = re.search(r"```text\n([^:\n]+):", page).group(1)  # how the page says hypothesis reports a failure
    assert f"{shown}: test_draws(" in output and "value=100000000" in output, output[-2000:]
    assert "@reproduce_failure(" in output, output[-2000:]
    database = tmp_path / ".hypothesis" / "examples"
    if profile == "ci":
        assert not database.exists() or not any(database.rglob("*")), "the ci profile wrote an example database"
        return
    assert any(p.is_file() for p in database.rglob("*")), "the fuzz profile kept no failure"
    second, _ = run_failing(tmp_path, profile, 2, on_ci)
    assert second[0] == -1 and second[1] >= 10**8, f"the kept failure was not tried first: {second[:3]}"
