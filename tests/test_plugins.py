"""Plug-in predictors (``package.module:name``): the example scores what an independent computation scores, through
the evaluate and navigate commands and ``gym.make``; every hostile plug-in gives one ``PluginError`` naming its spec."""

from __future__ import annotations

import itertools
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.predictors import predict_futures
from predictor.plugins import PluginError, PluginPredictor, load_plugin
from predictor.registry import make_predictor
from replays import load_windows
from replays.constants import T_PRED
from st_sim.apps.cli import main
from st_sim.apps.navigation.planners import make_planner
from st_sim.apps.navigation.predictors import env_predictor
from st_sim.apps.navigation.world import world_of

REPO = Path(__file__).resolve().parents[1]
KNN = "examples.knn_predictor:make"
LIGHT = ("domain", "A2B")  # the smallest training split: a plug-in loads in milliseconds
MODULE_NUMBERS = itertools.count()  # every throwaway module gets a new name (imports are cached per name)
HOSTILE = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def run_cli(*args: str) -> subprocess.CompletedProcess:
    """``python -m st_sim ARGS`` from the repository root, as a user runs it (the root is then on sys.path)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "st_sim", *args], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=600)


def write_plugin(folder: Path, source: str, attr: str = "make") -> str:
    """Write a throwaway module into ``folder`` (on sys.path); returns its spec ``module:attr``."""
    import importlib

    name = f"stcrowd_plugin_{os.getpid()}_{next(MODULE_NUMBERS)}"
    (folder / f"{name}.py").write_text("import numpy as np\n" + source)
    importlib.invalidate_caches()  # the import system caches folder listings
    return f"{name}:{attr}"


def test_a_factory_without_a_seed_parameter_is_called_without_one(plugin_dir: Path) -> None:
    spec = write_plugin(plugin_dir, "class P:\n    def predict(self, obs, group, scene, num_samples):\n"
                        "        return np.repeat(obs[:, None, -1:], num_samples, 1).repeat(12, 2)\n"
                        "def make(task, scene, train, val, data_root):\n    return P()\n")
    assert load_plugin(spec, *LIGHT, seed=3).predict(np.zeros((1, 8, 2)), np.zeros(1, np.int64), None, 2).shape \
        == (1, 2, 12, 2)


@pytest.fixture
def plugin_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def best_of_s(pred: np.ndarray, fut: np.ndarray) -> tuple[float, float]:
    """Mean best-of-S ADE and FDE [m], computed here without the project's metrics."""
    dist = np.sqrt(((pred.astype(np.float64) - fut[:, None].astype(np.float64)) ** 2).sum(axis=-1))  # (N, S, 12)
    return float(dist.mean(axis=2).min(axis=1).mean()), float(dist[:, :, -1].min(axis=1).mean())


def test_example_plugin_through_evaluate_scores_what_numpy_scores(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "res.json"
    """The factory takes ``seed``, so ``--seeds 0 1`` builds it twice: each seed's row is the independent figure."""
    done = run_cli("evaluate", "--task", "stochastic", "--scenes", "eth", "hotel", "--predictor", KNN, "--seeds", "0",
                   "1", "--runs", str(tmp_path / "runs"), "--json", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    assert f"predictor `{KNN}`" in done.stdout and "| eth | 181 |" in done.stdout
    result = json.loads(out.read_text())
    assert result["predictor"] == KNN
    monkeypatch.syspath_prepend(str(REPO))
    from examples.knn_predictor import MAX_TRAIN_WINDOWS, make
    for scene in ("eth", "hotel"):
        train, val = (load_windows("stochastic", scene, split) for split in ("train", "val"))
        test = load_windows("stochastic", scene, "test")
        row = result["scenes"][scene]
        assert row["samples"] == len(test), scene
        assert len(train) > MAX_TRAIN_WINDOWS, f"{scene}: the seed must choose a subsample for this test to mean much"
        per_seed = []
        for seed in (0, 1):
            model = make(task="stochastic", scene=scene, train=train, val=val, data_root=None, seed=seed)
            ade, fde = best_of_s(model.predict(test.obs, test.group, None, 20), test.fut)
            cell = row["seeds"][str(seed)]
            assert abs(cell["ade"] - ade) < 1e-4 and abs(cell["fde"] - fde) < 1e-4, (scene, seed, cell, ade, fde)
            assert cell["stream_samples"] is not None, f"{scene}: the env's replay must agree with the windows"
            per_seed.append(fde)
        assert per_seed[0] != per_seed[1], f"{scene}: two seeds, two subsamples, two figures"
        assert row["stream_checked"], scene
        assert abs(row["fde"] - sum(per_seed) / 2) < 1e-4, (scene, row["fde"], per_seed)


def test_example_plugin_drives_the_mpc_through_navigate(tmp_path: Path) -> None:
    done = run_cli("navigate", "--env", "STCrowd-Zara1-v0", "--policy", "mpc", "--predictor", KNN, "--episodes", "2",
                   "--quiet", "--json", str(tmp_path / "nav.json"))
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "nav.json").read_text())
    assert result["predictor"] == KNN and len(result["episodes"]) == 2


