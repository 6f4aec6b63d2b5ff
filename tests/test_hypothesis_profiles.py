"""The hypothesis profiles of tests/conftest.py: "ci" draws the same examples on every run, "fuzz" draws fresh ones,
FUZZ_FACTOR times as many, and runs only the property tests."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

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


def run_profile(tmp_path: Path, profile: str, run: int) -> tuple[list[int], str]:
    """Run the property test above under ``profile`` in a fresh pytest; returns (its draws, pytest's output)."""
    test_file = tmp_path / "test_profile_probe.py"
    test_file.write_text(PROPERTY_TEST)
    draws = tmp_path / f"{profile}-{run}.jsonl"
    env = {**os.environ, "HYPOTHESIS_PROFILE": profile, "HYPOTHESIS_FUZZ_FACTOR": "3", "DRAWS": str(draws),
           "PYTHONPATH": os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-p", "conftest", "-q", "-p", "no:cacheprovider",
                           "--rootdir", str(tmp_path), str(test_file)], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return [json.loads(line) for line in draws.read_text().splitlines()], proc.stdout


def test_ci_profile_draws_the_same_examples_on_every_run(tmp_path: Path) -> None:
    (first, output), (second, _) = run_profile(tmp_path, "ci", 1), run_profile(tmp_path, "ci", 2)
    assert first == second and len(set(first)) >= 5, (first, second)
    assert "2 passed" in output, output


def test_fuzz_profile_draws_fresh_examples_factor_times_as_many(tmp_path: Path) -> None:
    (first, output), (second, _) = run_profile(tmp_path, "fuzz", 1), run_profile(tmp_path, "fuzz", 2)
    assert len(first) >= 3 * 7 and len(second) >= 3 * 7, "each test draws FUZZ_FACTOR times its max_examples"
    assert set(first) != set(second), "two fuzz runs drew the same examples"
    assert "1 passed, 1 deselected" in output, "only the property tests run under fuzz"
