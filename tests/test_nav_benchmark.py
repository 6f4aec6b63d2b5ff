"""The benchmark suite and runner: the suite file's seeds, a policy from outside the project through every scenario
with the figures of a plain gym loop, errors that name the policy, scenario, episode and seed, resuming after a
kill, and the leaderboard."""

from __future__ import annotations

import copy
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.suite import LISTED_SPLITS, SuiteError, env_kwargs_of, load_suite
from st_sim.apps.cli import main
from st_sim.apps.navigation.benchmark import BenchmarkRun, episode_record, run_benchmark
from st_sim.apps.navigation.episodes import TraceRecorder
from st_sim.apps.navigation.leaderboard import LeaderboardError, load_result, markdown
from st_sim.apps.navigation.metrics import METRICS, episode_metrics, outcome_of
from st_sim.apps.navigation.policies import PolicyError, load_policy
from st_sim.apps.navigation.world import world_of

REPO = Path(__file__).resolve().parents[1]
KEEP_CLEAR = "examples.my_policy.keep_clear:KeepClear"
SUITE = load_suite()


def run_cli(*args: str, **popen) -> subprocess.CompletedProcess:
    """``python -m st_sim ARGS`` from the repository root, as a user runs it."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "st_sim", *args], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=900, **popen)


def test_the_shipped_suite_has_disjoint_seed_lists_and_every_scenario_makes() -> None:
    val, test = (set(SUITE.seeds[split]) for split in LISTED_SPLITS)
    assert not val & test, "tuning seeds must never be test seeds"
    assert len(val) == len(SUITE.seeds["val"]) and len(test) == len(SUITE.seeds["test"]), "no repeats"
    assert min(len(val), len(test)) >= SUITE.episodes
    names = [scenario.name for scenario in SUITE.scenarios]
    assert len(set(names)) == len(names) and {"univ-reactive", "sim-crossing", "frontal-approach"} <= set(names)
    for scenario in SUITE.scenarios:
        env = gym.make(scenario.env, **env_kwargs_of(scenario, "none"))
        assert env.reset(seed=SUITE.seeds["val"][0])[0]["ego"].shape == (9,), scenario.name
        env.close()


CORRUPTIONS = {
    "format": lambda s: s.update(format="other/1"),
    "version": lambda s: s.update(version=3),
    "episodes": lambda s: s.update(episodes=0),
    "shared seed": lambda s: s["seeds"]["val"].append(s["seeds"]["test"][0]),
    "repeated seed": lambda s: s["seeds"]["test"].append(s["seeds"]["test"][0]),
    "negative seed": lambda s: s["seeds"]["val"].append(-1),
    "bool seed": lambda s: s["seeds"]["val"].append(True),
    "fourth split": lambda s: s["seeds"].update(holdout=[1]),
    "train as a list": lambda s: s["seeds"].update(train=[1]),
    "no test list": lambda s: s["seeds"].pop("test"),
    "unknown env": lambda s: s["scenarios"][0].update(env="STCrowd-Nowhere-v9"),
    "twin name": lambda s: s["scenarios"].append(dict(s["scenarios"][0])),
    "predictor kwarg": lambda s: s["scenarios"][1].update(env_kwargs={"predictor": "cvm"}),
    "kwargs list": lambda s: s["scenarios"][1].update(env_kwargs=[1]),
    "no scenarios": lambda s: s.update(scenarios=[]),
}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(names=st.lists(st.sampled_from(sorted(CORRUPTIONS)), min_size=1, max_size=3, unique=True))
def test_a_corrupt_suite_file_is_refused_naming_the_file(tmp_path: Path, names: list[str]) -> None:
    raw = json.loads(SUITE.path.read_text())
    for name in names:
        corrupted = copy.deepcopy(raw)
        CORRUPTIONS[name](corrupted)
        path = tmp_path / "suite.json"
        path.write_text(json.dumps(corrupted))
        with pytest.raises(SuiteError, match=r"suite\.json"):
            load_suite(path)


def test_unknown_scenarios_splits_and_too_many_episodes_are_refused() -> None:
    with pytest.raises(SuiteError, match="no scenario 'nowhere'"):
        SUITE.select(["sim-crossing", "nowhere"])
    with pytest.raises(SuiteError, match="no split 'training'"):
        SUITE.seeds_of("training")
    with pytest.raises(SuiteError, match="ask 1 to"):
        SUITE.seeds_of("test", len(SUITE.seeds["test"]) + 1)


def plain_loop(scenario_name: str, predictor: str, seeds: list[int], policy_spec: str) -> list[dict]:
    """The records of a plain ``gym.make`` loop over the scenario's env, keywords and seeds, as a user writes it."""
    (scenario,) = SUITE.select([scenario_name])
    env = gym.make(scenario.env, **env_kwargs_of(scenario, predictor))
    world = world_of(env)
    policy = load_policy(policy_spec, world, predictor)
    records = []
    for i, seed in enumerate(seeds):
        obs, info = env.reset(seed=seed)
        policy.reset()
        recorder = TraceRecorder(world)
        recorder.start(obs, info)
        path_m, least_m, steps, done = 0.0, np.inf, 0, False
        while not done:
            before = obs["ego"][:2].astype(np.float64)
            obs, _, terminated, truncated, info = env.step(policy.act(obs))
            recorder.add(obs, info)
            steps += 1
            path_m += float(np.linalg.norm(obs["ego"][:2] - before))
            present = obs["history"][obs["history_mask"][:, -1], -1]
            if len(present):
                least_m = min(least_m, float(np.min(np.linalg.norm(present - obs["ego"][:2], axis=1))))
            done = terminated or truncated
        record = episode_record(scenario_name, i, seed, episode_metrics(
            recorder.finish(outcome_of(info["termination"], truncated), info.get("at_fault"))))
        # figures computed here without the project's metrics
        assert record["steps"] == steps
        assert record["success"] == (info["termination"] == "goal")
        assert record["path_length_m"] == pytest.approx(path_m, abs=1e-4)
        expected = least_m - world.contact_m if np.isfinite(least_m) else None
        assert (record["min_step_end_gap_m"] is None) == (expected is None)
        if expected is not None:
            assert record["min_step_end_gap_m"] == pytest.approx(expected, abs=1e-4)
        records.append(record)
    env.close()
    return records


