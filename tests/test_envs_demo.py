"""The demo: the best planner (MPC + SingularTrajectory) crosses the simulated crowd; outcomes named, recorded."""

from __future__ import annotations

from pathlib import Path

import pytest

from st_sim.apps.demo import OUTCOMES, run_demo


def test_demo_runs_whole_episodes_names_outcomes_and_records(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "demo.rrd"
    result = run_demo(steps=10, rerun_path=str(path), seed=1)
    assert path.is_file() and path.stat().st_size > 0
    assert result["steps"] >= 10 and sum(e["steps"] for e in result["episodes"]) == result["steps"]
    assert all(e["outcome"] in OUTCOMES for e in result["episodes"]), "every episode ends with a named outcome"
    assert sum(result["counts"].values()) == len(result["episodes"])
    assert {"ade_m", "min_step_end_gap_m", "jerk_mps3", "outcome"} <= set(result["episodes"][0])
    out = capsys.readouterr().out
    assert "episode 0 (seed 1):" in out and "goal" in out
    again = run_demo(steps=10, rerun_path=None, seed=1)
    assert repr(again["episodes"]) == repr(result["episodes"]), "the same seed must give the same episodes"  # NaN-safe