RECORDER = """
CALLS = []

class Still:
    def predict(self, obs, group, scene, num_samples):
        return np.repeat(obs[:, None, -1:], num_samples, axis=1).repeat(12, axis=2).astype(np.float32)

def make(**kwargs):
    CALLS.append(kwargs)
    return Still()
"""


@pytest.mark.parametrize(("env_id", "task", "scene", "windows_of"),
                         [("STCrowd-Zara1-v0", "stochastic", "zara1", "zara1"),
                          ("STCrowd-Hotel-v0", "momentary", "hotel", "hotel"),
                          ("STCrowd-SimCorridor-v1", "stochastic", None, "all")])
def test_env_calls_the_factory_with_its_task_scene_and_windows(plugin_dir: Path, env_id: str, task: str,
                                                               scene: str | None, windows_of: str) -> None:
    spec = write_plugin(plugin_dir, RECORDER)
    env = gym.make(env_id, predictor=spec, task=task)
    obs, _ = env.reset(seed=0)
    (call,) = sys.modules[spec.partition(":")[0]].CALLS
    assert set(call) == {"task", "scene", "train", "val", "data_root"}
    assert (call["task"], call["scene"]) == (task, scene)
    assert (call["train"].scene, call["train"].split, call["val"].split) == (windows_of, "train", "val")
    assert call["train"].obs.shape[1] == (2 if task == "momentary" else 8)
    rows = obs["futures_mask"]
    assert rows.any() and np.allclose(obs["futures"][rows][:, :, -1], obs["history"][rows][:, None, -1])
    assert world_of(env).sample_prior is None, "a plug-in's samples count equally"


def test_navigation_helpers_take_a_spec_and_check_it(plugin_dir: Path) -> None:
    spec = write_plugin(plugin_dir, RECORDER)
    assert env_predictor(spec) == spec
    env = gym.make("STCrowd-SimCorridor-v1", predictor=env_predictor(spec))
    assert make_planner("mpc", world_of(env), spec) is not None
    with pytest.raises(PluginError, match="no_such_module_here"):
        env_predictor("no_such_module_here:make")


# hostile plug-ins: (module source, attribute) -> PluginError naming the spec ---------------------------------------

EXCEPTIONS = st.sampled_from(["ValueError", "RuntimeError", "KeyError", "ZeroDivisionError", "TypeError",
                              "MemoryError", "SystemExit"])
NOT_CALLABLE = st.one_of(st.integers(), st.text(max_size=5), st.none(), st.lists(st.integers(), max_size=3),
                         st.floats(allow_nan=True))


@st.composite
def bad_factories(draw) -> tuple[str, str]:
    """(module source, attribute): a module whose factory cannot give a predictor."""
    kind = draw(st.sampled_from(["syntax", "import raises", "missing import", "no attribute", "not callable",
                                 "factory raises", "wrong signature", "no predict", "predict not callable"]))
    if kind == "syntax":
        return "def make(:\n", "make"
    if kind == "import raises":
        return f"raise {draw(EXCEPTIONS)}('at import')\n", "make"
    if kind == "missing import":
        return "import stcrowd_no_such_dependency\ndef make(**kw):\n    return None\n", "make"
    if kind == "no attribute":
        return "def make(**kw):\n    return None\n", draw(st.sampled_from(["nothere", "make.nothere", "Make"]))
    if kind == "not callable":
        return f"make = {draw(NOT_CALLABLE)!r}\n", "make"
    if kind == "factory raises":
        return f"def make(**kw):\n    raise {draw(EXCEPTIONS)}('no model')\n", "make"
    if kind == "wrong signature":
        return "def make(task, scene):\n    return None\n", "make"
    if kind == "no predict":
        value = draw(st.sampled_from(["None", "3", "'predict'", "{}", "object()", "[1, 2]"]))
        return f"def make(**kw):\n    return {value}\n", "make"
    return f"class M:\n    predict = {draw(NOT_CALLABLE)!r}\ndef make(**kw):\n    return M()\n", "make"