def test_a_policy_from_outside_the_project_runs_every_scenario_with_a_plain_loops_figures(tmp_path: Path) -> None:
    """The example package's policy through the whole suite from the command line (two episodes each), and three
    scenarios against a plain gym loop, figure for figure."""
    out = tmp_path / "keep-clear"
    done = run_cli("benchmark", "--policy", KEEP_CLEAR, "--suite", "val", "--episodes", "2", "--predictor", "cvm",
                   "--out", str(out), "--workers", "2", "--quiet")
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert [s["name"] for s in summary["scenarios"]] == [s.name for s in SUITE.scenarios]
    assert (summary["suite"], summary["suite_version"], summary["split"]) == (SUITE.name, SUITE.version, "val")
    lines = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(lines) == 2 * len(SUITE.scenarios)
    documented = set(re.findall(r"^\| `(\w+)` \| (?:safety|efficiency|comfort|perception) \|",  # the table's rows
                                (REPO / "docs" / "benchmark-your-policy.md").read_text(), re.M))
    assert all(set(line) == {"scenario", "episode", "seed", "outcome"} | documented for line in lines), \
        "an episode line holds exactly the keys the guide lists: scenario, episode, seed, outcome, every metric"
    for scenario in summary["scenarios"]:
        assert scenario["env_kwargs"]["predictor"] == "cvm"
        assert [e["seed"] for e in scenario["episodes"]] == list(SUITE.seeds["val"][:2])
        for episode in scenario["episodes"]:
            assert {"success", "collision", "collision_at_fault", "time_to_goal_s", "path_length_m",
                    "min_step_end_gap_m"} <= set(episode)
            assert isinstance(episode["success"], bool) and isinstance(episode["collision_at_fault"], bool)
    # in this process (where --perturb nudges the simulated crowds as it does the plain loop's)
    names = ("sim-corridor", "zara1-reactive", "frontal-approach")
    here = run_benchmark(BenchmarkRun(KEEP_CLEAR, str(tmp_path / "here"), predictor="cvm", split="val", episodes=2,
                                      scenarios=names), workers=1, progress=False)
    by_scenario = {s["name"]: s["episodes"] for s in here["scenarios"]}
    for name in names:
        expected = plain_loop(name, "cvm", list(SUITE.seeds["val"][:2]), KEEP_CLEAR)
        assert by_scenario[name] == [{k: v for k, v in e.items() if k != "scenario"} for e in expected], name
    assert main(["leaderboard", str(out), "--no-baselines", "--out", str(tmp_path / "board.md"),
                 "--chart", str(tmp_path / "board.png")]) == 0
    board = (tmp_path / "board.md").read_text()
    assert "### Safety" in board and "### Efficiency" in board and "### Comfort and social" in board
    assert (tmp_path / "board.png").stat().st_size > 10_000


