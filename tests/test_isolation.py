"""What a plug-in or a bad input cannot do to the benchmark: write into shared scenes, return futures beyond the
recordings' bounds, skip a frame when it fails mid-step, reset some sub-envs of a vector env and not others, or leave
worker processes behind a killed grid driver."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_plugins import LIGHT, PREDICTOR_TEMPLATE, write_plugin

import envs  # noqa: F401  (registers the ids)
from envs.common.errors import EnvInputError, NeedsResetError
from envs.common.predictors import predict_futures
from predictor.plugins import PluginError, load_plugin
from replays.constants import FORECAST_LIMIT_M
from replays.data_root import data_root
from replays.scenes import Scene, load_scene, scene_info
from st_sim.apps.cli import main

PLUGIN_CASES = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

MUTATIONS = [  # what a careless or hostile predict does to what it is handed
    "scene.walkable[:] = False", "scene.walkable[::2] = ~scene.walkable[::2]", "scene.H[0, 0] *= 5.0",
    "scene.H_inv[:] = 0.0", "scene.photo[:] = 0", "scene.walkable = np.zeros((2, 2), bool)", "scene.name = 'x'",
    "obs[:] = 0.0", "group[:] = 7",
]


@pytest.fixture
def plugin_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def _mutating_plugin(folder: Path, mutation: str) -> str:
    return write_plugin(folder, f"""
class Mutating:
    def predict(self, obs, group, scene, num_samples):
        {mutation}
        return np.repeat(obs[:, None, -1:], num_samples, 1).repeat(12, 2)

def make(**kw):
    return Mutating()
""")


@PLUGIN_CASES
@given(mutation=st.sampled_from(MUTATIONS), scene=st.sampled_from(["eth", "zara1"]))
def test_a_plugin_cannot_change_the_shared_scene(plugin_dir: Path, mutation: str, scene: str) -> None:
    shared = load_scene(scene)
    fresh = Scene.from_files(scene_info(scene), data_root())
    model = load_plugin(_mutating_plugin(plugin_dir, mutation), *LIGHT)
    obs = np.cumsum(np.full((3, 8, 2), 0.4, np.float32), axis=1)
    try:
        predict_futures(model, obs, shared, 20)
    except PluginError as err:
        assert "read-only" in str(err), err
    assert shared is load_scene(scene) and shared.name == scene
    for field in ("H", "H_inv", "walkable", "photo"):
        assert np.array_equal(getattr(shared, field), getattr(fresh, field)), f"{mutation} changed scene.{field}"
    assert (obs == np.cumsum(np.full((3, 8, 2), 0.4, np.float32), axis=1)).all(), "the caller's histories changed"


def test_a_scene_writing_plugin_changes_no_other_cell_nor_a_later_env(plugin_dir: Path, capsys) -> None:
    spec = _mutating_plugin(plugin_dir, "scene.walkable[:] = False")
    args = ["evaluate", "--task", "deterministic", "--scenes", "eth", "--no-stream", "--quiet", "--workers", "1"]
    assert main([*args, "--predictor", "cvm", "--json", str(plugin_dir / "alone.json"),
                  "--runs", str(plugin_dir / "alone")]) == 0
    assert main([*args, "--predictor", spec, "cvm", "--runs", str(plugin_dir / "runs")]) == 1
    assert "read-only" in capsys.readouterr().err
    assert main([*args, "--predictor", "cvm", "--json", str(plugin_dir / "after.json"),
                 "--runs", str(plugin_dir / "runs")]) == 0
    assert _scores(plugin_dir / "after.json") == _scores(plugin_dir / "alone.json")
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    env.reset(seed=0)  # the ego's start is drawn on the (intact) walkable map
    env.close()


def _scores(path: Path) -> dict:
    """Every scene's figures of an evaluate --json file, without wall times."""
    import json

    scenes = json.loads(path.read_text())["scenes"]
    return {name: {k: v for k, v in row.items() if k != "seeds"} for name, row in scenes.items()}


@PLUGIN_CASES
@given(value=st.sampled_from(["3e4", "-3e4", "1e30", "-1e30", f"{FORECAST_LIMIT_M * 1.0001}"]),
       where=st.integers(0, 10**6))
def test_futures_beyond_the_recordings_bound_are_refused_naming_the_plugin(plugin_dir: Path, value: str,
                                                                             where: int) -> None:
    spec = write_plugin(plugin_dir, PREDICTOR_TEMPLATE.format(
        body=f"out = good.astype(np.float64); out.flat[{where} % out.size] = {value}; return out"))
    model = load_plugin(spec, *LIGHT)
    with pytest.raises(PluginError, match=repr(spec).replace("(", r"\(") + f".*{FORECAST_LIMIT_M:g} m bound"):
        predict_futures(model, np.ones((2, 8, 2), np.float32), None, 20)


FAILING_TEMPLATE = """
calls = [0]

class Failing:
    def predict(self, obs, group, scene, num_samples):
        calls[0] += 1
        if calls[0] == {fail_at}:
            raise RuntimeError("predict failed on call {fail_at}")
        return np.repeat(obs[:, None, -1:], num_samples, 1).repeat(12, 2)

def make(**kw):
    return Failing()
"""


