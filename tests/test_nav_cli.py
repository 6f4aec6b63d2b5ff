"""The navigate command and its runner: paired seeded episodes, JSON output, env options, shipped policies."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from envs.common.terrain import Terrain
from replays.scenes import Scene
from st_sim.apps.cli import main
from st_sim.apps.navigation.episodes import SEE_EGO_KWARG, NavRun, accepts_keyword, run_navigation
from st_sim.apps.navigation.ppo import SHIPPED, SHIPPED_REACTIVE, SHIPPED_SUITE, PolicyFileError, load_policy


def test_navigate_prints_intervals_writes_json_and_recordings_and_repeats(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture) -> None:
    args = ["navigate", "--env", "STCrowd-SimCorridor-v1", "--policy", "straight", "--predictor", "none",
            "--episodes", "2", "--seed", "5", "--quiet"]
    assert main([*args, "--json", str(tmp_path / "a.json")]) == 0
    out = capsys.readouterr().out
    assert "95 % CI" in out and "pedestrian_collision" in out and "jerk" in out and "comfort:" in out
    main([*args, "--json", str(tmp_path / "b.json"), "--rerun", str(tmp_path / "rrd")])
    assert len(list((tmp_path / "rrd").glob("*seed[56].rrd"))) == 2, "one recording per episode"
    a, b = (json.loads((tmp_path / name).read_text()) for name in ("a.json", "b.json"))
    assert [e["seed"] for e in a["episodes"]] == [5, 6]
    assert a["episodes"] == b["episodes"], "the same seeds must give the same episodes"
    assert set(a["summary"]) >= {"success", "pedestrian_collision", "wall_collision", "timeout", "discomfort"}


def test_runner_gives_every_planner_the_same_episode_starts() -> None:
    runs = [run_navigation(NavRun("STCrowd-Zara1-v0", policy, "cvm", episodes=2, seed=3), progress=False)
            for policy in ("straight", "mpc")]
    starts = [[(e["seed"], e["outcome"] != "") for e in run["episodes"]] for run in runs]
    assert starts[0] == starts[1]
    assert runs[1]["pedestrians_see_ego"] is None, "replays have no pedestrians_see_ego option"


def test_see_ego_keyword_is_detected_not_assumed() -> None:
    assert accepts_keyword("STCrowd-Zara1-v0", "rerun")
    assert not accepts_keyword("STCrowd-Zara1-v0", SEE_EGO_KWARG)
    assert not accepts_keyword("STCrowd-Zara1-v0", "no_such_option")


def test_terrain_cost_to_go_goes_around_a_wall(toy_scene: Scene) -> None:
    terrain = Terrain(toy_scene, (0.0, 0.0, 4.9, 9.9))  # the toy scene's walkable left half
    goal = np.array([1.0, 9.0])
    assert terrain.cost_to_go(np.array([1.0, 1.0]), goal, 0.3) == pytest.approx(8.0, abs=0.1)
    assert terrain.clearance_at(np.array([4.5, 5.0])) == pytest.approx(0.5, abs=0.11)
    assert terrain.clearance_at(np.array([7.0, 5.0])) == 0.0, "the wall half is not walkable"
    assert terrain.direction_to(np.array([1.0, 1.0]), goal, 0.3) @ np.array([0.0, 1.0]) > 0.99


def test_shipped_policies_load_by_name_and_a_broken_file_is_refused(tmp_path: Path) -> None:
    for use_predictions, name in [*SHIPPED.items(), *SHIPPED_REACTIVE.items(), *SHIPPED_SUITE.items()]:
        policy, features = load_policy(name)
        assert features.use_predictions == use_predictions
        assert policy.observation_space.shape == (features.size,)
    broken = tmp_path / "broken.pt"
    broken.write_bytes(b"not a policy")
    with pytest.raises(PolicyFileError, match=r"broken\.pt"):
        load_policy(broken)


def test_a_grid_job_writes_the_run_with_its_mode_and_at_fault_counts(tmp_path: Path) -> None:
    from st_sim.apps.grid import execute
    from st_sim.apps.navigation.episodes import grid_job
    from st_sim.apps.navigation.mpc import MpcConfig

    run = NavRun("STCrowd-Zara1-v0", "mpc", "cvm", episodes=2, seed=7, pedestrians="reactive",
                 mpc=MpcConfig(risk_limit=0.5))
    job = grid_job("nav/test", run, tmp_path / "cell.json")
    assert execute(job).status == "done"
    result = json.loads((tmp_path / "cell.json").read_text())
    assert result["pedestrians"] == "reactive" and result["planner_config"]["risk_limit"] == 0.5
    assert {"collision", "collision_at_fault", "log_ade_m"} <= set(result["summary"])
    assert all(e["collision_at_fault"] in (True, False) for e in result["episodes"])
    assert all(np.isfinite(e["log_ade_m"]) for e in result["episodes"]), "a reactive replay reports its price"


def test_a_simulated_env_has_no_pedestrian_mode() -> None:
    with pytest.raises(ValueError, match="only the replays"):
        run_navigation(NavRun("STCrowd-SimCorridor-v1", "straight", "none", episodes=1, pedestrians="reactive"),
                       progress=False)


@pytest.mark.parametrize("predictor", ["linear", "cvm-s"])
def test_navigate_takes_every_baseline_predictor(tmp_path: Path, predictor: str) -> None:
    """The open/closed-loop study drives the MPC with the least-squares line too (it once was refused)."""
    out = tmp_path / "nav.json"
    assert main(["navigate", "--env", "STCrowd-Zara1-v0", "--policy", "mpc", "--predictor", predictor,
                 "--pedestrians", "reactive", "--episodes", "1", "--quiet", "--json", str(out)]) == 0
    run = json.loads(out.read_text())
    assert run["predictor"] == predictor and len(run["episodes"]) == 1


def test_a_sensor_range_reaches_the_env_and_bad_ranges_are_refused(capsys: pytest.CaptureFixture) -> None:
    from st_sim.apps.navigation.episodes import make_nav_env

    env = make_nav_env(NavRun("STCrowd-SimCrossing-v1", "ppo", "singular", sensor_range_m=5.0))
    assert env.unwrapped.cfg.sensor_range_m == 5.0
    assert make_nav_env(NavRun("STCrowd-SimCrossing-v1", "ppo", "none")).unwrapped.cfg.sensor_range_m == np.inf
    for bad in ("0", "-1", "nan"):
        with pytest.raises(SystemExit, match="--sensor-range"):
            main(["navigate", "--policy", "straight", "--predictor", "none", "--sensor-range", bad, "--quiet"])


def test_a_trained_policy_file_drives_ppo_and_other_planners_refuse_it(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture) -> None:
    """``--policy-file`` swaps the shipped policy for one's own: its episodes are its own (not the shipped one's)."""
    import torch

    from st_sim.apps.navigation.features import FeatureConfig
    from st_sim.apps.navigation.ppo import build_policy, save_policy

    cfg = FeatureConfig(False)
    policy = build_policy(cfg, [8])
    for parameter in policy.parameters():  # a policy that walks backwards, away from the goal
        parameter.data.zero_()
    policy.action_net.bias.data[:] = torch.tensor([-1.0, 0.0])
    save_policy(policy, cfg, [8], tmp_path / "backwards.pt")
    args = ["navigate", "--env", "STCrowd-SimCorridor-v1", "--policy", "ppo", "--predictor", "none", "--episodes",
            "2", "--quiet"]
    main([*args, "--policy-file", str(tmp_path / "backwards.pt"), "--json", str(tmp_path / "own.json")])
    main([*args, "--json", str(tmp_path / "shipped.json")])
    own, shipped = (json.loads((tmp_path / f"{name}.json").read_text()) for name in ("own", "shipped"))
    assert own["policy_file"].endswith("backwards.pt") and shipped["policy_file"] is None
    assert own["summary"]["success"]["value"] == 0.0, "walking away from the goal never reaches it"
    assert own["episodes"] != shipped["episodes"]
    capsys.readouterr()
    assert main(["navigate", "--policy", "straight", "--predictor", "none", "--policy-file", "x.pt", "--quiet"]) == 1
    assert re.fullmatch(r"error: a policy file .* given for the straight planner.*\n", capsys.readouterr().err)
    assert main([*args, "--policy-file", str(tmp_path / "nothing.pt")]) == 1
    assert re.fullmatch(r"error: .*nothing\.pt: no such policy file.*\n", capsys.readouterr().err)