def test_a_policy_that_fails_is_named_with_scenario_episode_and_seed_and_finished_episodes_stay(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(tmp_path))
    (tmp_path / "flaky_policy.py").write_text(
        "import numpy as np\nclass Policy:\n    calls = 0\n    def act(self, obs):\n"
        "        Policy.calls += 1\n        if Policy.calls > 60:\n            return np.zeros(3)\n"
        "        return (obs['ego'][4:6] - obs['ego'][:2]) * 5\n")
    out = tmp_path / "flaky"
    run = BenchmarkRun("flaky_policy:Policy", str(out), predictor="none", split="val", episodes=5,
                       scenarios=("sim-corridor",))
    with pytest.raises(PolicyError, match=r"policy 'flaky_policy:Policy': act returned shape \(3,\).*scenario "
                                          r"'sim-corridor', episode \d, seed \d+"):
        run_benchmark(run, workers=1, progress=False)
    kept = (out / "parts" / "sim-corridor" / "00000.jsonl").read_text().splitlines()
    assert 1 <= len(kept) < 5, "the episodes finished before the failure are on disk"


def test_a_killed_run_resumes_to_the_episodes_of_an_uninterrupted_one(tmp_path: Path) -> None:
    args = ["benchmark", "--policy", "straight", "--predictor", "none", "--suite", "val", "--episodes", "6",
            "--scenarios", "sim-corridor", "frontal-approach", "--workers", "1", "--quiet"]
    whole = run_cli(*args, "--out", str(tmp_path / "whole"))
    assert whole.returncode == 0, whole.stderr
    out = tmp_path / "killed"
    process = subprocess.Popen([sys.executable, "-m", "st_sim", *args, "--out", str(out)], cwd=REPO,
                               env={**os.environ, "OMP_NUM_THREADS": "1"}, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    part = out / "parts" / "sim-corridor" / "00000.jsonl"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and (not part.is_file() or len(part.read_text().splitlines()) < 2):
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert part.is_file() and not (out / "summary.json").exists(), "killed before the end"
    with part.open("a") as lines:
        lines.write('{"scenario": "sim-corridor", "episode": 5, "se')  # a line torn by the kill
    resumed = run_cli(*args, "--out", str(out))
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "episodes.jsonl").read_text() == (tmp_path / "whole" / "episodes.jsonl").read_text()
    other = run_cli(*[a if a != "straight" else "orca" for a in args], "--out", str(out))
    assert other.returncode == 1 and "holds another run" in other.stderr


def test_the_command_refuses_bad_options_in_one_line(tmp_path: Path, capsys) -> None:
    for args, message in [(["--scenarios", "nowhere"], "no scenario 'nowhere'"),
                          (["--episodes", "5000"], "ask 1 to 1000"),
                          (["--suite-file", str(tmp_path / "none.json")], "cannot read the suite file")]:
        assert main(["benchmark", "--policy", "straight", "--out", str(tmp_path / "x"), *args]) == 1
        assert message in capsys.readouterr().err
    assert main(["benchmark", "--list"]) == 0, "--list alone prints the suite"
    assert "univ-reactive" in capsys.readouterr().out
    assert main(["benchmark", "--out", str(tmp_path / "y")]) == 1 and "--policy is required" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists(), "a refused run leaves no folder"


