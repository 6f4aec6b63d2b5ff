"""Benchmark episodes back: ``benchmark --record`` writes a recording of exactly the chosen episodes, and ``episode``
re-runs any episode of a finished run to the same figures (shipped planners and a plug-in, logged, reactive and
simulated scenarios), failing on a figure that differs, by name."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rrd_files import logged_steps, read_rrd

from st_sim.apps.cli import main
from st_sim.apps.navigation.benchmark import BenchmarkRun, run_benchmark, summary_of
from st_sim.apps.navigation.episode_recording import chosen
from st_sim.apps.navigation.episode_replay import differences, replay_episode

KEEP_CLEAR = "examples.my_policy.keep_clear:KeepClear"
SCENARIOS = ("zara1-log", "eth-reactive", "frontal-approach")  # logged, reactive and simulated
RUNS = {"straight": ("straight", "none"), "mpc-cvm": ("mpc", "cvm"), "keep-clear": (KEEP_CLEAR, "cvm")}


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, dict]]:
    """Two episodes of each scenario per policy, the straight planner's recorded (``--record all``); name -> (folder,
    summary)."""
    made = {}
    for name, (policy, predictor) in RUNS.items():
        out = tmp_path_factory.mktemp(name)
        summary = run_benchmark(BenchmarkRun(policy=policy, out=str(out), predictor=predictor, split="val",
                                             episodes=2, scenarios=SCENARIOS,
                                             record="all" if name == "straight" else "none"),
                                workers=1, progress=False)
        made[name] = (out, summary)
    return made


@pytest.mark.parametrize("name", sorted(RUNS))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_episode_reproduces_the_runs_line(runs: dict[str, tuple[Path, dict]], name: str, scenario: str) -> None:
    """The second episode (the first ran before it in the same env and policy) comes out figure for figure."""
    folder, _ = runs[name]
    policy = RUNS[name][0] if name == "keep-clear" else None  # a folder names no code: the user gives it
    expected, measured, path = replay_episode(folder, scenario, 1, policy=policy)
    assert path is None and differences(expected, measured) == [], f"{name} on {scenario}"
    assert measured == expected


def test_record_all_writes_each_episode_with_its_walls_line_and_collision(runs: dict[str, tuple[Path, dict]]) -> None:
    folder, summary = runs["straight"]
    for scenario in summary["scenarios"]:
        for line in scenario["episodes"]:
            path = folder / "recordings" / scenario["name"] / f"{line['episode']}.rrd"
            assert path.is_file(), f"{path} missing"
            entities = read_rrd(path)
            assert logged_steps(path) == line["steps"] + 1, f"{path}: one logged step per state"
            notes = entities["/notes"][None]["TextDocument:text"][0]
            assert f"**{scenario['name']}**, episode {line['episode']} (seed {line['seed']})" in notes
            assert f"| min_step_end_gap_m | {json.dumps(line['min_step_end_gap_m'])} |" in notes
            assert entities["/world/walls"][None]["LineStrips2D:strips"], f"{path}: no walls"
            assert "/world/predictions" not in str(sorted(entities)), "a run without forecasts logs none"
            marker = entities.get("/world/events/collision")
            assert (marker is not None) == line["collision"], f"{path}: collision marker {marker} for {line}"
            if line["collision"]:
                (step, logged), = marker.items()
                assert step == line["steps"], "the marker appears at the colliding step"
                assert ("robot at fault" in logged["Points2D:labels"][0]) == line["collision_at_fault"]


def test_record_failures_writes_exactly_the_failed_episodes(tmp_path: Path) -> None:
    summary = run_benchmark(BenchmarkRun(policy="straight", out=str(tmp_path), predictor="none", split="val",
                                         episodes=4, scenarios=("sim-crossing", "univ-reactive"), record="failures"),
                            workers=1, progress=False)
    failed = {(s["name"], line["episode"]) for s in summary["scenarios"] for line in s["episodes"]
              if not line["success"]}
    written = {(path.parent.name, int(path.stem)) for path in (tmp_path / "recordings").glob("*/*.rrd")}
    assert failed and written == failed
    assert summary["scenarios"][0]["episodes"] == json.loads((tmp_path / "summary.json").read_text())[
        "scenarios"][0]["episodes"]


def test_a_recorded_episode_replays_to_a_recording_of_the_same_states(runs: dict[str, tuple[Path, dict]],
                                                                     tmp_path: Path, capsys) -> None:
    folder, _ = runs["mpc-cvm"]
    target = tmp_path / "replay.rrd"
    assert main(["episode", str(folder), "eth-reactive", "0", "--rerun", str(target)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {target}" in out and "every figure equals the run's line" in out
    line = next(line for s in runs["mpc-cvm"][1]["scenarios"] if s["name"] == "eth-reactive"
                for line in s["episodes"] if line["episode"] == 0)
    entities = read_rrd(target)
    assert logged_steps(target) == line["steps"] + 1
    assert any(path.startswith("/world/predictions/") for path in entities), "forecasts of a run with cvm are kept"


def test_a_figure_that_differs_fails_the_command_naming_it(runs: dict[str, tuple[Path, dict]], tmp_path: Path,
                                                           capsys) -> None:
    folder, _ = runs["straight"]
    edited = json.loads((folder / "summary.json").read_text())
    scenario = edited["scenarios"][2]
    line = scenario["episodes"][1]
    line["min_step_end_gap_m"] = line["min_step_end_gap_m"] + 0.5
    scenario["summary"] = summary_of(scenario["episodes"])  # consistent, or the reader refuses the folder
    edited["summary"] = summary_of([e for s in edited["scenarios"] for e in s["episodes"]])
    (tmp_path / "summary.json").write_text(json.dumps(edited))
    assert main(["episode", str(tmp_path), edited["scenarios"][2]["name"], "1"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "min_step_end_gap_m:" in err and "does not reproduce" in err, err
    assert "steps" not in err.split("reproduce", 1)[1].split("(the code")[0], "only the edited figure is named"


def test_verify_re_runs_the_first_episodes_of_each_scenario_and_fails_on_one_that_differs(
        runs: dict[str, tuple[Path, dict]], tmp_path: Path, capsys) -> None:
    folder, _ = runs["straight"]
    assert main(["verify", str(folder), "--per-scenario", "2"]) == 0
    assert capsys.readouterr().out.count("2 of 2 episodes reproduce") == len(SCENARIOS)
    edited = json.loads((folder / "summary.json").read_text())
    lines = edited["scenarios"][2]["episodes"]
    lines[0]["seed"], lines[1]["seed"] = lines[1]["seed"], lines[0]["seed"]  # each line now names another episode
    (tmp_path / "summary.json").write_text(json.dumps(edited))
    assert main(["verify", str(tmp_path), "--scenarios", edited["scenarios"][2]["name"]]) == 1
    assert "1 episodes do not reproduce" in capsys.readouterr().err


def test_unknown_scenarios_and_episodes_are_one_line_errors(runs: dict[str, tuple[Path, dict]], tmp_path: Path,
                                                           capsys) -> None:
    folder, _ = runs["straight"]
    for args, says in (([str(folder), "zara9-log", "0"],
                        "no scenario 'zara9-log'; it has frontal-approach, eth-reactive, zara1-log"),
                       ([str(folder), "zara1-log", "5"], "has no episode 5; it has episodes 0 to 1"),
                       ([str(tmp_path), "zara1-log", "0"], "no summary.json"),
                       ([str(folder), "zara1-log", "0", "--rerun", "x.rrd", "--spawn"], "not both")):
        assert main(["episode", *args]) == 1
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err, err


FIGURES = st.dictionaries(st.sampled_from(["steps", "success", "min_step_end_gap_m", "outcome", "path_ratio"]),
                          st.one_of(st.none(), st.booleans(), st.integers(-5, 5), st.floats(allow_nan=False),
                                    st.text(max_size=4)), min_size=1)


@given(line=FIGURES, key=st.sampled_from(["steps", "success", "min_step_end_gap_m", "outcome", "path_ratio"]),
       value=st.one_of(st.none(), st.booleans(), st.integers(-5, 5), st.floats(allow_nan=False)))
def test_differences_names_exactly_the_figures_that_changed(line: dict, key: str, value: object) -> None:
    assert differences(line, dict(line)) == []
    changed = {**line, key: value}
    named = [phrase.split(":")[0] for phrase in differences(line, changed)]
    assert named == ([] if key in line and json.dumps(line[key]) == json.dumps(value) else [key])
    assert [p.split(":")[0] for p in differences(line, {k: v for k, v in line.items() if k != key})] == (
        [key] if key in line else [])


def test_record_choices_are_checked() -> None:
    assert chosen("all", {"success": True}) and chosen("failures", {"success": False})
    assert not chosen("failures", {"success": True}) and not chosen("none", {"success": False})
    with pytest.raises(ValueError, match="record='some'"):
        chosen("some", {"success": False})


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(patterns=st.lists(st.from_regex(r"zz[a-z*?-]{0,8}", fullmatch=True), min_size=1, max_size=3))
def test_verify_fails_when_its_patterns_match_no_scenario(runs: dict[str, tuple[Path, dict]], patterns: list[str],
                                                          capsys) -> None:
    folder, _ = runs["straight"]
    assert main(["verify", str(folder), "--scenarios", *patterns, "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "matches none of the run's scenarios" in err and "reproduce" not in err, err


def test_verify_checks_a_run_of_the_users_own_policy_given_on_the_command_line(runs: dict[str, tuple[Path, dict]],
                                                                              capsys) -> None:
    folder, _ = runs["keep-clear"]
    assert main(["verify", str(folder), "--quiet"]) == 1
    assert "give it yourself with --policy SPEC" in capsys.readouterr().err
    assert main(["verify", str(folder), "--policy", "straight", "--quiet"]) == 1
    assert f"--policy straight: the run's is '{KEEP_CLEAR}'" in capsys.readouterr().err
    assert main(["verify", str(folder), "--policy", KEEP_CLEAR, "--quiet"]) == 0
    captured = capsys.readouterr()
    assert f"every episode re-run equals its line ({len(SCENARIOS)} episodes)" in captured.out
    assert "scenario/s" not in captured.err and "%" not in captured.err, "no progress bar with --quiet"