@HOSTILE
@given(bad=bad_factories())
def test_a_factory_that_cannot_give_a_predictor_raises_plugin_error_naming_the_spec(plugin_dir: Path, bad) -> None:
    spec = write_plugin(plugin_dir, *bad)
    with pytest.raises(PluginError) as caught:
        load_plugin(spec, *LIGHT)
    assert repr(spec) in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.parametrize("spec", ["stcrowd_missing_module:make", "stcrowd_missing.deeper:make", "a:b:c",
                                  "1module:make", "module:", ":make", "mod:ma ke", "mod-name:make"])
def test_a_spec_that_does_not_import_raises_plugin_error_naming_it(spec: str) -> None:
    with pytest.raises(PluginError, match=re.escape(f"predictor {spec!r}")):
        make_predictor(spec, *LIGHT)


@st.composite
def bad_outputs(draw) -> str:
    """The body of a ``predict`` (``obs``, ``num_samples`` in scope; ``good`` the right answer) that is wrong."""
    kind = draw(st.sampled_from(["shape", "samples", "nan", "list", "none", "scalar", "int", "object", "complex",
                                 "raises", "tuple"]))
    if kind == "shape":
        shape = draw(st.lists(st.integers(0, 13), min_size=1, max_size=5).filter(lambda s: len(s) != 4 or s[2:] !=
                                                                                   [12, 2]))
        return f"return np.zeros({tuple(shape)!r}, np.float32)"
    if kind == "samples":
        return f"return np.zeros((len(obs), num_samples + {draw(st.integers(1, 5))}, 12, 2), np.float32)"
    if kind == "nan":
        value = draw(st.sampled_from(["np.nan", "np.inf", "-np.inf", "1e300"]))
        where = draw(st.integers(0, 10**6))
        dtype = "np.float64" if value == "1e300" else draw(st.sampled_from(["np.float32", "np.float64"]))
        return f"out = good.astype({dtype}); out.flat[{where} % out.size] = {value}; return out"
    return {"list": "return good.tolist()", "none": "return None", "scalar": "return 0.0",
            "int": "return good.astype(np.int64)", "object": "return good.astype(object)",
            "complex": "return good.astype(np.complex64)", "raises": "raise RuntimeError('predict failed')",
            "tuple": "return (good, good)"}[kind]


PREDICTOR_TEMPLATE = """
class Bad:
    def predict(self, obs, group, scene, num_samples):
        good = np.zeros((len(obs), num_samples, 12, 2), np.float32)
        {body}

def make(**kw):
    return Bad()
"""


@HOSTILE
@given(body=bad_outputs(), agents=st.integers(1, 6), samples=st.sampled_from([1, 20]))
def test_a_predict_with_a_wrong_output_raises_plugin_error_naming_the_spec(plugin_dir: Path, body: str, agents: int,
                                                                           samples: int) -> None:
    spec = write_plugin(plugin_dir, PREDICTOR_TEMPLATE.format(body=body))
    model = load_plugin(spec, *LIGHT)
    obs = np.cumsum(np.full((agents, 8, 2), 0.4, np.float32), axis=1)
    with pytest.raises(PluginError) as caught:
        model.predict(obs, np.zeros(agents, np.int64), None, samples)
    message = str(caught.value)
    assert repr(spec) in message and "\n" not in message
    assert "raise" in body or f"(N, S, 12, 2) = ({agents}, {samples}, {T_PRED}, 2)" in message
    with pytest.raises(PluginError, match=re.escape(repr(spec))):  # the env's prediction step
        predict_futures(model, obs, None, samples)