def test_the_leaderboard_refuses_results_of_other_episodes(tmp_path: Path) -> None:
    for name, episodes in (("a", 2), ("b", 3)):
        run_benchmark(BenchmarkRun("straight", str(tmp_path / name), predictor="none", split="val",
                                   episodes=episodes, scenarios=("frontal-approach",)), workers=1, progress=False)
    a, b = load_result(tmp_path / "a"), load_result(tmp_path / "b")
    with pytest.raises(LeaderboardError, match="different episodes"):
        markdown([a, b])
    with pytest.raises(LeaderboardError, match=r"no summary\.json"):
        load_result(tmp_path / "nothing")
    table = markdown([a])
    for metric, spec in METRICS.items():
        if spec.group == "safety" and a["summary"][metric]["n"]:
            assert metric in table


def test_the_docs_define_every_metric_as_the_code_does() -> None:
    from st_sim.apps.navigation.metrics import metrics_table

    assert metrics_table() in (REPO / "docs" / "benchmark-your-policy.md").read_text(), \
        "docs/benchmark-your-policy.md: paste metrics_table() again"


def test_an_sb3_model_runs_where_it_fits_and_is_refused_before_any_episode_where_it_does_not(tmp_path: Path,
                                                                                            capsys) -> None:
    from stable_baselines3 import PPO

    env = gym.wrappers.FilterObservation(gym.make("STCrowd-SimCorridor-v1", predictor="none"),
                                         ["ego", "history", "history_mask"])
    PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, device="cpu").save(tmp_path / "raw.zip")
    spec = f"sb3:{tmp_path / 'raw.zip'}"
    args = ["benchmark", "--policy", spec, "--predictor", "none", "--suite", "val", "--episodes", "1", "--workers", "1",
            "--quiet"]
    assert main([*args, "--scenarios", "sim-corridor", "--out", str(tmp_path / "fits")]) == 0
    assert main([*args, "--scenarios", "sim-corridor", "zara1-log", "--out", str(tmp_path / "misfit")]) == 1
    err = capsys.readouterr().err
    assert "does not fit scenario 'zara1-log'" in err and "(20, 8, 2)" in err and "(40, 8, 2)" in err
    assert "envs.view.FixedView" in err, "the way round is named"
    assert not (tmp_path / "misfit" / "parts").exists(), "refused before any episode"


def test_a_model_of_the_fixed_view_fits_any_pedestrian_slots_but_not_other_histories_or_samples() -> None:
    from envs.view import view_space
    from st_sim.apps.navigation.policies import observation_fits

    for env_id, kwargs in [("STCrowd-SimCorridor-v1", {}), ("STCrowd-Univ-v0", {}), ("STCrowd-Hotel-v0", {})]:
        env_space = gym.make(env_id, predictor="none", **kwargs).observation_space
        assert observation_fits(view_space(8, 16, 8, 20), env_space), env_id
        assert observation_fits(view_space(3, 5, 8, 20), env_space), f"{env_id}: any K and R"
        assert not observation_fits(view_space(8, 16, 2, 20), env_space), f"{env_id}: 2 observed steps, not 8"
        assert not observation_fits(view_space(8, 16, 8, 1), env_space), f"{env_id}: 1 sample, not 20"


