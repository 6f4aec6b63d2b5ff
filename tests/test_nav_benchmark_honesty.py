"""Benchmark numbers that cannot mislead: a run knows what it scored (a changed model or changed code behind the same
spec is refused), partial runs are labelled and pooled only over shared scenarios, intervals stay inside their
metric's range, every JSON written is strict, and paired comparisons and outcome tables come with the leaderboard."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from st_sim.apps.cli import main
from st_sim.apps.navigation.benchmark import BenchmarkRun, run_benchmark
from st_sim.apps.navigation.leaderboard import LeaderboardError, comparable, load_result, markdown
from st_sim.apps.navigation.metrics import (
    EpisodeTrace,
    Outcome,
    episode_metrics,
    mean_interval,
    rate_interval,
    summarize,
)
from st_sim.apps.navigation.paired import paired_text

REPO = Path(__file__).resolve().parents[1]
STRAIGHT = ("straight", "none")


def strict_loads(text: str) -> object:
    """``json.loads`` that refuses NaN and Infinity, as strict parsers do."""
    def refuse(constant: str) -> None:
        raise ValueError(f"not strict JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


def bench(out: Path, policy: str = "straight", scenarios: tuple[str, ...] = ("frontal-approach",),
          episodes: int = 2) -> dict:
    return run_benchmark(BenchmarkRun(policy, str(out), predictor="none", split="val", episodes=episodes,
                                      scenarios=scenarios), workers=1, progress=False)


def write_policy_package(root: Path, body: str) -> None:
    """A user's package ``mypolicy`` under ``root`` whose ``policy.Policy`` heads for the goal; ``body`` is added to
    the class."""
    package = root / "mypolicy"
    package.mkdir(exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "policy.py").write_text(
        "import os\nimport numpy as np\n\n\nclass Policy:\n"
        "    def act(self, obs):\n        ego = obs['ego']\n        way = ego[4:6] - ego[:2]\n"
        "        return way / max(float(np.hypot(*way)), 1.0)\n" + body)


def test_a_changed_model_or_changed_code_behind_the_same_spec_is_refused_naming_what_changed(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    write_policy_package(tmp_path, "\n    def fingerprint(self):\n        return os.environ['MODEL_TAG']\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("MODEL_TAG", "model a")
    args = ["benchmark", "--policy", "mypolicy.policy:Policy", "--predictor", "none", "--suite", "val", "--episodes",
            "1", "--scenarios", "frontal-approach", "--workers", "1", "--quiet", "--out", str(tmp_path / "run")]
    assert main(args) == 0
    held = strict_loads((tmp_path / "run" / "run.json").read_text())["fingerprint"]
    assert held["declared"] == "model a" and "source policy.py" in held
    assert load_result(tmp_path / "run")["fingerprint"] == held, "summary.json records it too"
    assert main(args) == 0, "the same policy resumes (nothing to do)"
    monkeypatch.setenv("MODEL_TAG", "model b")
    assert main(args) == 1
    assert "declared 'model a' then, 'model b' now" in capsys.readouterr().err
    monkeypatch.setenv("MODEL_TAG", "model a")
    with (tmp_path / "mypolicy" / "policy.py").open("a") as source:
        source.write("# tuned\n")
    assert main(args) == 1
    assert "source policy.py changed" in capsys.readouterr().err


def test_a_retrained_sb3_zip_at_the_same_path_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO

    env = gym.wrappers.FilterObservation(gym.make("STCrowd-SimFrontalApproach-v1", predictor="none"),
                                         ["ego", "history", "history_mask"])
    model = tmp_path / "model.zip"
    args = ["benchmark", "--policy", f"sb3:{model}", "--predictor", "none", "--suite", "val", "--episodes", "1",
            "--scenarios", "frontal-approach", "--workers", "1", "--quiet", "--out", str(tmp_path / "run")]
    PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, seed=0, device="cpu").save(model)
    assert main(args) == 0
    PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, seed=1, device="cpu").save(model)
    assert main(args) == 1
    assert "file model.zip changed" in capsys.readouterr().err


def test_partial_runs_are_labelled_and_pooled_only_over_the_scenarios_every_run_shares(tmp_path: Path) -> None:
    bench(tmp_path / "one")
    bench(tmp_path / "two", scenarios=("frontal-approach", "overtaking"))
    one, two = load_result(tmp_path / "one"), load_result(tmp_path / "two")
    assert one["scenario_set"] == ["frontal-approach"] and two["suite_scenarios"] == 18
    assert "2 scenarios every result holds, of the suite's 18 (frontal-approach, overtaking)" in markdown([two])
    with pytest.raises(LeaderboardError, match="--common-scenarios"):
        comparable([one, two])
    pooled = comparable([one, {**two, "policy": "other"}], common_scenarios=True)
    assert all(result["scenario_set"] == ["frontal-approach"] for result in pooled)
    assert pooled[1]["summary"]["success"] == one["summary"]["success"], "pooled again over the shared scenario"
    assert "1 scenarios every result holds" in markdown(pooled)


def test_the_leaderboard_gives_outcomes_per_scenario_and_pairs_two_runs(tmp_path: Path) -> None:
    bench(tmp_path / "a", scenarios=("frontal-approach", "overtaking"), episodes=3)
    table = markdown([load_result(tmp_path / "a")])
    outcomes = table.split("### Outcomes per scenario")[1].split("###")[0]
    row = next(line for line in outcomes.splitlines() if line.startswith("| straight + none |"))
    for cell in row.strip("|").split("|")[1:]:
        assert math.isclose(sum(float(share) for share in cell.split("/")), 1.0, abs_tol=0.02), cell
    text = paired_text(tmp_path / "a", tmp_path / "a")
    assert "6 paired episodes" in text and "only the first 0, only the second 0" in text
    with pytest.raises(LeaderboardError, match="no scenario matches"):
        paired_text(tmp_path / "a", tmp_path / "a", ("sim-*",))


def test_a_run_records_its_wall_time_apart_from_the_workers_summed_time(tmp_path: Path) -> None:
    timing = bench(tmp_path / "run")["timing"]
    assert set(timing) == {"wall_s", "worker_s", "policy_s", "steps"}
    assert 0 < timing["worker_s"] <= timing["wall_s"], "one worker: its time is inside the run's"


SKEWED = st.lists(st.one_of(st.just(0.0), st.floats(0.0, 1e3, allow_nan=False)), min_size=1, max_size=60)


@settings(max_examples=200, deadline=None)
@given(values=SKEWED, extra=st.lists(st.just(float("nan")), max_size=3))
@example(values=[205.02382997084612] * 5, extra=[])  # equal values whose float mean is one ulp above them
def test_a_mean_interval_holds_its_value_and_stays_inside_the_values_range(values: list[float],
                                                                           extra: list[float]) -> None:
    mean, low, high = mean_interval(np.array(values + extra))
    assert low <= mean <= high
    assert min(values) <= low and high <= max(values), "a time or count interval never goes below 0"
    assert mean_interval(np.array(values + extra)) == (mean, low, high), "seeded: the same values, the same interval"


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 2000), share=st.floats(0, 1))
def test_a_rate_interval_holds_its_value_inside_zero_and_one(n: int, share: float) -> None:
    hits = round(share * n)
    low, high = rate_interval(hits, n)
    assert 0.0 <= low <= hits / n <= high <= 1.0


def test_every_committed_summary_interval_stays_in_its_metrics_range() -> None:
    bounded_below = re.compile(r"_s$|_m$|_entries_|intrusions|share|ratio|^off_map$|^discomfort$|^spl$|^steps$")
    for folder in sorted((REPO / "results" / "benchmark").iterdir()):
        if not folder.is_dir():
            continue
        result = load_result(folder)
        for cell_owner in [result, *result["scenarios"]]:
            for name, cell in cell_owner["summary"].items():
                if cell["value"] is None:
                    continue
                assert cell["low"] <= cell["value"] <= cell["high"], (folder.name, name)
                if bounded_below.search(name) and name != "min_step_end_gap_m":
                    assert cell["low"] >= 0, (folder.name, name, cell)


def test_a_straight_drive_into_the_goals_edge_has_path_ratio_one() -> None:
    xy = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0], [4.5, 0.0]])
    trace = EpisodeTrace(ego_xy_m=xy, ego_velocity_mps=np.zeros((4, 2)), clearance_m=np.full(4, np.inf),
                         off_map=np.zeros(4, bool), goal_m=np.array([5.0, 0.0]), outcome=Outcome.GOAL,
                         goal_radius_m=0.5)
    assert episode_metrics(trace)["path_ratio"] == pytest.approx(1.0)


def test_navigate_json_is_strict_json_with_null_for_missing_figures(tmp_path: Path) -> None:
    out = tmp_path / "nav.json"
    assert main(["navigate", "--env", "STCrowd-SimFrontalApproach-v1", "--policy", "straight", "--predictor", "none",
                 "--episodes", "2", "--quiet", "--json", str(out)]) == 0
    result = strict_loads(out.read_text())
    assert any(value is None for episode in result["episodes"] for value in episode.values()), \
        "a figure that does not exist is written as null"
    assert summarize(result["episodes"])["collision"]["n"] == 2


def test_nothing_in_the_project_writes_json_without_the_strict_writer() -> None:
    loose = []
    for folder in ("st_sim", "envs", "predictor", "replays", "benchmarks", "examples"):
        for path in sorted((REPO / folder).rglob("*.py")):
            if path.name != "strict_json.py" and re.search(r"(?<!\w)json\.dumps?\(", path.read_text()):
                loose.append(str(path.relative_to(REPO)))
    assert not loose, f"write JSON with replays.strict_json.dumps (null for NaN): {loose}"