def test_a_good_plugin_passes_the_same_checks_and_cannot_touch_the_callers_arrays(plugin_dir: Path) -> None:
    spec = write_plugin(plugin_dir, """
class Good:
    def predict(self, obs, group, scene, num_samples):
        obs -= 100.0  # in place: must not reach the caller
        return np.zeros((len(obs), num_samples, 12, 2), np.float64)

def make(**kw):
    return Good()
""")
    model = load_plugin(spec, *LIGHT)
    assert isinstance(model, PluginPredictor) and model.name == spec
    obs = np.ones((3, 8, 2), np.float32)
    futures = model.predict(obs, np.zeros(3, np.int64), None, 20)
    assert futures.dtype == np.float32 and futures.shape == (3, 20, T_PRED, 2)
    assert (obs == 1.0).all(), "the caller's observations were changed"


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(body=bad_outputs())
def test_the_plot_command_prints_one_error_line_naming_the_spec(plugin_dir: Path, capsys, body: str) -> None:
    spec = write_plugin(plugin_dir, PREDICTOR_TEMPLATE.format(body=body))
    assert main(["plot", "--scene", "hotel", "--step", "3", "--predictor", spec, "--out",
                 str(plugin_dir / "fig.png")]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: predictor {spec!r}") and err.count("\n") == 1, err


@pytest.mark.parametrize("source", ["def make(**kw):\n    raise KeyError('weights.pt')\n",
                                    PREDICTOR_TEMPLATE.format(body="return good + np.nan"),
                                    "import stcrowd_no_such_dependency\n"], ids=["factory", "predict", "import"])
def test_evaluate_prints_one_error_line_naming_the_spec(plugin_dir: Path, capsys, source: str) -> None:
    spec = write_plugin(plugin_dir, source)
    runs = plugin_dir / "runs"
    assert main(["evaluate", "--task", "deterministic", "--scenes", "eth", "--predictor", "cvm", spec,
                 "--no-stream", "--quiet", "--workers", "1", "--runs", str(runs)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: predictor {spec!r}") and err.count("\n") == 1, err
    if "import" in source:
        assert not runs.exists(), "a spec that does not import must fail before any work"


@pytest.mark.parametrize("env_id", ["STCrowd-Zara1-v0", "STCrowd-SimCorridor-v1"])
def test_gym_make_with_a_failing_factory_raises_plugin_error_naming_the_spec(plugin_dir: Path, env_id: str) -> None:
    spec = write_plugin(plugin_dir, "def make(task, scene, train, val, data_root):\n    return object()\n")
    with pytest.raises(PluginError, match=re.escape(f"predictor {spec!r}") + ".*without a callable predict"):
        gym.make(env_id, predictor=spec)


def test_navigate_prints_one_error_line_naming_the_spec(plugin_dir: Path, capsys) -> None:
    spec = write_plugin(plugin_dir, PREDICTOR_TEMPLATE.format(body="return good[:, :1]"))
    assert main(["navigate", "--env", "STCrowd-SimCorridor-v1", "--policy", "straight", "--predictor", spec,
                 "--episodes", "1", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: predictor {spec!r}") and err.count("\n") == 1, err


COUNTER = """
import os

class Still:
    def predict(self, obs, group, scene, num_samples):
        return np.repeat(obs[:, None, -1:], num_samples, axis=1).repeat(12, axis=2).astype(np.float32)

def make(**kwargs):
    with open(os.environ["STCROWD_TEST_BUILDS"], "a") as out:
        out.write("built\\n")
    return Still()
"""


def test_a_plugins_cells_are_evaluated_afresh_on_every_run(plugin_dir: Path, tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/plugins.md: STCrowd cannot tell whether the code or weights behind a spec changed, so a plug-in's cells
    are evaluated again by every run into the same ``--runs`` folder (a shipped predictor's are kept)."""
    builds = tmp_path / "builds.txt"
    monkeypatch.setenv("STCROWD_TEST_BUILDS", str(builds))
    spec = write_plugin(plugin_dir, COUNTER)
    command = ["evaluate", "--task", LIGHT[0], "--scenes", LIGHT[1], "--no-stream", "--quiet", "--workers", "1",
               "--runs", str(tmp_path / "runs")]
    for run in (1, 2):
        assert main([*command, "--predictor", spec]) == 0
        assert builds.read_text().count("built") == run, f"run {run}: the plug-in's cell was not evaluated again"
    assert main([*command, "--predictor", "cvm"]) == 0
    cells = sorted((tmp_path / "runs" / "evaluations").rglob("cvm-*.json"))
    stamps = [cell.stat().st_mtime_ns for cell in cells]
    assert cells and main([*command, "--predictor", "cvm"]) == 0
    assert [cell.stat().st_mtime_ns for cell in cells] == stamps, "a shipped predictor's cell is kept"