def test_the_example_sb3_policy_trains_in_a_few_lines_and_runs_where_the_raw_model_could_not(tmp_path: Path) -> None:
    """The example trains on the suite env's fixed-size view; ``--policy sb3:PATH.zip`` takes the model as it is, in
    a scenario it never saw and with another number of pedestrian slots (UNIV: 75), after checking it fits every
    scenario of the suite."""
    model = tmp_path / "suite.zip"
    trained = subprocess.run([sys.executable, "-m", "examples.my_policy.train_sb3", "--steps", "512", "--scenarios",
                              "frontal-approach", "zara1-log", "--out", str(model)], cwd=REPO,
                             env={**os.environ, "OMP_NUM_THREADS": "1"}, capture_output=True, text=True, timeout=900)
    assert trained.returncode == 0, trained.stderr
    done = subprocess.run([sys.executable, "-m", "st_sim", "benchmark", "--policy", f"sb3:{model}", "--predictor",
                           "cvm", "--suite", "val", "--episodes", "1", "--scenarios", "overtaking", "univ-log",
                           "--workers", "1", "--quiet", "--out", str(tmp_path / "bench")], cwd=REPO,
                          env={**os.environ, "OMP_NUM_THREADS": "1"}, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert len((tmp_path / "bench" / "episodes.jsonl").read_text().splitlines()) == 2


def test_the_committed_baselines_load_and_join_a_run_of_the_same_episodes() -> None:
    from st_sim.apps.navigation.leaderboard import BASELINES_DIR, baseline_results

    committed = [load_result(folder) for folder in sorted(BASELINES_DIR.iterdir()) if folder.is_dir()]
    assert len(committed) >= 6 and all(r["split"] == "test" and r["episodes_per_scenario"] == 100 for r in committed)
    assert {s["name"] for s in committed[0]["scenarios"]} == {s.name for s in SUITE.scenarios}
    joined, note = baseline_results(committed[0])
    assert len(joined) == len(committed) and note is None
    joined, note = baseline_results({**committed[0], "split": "val"})
    assert joined == [] and "--suite test" in note, "other episodes never join, and the note says how to get them"
    joined, note = baseline_results({**committed[0], "scenario_set": ["sim-crossing"]})
    assert joined == [] and "--common-scenarios" in note, "another scenario set joins only when asked"
    table = markdown(committed)
    labels = ("straight + none", "orca + none", "mpc + singular", "ppo + singular")
    assert all(f"| {name} |" in table for name in labels)


BAD_ACTIONS = st.sampled_from(["np.zeros(3)", "np.full(2, np.nan)", "np.array([np.inf, 0.0])", "None",
                               "np.zeros((2, 2))", "'ahead'", "np.array([1e300, -1e300]) * 10"])


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(action=BAD_ACTIONS)
def test_a_policy_that_fails_in_the_first_episode_is_named_with_scenario_episode_and_seed(
        tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch, action: str) -> None:
    folder = tmp_path_factory.mktemp("bad")
    monkeypatch.syspath_prepend(str(folder))
    name = f"bad_first_{abs(hash(action))}"
    (folder / f"{name}.py").write_text(f"import numpy as np\nclass Policy:\n    def act(self, obs):\n"
                                       f"        return {action}\n")
    seed = load_suite().seeds["val"][0]
    run = BenchmarkRun(f"{name}:Policy", str(folder / "out"), predictor="none", split="val", episodes=2,
                       scenarios=("sim-corridor",))
    with pytest.raises(PolicyError, match=rf"scenario 'sim-corridor', episode 0, seed {seed}\)$"):
        run_benchmark(run, workers=1, progress=False)


def test_a_run_is_planned_once_and_its_chunks_load_no_suite(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """One run of three scenarios in two chunks each, in this process: the suite is loaded and its seeds resolved
    once (``plan_run``), and every chunk runs from what the plan gave it."""
    from envs import suite as suite_module
    from st_sim.apps.navigation import benchmark

    calls = {"load_suite": 0, "seeds_of": 0, "select": 0}
    loaded, seeds_of, select = suite_module.load_suite, suite_module.Suite.seeds_of, suite_module.Suite.select

    def counting(name, function):
        def counted(*args, **kwargs):
            calls[name] += 1
            return function(*args, **kwargs)
        return counted

    monkeypatch.setattr(benchmark, "load_suite", counting("load_suite", loaded))
    monkeypatch.setattr(suite_module.Suite, "seeds_of", counting("seeds_of", seeds_of))
    monkeypatch.setattr(suite_module.Suite, "select", counting("select", select))
    monkeypatch.setattr(benchmark, "CHUNK_EPISODES", 2)
    summary = run_benchmark(BenchmarkRun("straight", str(tmp_path / "run"), predictor="none", split="val",
                                         episodes=4, scenarios=("frontal-approach", "overtaking", "group")),
                            workers=1, progress=False)
    assert calls == {"load_suite": 1, "seeds_of": 1, "select": 1}, calls
    assert len(list((tmp_path / "run" / "parts").glob("*/*.jsonl"))) == 6
    assert [[e["seed"] for e in s["episodes"]] for s in summary["scenarios"]] == [list(SUITE.seeds["val"][:4])] * 3