@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fail_at=st.integers(1, 6), env_id=st.sampled_from(["STCrowd-Zara1-v0", "STCrowd-SimCorridor-v1"]),
       vector=st.booleans())
def test_a_step_whose_predictor_fails_demands_a_reset_and_skips_no_frame(plugin_dir: Path, fail_at: int, env_id: str,
                                                                       vector: bool) -> None:
    spec = write_plugin(plugin_dir, FAILING_TEMPLATE.format(fail_at=fail_at))
    # gymnasium's env checker breaks on the first step after a first reset that raised: not what is tested here
    env = gym.make_vec(env_id, num_envs=2, predictor=spec) if vector else \
        gym.make(env_id, predictor=spec, disable_env_checker=fail_at == 1)
    action = np.zeros((2, 2) if vector else 2, np.float32)
    if fail_at == 1:  # the reset's forecast: no episode began, so a step asks for a reset
        with pytest.raises(PluginError, match="predict failed on call 1"):
            env.reset(seed=0)
        with pytest.raises(NeedsResetError, match=r"call reset\(\) before step\(\)"):
            env.step(action)
    else:
        env.reset(seed=0)  # the first call
        with pytest.raises(PluginError, match=f"predict failed on call {fail_at}"):
            for _ in range(fail_at):
                env.step(action)
        for _ in range(2):  # not the next frame: every later step is refused until a reset
            with pytest.raises(NeedsResetError, match=r"did not finish.*predict failed"):
                env.step(action)
    _, info = env.reset(seed=0)
    assert (np.asarray(env.step(action)[4]["frame"]) > np.asarray(info["frame"])).all()
    env.close()


@pytest.mark.parametrize("vector", [False, True])
def test_a_step_whose_world_fails_demands_a_reset(monkeypatch: pytest.MonkeyPatch, vector: bool) -> None:
    from envs.sim_env import SimCrowdEnv

    env = gym.make_vec("STCrowd-SimCorridor-v1", num_envs=2, predictor="cvm") if vector else \
        gym.make("STCrowd-SimCorridor-v1", predictor="cvm")
    action = np.zeros((2, 2) if vector else 2, np.float32)
    env.reset(seed=0)
    env.step(action)

    def failing(cls: type, batch: list, velocities: list) -> None:
        raise RuntimeError("the crowd failed")

    monkeypatch.setattr(SimCrowdEnv, "_step_worlds", classmethod(failing))
    with pytest.raises(RuntimeError, match="the crowd failed"):
        env.step(action)
    monkeypatch.undo()
    with pytest.raises(NeedsResetError, match=r"did not finish.*the crowd failed"):
        env.step(action)
    _, info = env.reset(seed=0)
    assert (np.asarray(env.step(action)[4]["frame"]) > np.asarray(info["frame"])).all()
    env.close()


def test_a_vector_reset_refused_for_one_sub_env_resets_none() -> None:
    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=3, predictor="cvm")
    vec.reset(seed=0)
    for _ in range(2):
        before = vec.step(np.zeros((3, 2), np.float32))[4]["frame"]
    with pytest.raises(EnvInputError, match="sub-env 2: seed=-1"):
        vec.reset(seed=[0, 1, -1])
    after = vec.step(np.zeros((3, 2), np.float32))[4]["frame"]  # no NeedsResetError: the episodes went on
    assert (after == before + 1).all()
    with pytest.raises(EnvInputError, match="ragged"):
        vec.step([[0.0, 0.0], [0.0], [0.0, 0.0]])
    vec.close()


def test_killing_the_grid_driver_ends_its_workers(tmp_path: Path) -> None:
    pids = tmp_path / "pids"
    driver = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from st_sim.apps.grid import Job, run_jobs
        jobs = [Job(f"sleep{{i}}", "test_isolation:sleeping_job", {{"pids": {str(pids)!r}}}, {str(tmp_path)!r} +
                    f"/never{{i}}") for i in range(2)]
        run_jobs(jobs, workers=2, progress=False)
        """)
    process = subprocess.Popen([sys.executable, "-c", driver], cwd=Path(__file__).parents[1])
    deadline = time.monotonic() + 120
    while (not pids.exists() or len(pids.read_text().split()) < 2) and time.monotonic() < deadline:
        time.sleep(0.2)
    workers = [int(p) for p in pids.read_text().split()]
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    deadline = time.monotonic() + 15
    while any(_alive(pid) for pid in workers) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(pid) for pid in workers), "a worker outlived its killed driver"


def sleeping_job(pids: str) -> None:
    """A grid job that records its process id and never finishes."""
    with open(pids, "a") as f:
        f.write(f"{os.getpid()}\n")
    time.sleep(600)


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"  # a zombie has exited
    except FileNotFoundError:
        return False


def test_a_plugin_that_kills_its_worker_is_reported_by_name(plugin_dir: Path, capsys) -> None:
    spec = write_plugin(plugin_dir, PREDICTOR_TEMPLATE.format(body="import os; os._exit(3)"))
    code = main(["evaluate", "--task", "deterministic", "--scenes", "eth", "--predictor", spec, "--no-stream",
                 "--quiet", "--workers", "1", "--runs", str(plugin_dir / "runs")])
    err = capsys.readouterr().err
    assert code == 1 and spec in err and err.count("\n") == 1, err
