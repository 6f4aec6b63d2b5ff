"""Hostile env inputs: configs, constructor arguments, reset options, actions, misuse, placement, vector envs.

Every input either works (and the observation stays inside ``observation_space``) or raises the env's own
error naming the field at fault, before anything in the env changes.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st
from test_data_root import linked_layout  # a data root of symlinks into the shared folder

import envs  # noqa: F401  (registers the ids)
from envs.common.config import EnvConfig, RewardWeights
from envs.common.ego import on_image
from envs.common.errors import (
    ActionError,
    ConfigError,
    EgoPlacementError,
    EnvInputError,
    NeedsResetError,
    ResetOptionsError,
)
from replays import RecordingError, UnknownNameError, data_root
from replays.constants import POSITION_LIMIT_M

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
ENV_IDS = ("STCrowd-Zara1-v0", "STCrowd-SimCorridor-v1")

ANYTHING = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(), st.complex_numbers(), st.text(max_size=5),
    st.lists(st.integers(0, 3), max_size=3), st.sampled_from([np.float32(0.5), np.int64(3), np.bool_(True)]),
)


def unwrapped(env_id: str, **kwargs) -> gym.Env:
    """The bare env (no gymnasium wrappers, so nothing but the env checks the input), CVM predictor."""
    return gym.make(env_id, predictor="cvm", **kwargs).unwrapped


@pytest.fixture(scope="module")
def bare_envs() -> dict[tuple[str, bool], gym.Env]:
    made = {(env_id, ego): unwrapped(env_id, ego=ego) for env_id in ENV_IDS for ego in (True, False)}
    made[("STCrowd-Eth-v0", True)] = unwrapped("STCrowd-Eth-v0")  # projective scene: its image is a trapezoid
    yield made
    for env in made.values():
        env.close()


# ---------------------------------------------------------------- config dataclasses

RANGES = {"ego_radius_m": (0, 5, True), "pedestrian_radius_m": (0, 5, True),
          "goal_radius_m": (0, 100, True), "spawn_clearance_m": (0, 100, False), "goal_min_fraction": (0, 1, False),
          "arena_margin_m": (0, 100, False)}


def accepted(value, low: float, high: float, low_open: bool) -> bool:
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.integer | np.floating):
        return False
    return (low < value if low_open else low <= value) and value <= high


@SETTINGS
@given(name=st.sampled_from(sorted(RANGES)), value=ANYTHING)
def test_env_config_accepts_in_range_numbers_and_names_any_other_field_value(name: str, value) -> None:
    low, high, low_open = RANGES[name]
    if accepted(value, low, high, low_open):
        assert getattr(EnvConfig(**{name: value}), name) == float(value)
        return
    with pytest.raises(ConfigError) as err:
        EnvConfig(**{name: value})
    message = str(err.value)
    assert f"EnvConfig.{name}=" in message and f"{low:g}, {high:g}" in message, message


@SETTINGS
@given(name=st.sampled_from([f.name for f in fields(RewardWeights)]), value=ANYTHING)
def test_reward_weights_accept_finite_numbers_and_name_any_other(name: str, value) -> None:
    if accepted(value, -1e6, 1e6, low_open=False):
        assert getattr(RewardWeights(**{name: value}), name) == float(value)
        return
    with pytest.raises(ConfigError, match=f"RewardWeights.{name}="):
        RewardWeights(**{name: value})


def test_env_config_reward_must_be_reward_weights() -> None:
    with pytest.raises(ConfigError, match=r"EnvConfig\.reward"):
        EnvConfig(reward={"goal": 1.0})


@pytest.mark.parametrize("kwargs, error, field", [
    ({"ego": "no"}, EnvInputError, "ego="), ({"ego": 1}, EnvInputError, "ego="),
    ({"config": {"ego_radius_m": 1.0}}, ConfigError, "config="), ({"robot": "tank"}, EnvInputError, "robot="),
    ({"rerun": 5}, EnvInputError, "rerun="),
    ({"render_mode": "ansi"}, EnvInputError, "render_mode="), ({"task": "fewshot"}, ValueError, "task="),
    ({"scene": "mars"}, UnknownNameError, "mars"), ({"recording": 5}, EnvInputError, "recording="),
    ({"benchmark_windows": "yes", "ego": False}, EnvInputError, "benchmark_windows="),
    ({"benchmark_windows": True}, EnvInputError, "benchmark_windows"),
], ids=["ego-str", "ego-int", "config-dict", "robot-unknown", "rerun-int", "render-ansi", "task", "scene",
        "recording-int", "benchmark-str", "benchmark-with-ego"])
def test_replay_constructor_arguments_are_checked(kwargs: dict, error: type, field: str) -> None:
    with pytest.raises(error, match=field):
        gym.make("STCrowd-Zara1-v0", predictor="cvm", **kwargs)


# ---------------------------------------------------------------- reset options

@SETTINGS
@given(key=st.sampled_from(["start_index", "seed", "bogus", "ego_start"]), value=ANYTHING)
def test_reset_options_take_only_known_keys_and_int_start_index(bare_envs, key: str, value) -> None:
    for env_id in ENV_IDS:
        env = bare_envs[(env_id, True)]
        last = len(env.replay.frames) - 1 if hasattr(env, "replay") else 0
        valid = (key in env.RESET_OPTIONS and isinstance(value, int | np.integer)
                 and not isinstance(value, bool | np.bool_) and 0 <= value < last)
        if valid:
            _, info = env.reset(options={key: value})
            assert info["frame"] == int(env.replay.frames[value]), f"[{env_id}] start_index {value}"
            continue
        with pytest.raises(ResetOptionsError, match=key) as err:
            env.reset(options={key: value})
        assert repr(value)[:10] in str(err.value) or key not in env.RESET_OPTIONS, str(err.value)


@pytest.mark.parametrize("options", [[("start_index", 3)], "start_index", 5], ids=["list", "str", "int"])
def test_reset_options_must_be_a_dict(bare_envs, options) -> None:
    with pytest.raises(ResetOptionsError, match="must be a dict"):
        bare_envs[("STCrowd-Zara1-v0", True)].reset(options=options)


@pytest.mark.parametrize("bad", [{"options": {"start_index": 10**9}}, {"options": {"bogus": 1}}, {"seed": -1},
                                 {"seed": "5"}, {"seed": 2.5}],
                         ids=["range", "key", "seed-neg", "seed-str", "seed-float"])
def test_refused_reset_leaves_the_episode_running(bad: dict) -> None:
    env = unwrapped("STCrowd-Zara1-v0", ego=False)
    _, info = env.reset(seed=0, options={"start_index": 100})
    with pytest.raises(EnvInputError):
        env.reset(**bad)
    _, _, _, _, info = env.step(np.zeros(2))
    assert info["frame"] == int(env.replay.frames[101]), "the refused reset changed the episode"


# ---------------------------------------------------------------- actions

def action_strategy() -> st.SearchStrategy:
    finite = st.floats(-1e300, 1e300, allow_nan=False)
    return st.one_of(
        st.tuples(finite, finite).map(np.array),
        st.tuples(st.floats(), st.floats()).map(np.array),
        st.tuples(st.integers(-(2**40), 2**40), st.integers(-(2**40), 2**40)).map(list),
        st.tuples(st.complex_numbers(), st.complex_numbers()).map(np.array),
        st.tuples(st.booleans(), st.booleans()).map(np.array),
        st.tuples(st.text(max_size=3), st.text(max_size=3)).map(np.array),
        st.lists(finite, max_size=4).map(np.array),
        st.lists(st.lists(finite, min_size=2, max_size=2), min_size=1, max_size=2).map(np.array),
        ANYTHING,
        st.just([[1.0], [2.0, 3.0]]),
        st.just(np.array([0.5, 0.5], dtype=object)),
    )


def is_valid_action(action, ego: bool) -> bool:
    try:
        array = np.asarray(action)
    except (ValueError, TypeError):
        return False
    if array.dtype.kind not in "iuf" or array.shape != (2,):
        return False
    return not ego or bool(np.isfinite(array.astype(np.float64)).all())


@pytest.mark.parametrize("env_id", ENV_IDS, ids=ENV_IDS)
@pytest.mark.parametrize("ego", [True, False], ids=["ego", "spectator"])
@SETTINGS
@given(action=action_strategy())
def test_any_action_steps_inside_the_space_or_raises_action_error(bare_envs, env_id: str, ego: bool, action) -> None:
    env = bare_envs[(env_id, ego)]
    _, info = env.reset(seed=0)
    ego_xy_m = env.ego_xy_m.copy()
    if not is_valid_action(action, ego):
        with pytest.raises(ActionError, match="action"):
            env.step(action)
        assert env.tracks.now.frame == info["frame"] and np.array_equal(env.ego_xy_m, ego_xy_m), "refused, yet moved"
        return
    obs, reward, *_ = env.step(action)
    assert env.observation_space.contains(obs), f"observation left its space after action {action!r}"
    assert np.isfinite(reward)


def test_refused_action_leaves_no_trace() -> None:
    clean, attacked = unwrapped("STCrowd-Zara1-v0"), unwrapped("STCrowd-Zara1-v0")
    clean.reset(seed=4)
    attacked.reset(seed=4)
    for t, bad in enumerate([np.array([np.nan, 0.0]), np.array([1j, 0]), "go", [True, False], np.zeros(3)]):
        with pytest.raises(ActionError):
            attacked.step(bad)
        obs_a, reward_a, *_ = clean.step(np.array([1.0, 0.5]))
        obs_b, reward_b, *_ = attacked.step(np.array([1.0, 0.5]))
        assert reward_a == reward_b and all(np.array_equal(obs_a[k], obs_b[k]) for k in obs_a), f"[step {t}]"


# ---------------------------------------------------------------- misuse: order of calls

@pytest.mark.parametrize("env_id", ENV_IDS, ids=ENV_IDS)
def test_step_before_reset_is_an_error(env_id: str) -> None:
    env = unwrapped(env_id)
    with pytest.raises(NeedsResetError, match="reset"):
        env.step(np.zeros(2))


def test_step_after_the_recording_ended_is_an_error_and_keeps_the_index(bare_envs) -> None:
    env = bare_envs[("STCrowd-Zara1-v0", False)]
    last = len(env.replay.frames) - 1
    env.reset(options={"start_index": last - 1})
    *_, truncated, _ = env.step(np.zeros(2))
    assert truncated and env.index == last
    for _ in range(2):
        with pytest.raises(NeedsResetError, match="ended"):
            env.step(np.zeros(2))
    assert env.index == last, "a refused step moved the recording index"


def test_step_after_termination_is_an_error(bare_envs) -> None:
    env = bare_envs[("STCrowd-Zara1-v0", True)]
    env.reset(seed=0)
    env.goal_m = env.ego_xy_m + np.array([0.3, 0.0])
    *_, terminated, _, _ = env.step(np.zeros(2))
    assert terminated
    with pytest.raises(NeedsResetError):
        env.step(np.zeros(2))
    env.reset(seed=0)
    env.step(np.zeros(2))  # usable again after reset


MISUSE_UNDER_O = """
import gymnasium as gym, numpy as np, envs
from envs.common.errors import NeedsResetError
env = gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False).unwrapped
try:
    env.step(np.zeros(2))
except NeedsResetError:
    print("before reset: refused")
n = len(env.replay.frames)
env.reset(options={"start_index": n - 2})
env.step(np.zeros(2))
try:
    env.step(np.zeros(2))
except NeedsResetError:
    print("past the end: refused at index", env.index, "of", n)
"""


def test_misuse_is_refused_under_python_optimised_mode() -> None:
    out = subprocess.run([sys.executable, "-O", "-c", MISUSE_UNDER_O], capture_output=True, text=True, check=True)
    lines = out.stdout.strip().splitlines()
    assert lines[0] == "before reset: refused", out
    assert lines[1].startswith("past the end: refused at index") and lines[1].split()[-3] == str(
        int(lines[1].split()[-1]) - 1), out


# ---------------------------------------------------------------- ego placement

@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(heading=st.floats(0, 2 * np.pi), seed=st.integers(0, 5))
def test_replay_ego_never_leaves_the_image(bare_envs, heading: float, seed: int) -> None:
    env = bare_envs[("STCrowd-Eth-v0", True)]
    env.reset(seed=seed)
    action = 1.5 * np.array([np.cos(heading), np.sin(heading)])
    for t in range(60):
        obs, _, terminated, truncated, _ = env.step(action)
        assert on_image(env.scene, env.ego_xy_m), f"[step {t}] ego left the image at {env.ego_xy_m}"
        assert env.observation_space.contains(obs), f"[step {t}]"
        if terminated or truncated:
            env.reset(seed=seed)


def test_ego_placed_off_the_map_is_an_error(bare_envs) -> None:
    env = bare_envs[("STCrowd-Zara1-v0", True)]
    env.reset(seed=0)
    env.ego_xy_m = np.array([500.0, 500.0])
    with pytest.raises(EgoPlacementError, match="off the scene's image"):
        env.step(np.zeros(2))
    saved = env.candidates_m
    try:
        env.candidates_m = np.array([[500.0, 500.0]])  # a spawn point off the map
        with pytest.raises(EgoPlacementError, match="start"):
            env.reset(seed=0)
    finally:
        env.candidates_m = saved
    env.reset(seed=0)


# ---------------------------------------------------------------- metrics over nothing

def test_metrics_over_nothing_are_none_and_json_null(bare_envs) -> None:
    env = bare_envs[("STCrowd-Zara1-v0", False)]
    _, info = env.reset(seed=0)
    metrics = info["metrics"]
    assert metrics["matured"] == 0 and metrics["ade_m"] is None and metrics["fde_m"] is None
    assert json.loads(json.dumps(dict(metrics)))["ade_m"] is None
    for _ in range(14):
        _, _, _, _, info = env.step(np.zeros(2))
    assert info["metrics"]["matured"] > 0 and info["metrics"]["ade_m"] > 0


# ---------------------------------------------------------------- vector envs

@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_env_reraises_the_envs_own_error(mode: str) -> None:
    vec = gym.make_vec("STCrowd-SimCorridor-v1", num_envs=2, vectorization_mode=mode, predictor="cvm")
    try:
        vec.reset(seed=[0, 1])
        for _ in range(3):
            _, _, _, _, infos = vec.step(np.zeros((2, 2), np.float32))
        # one Metrics per env in an object array: an env's None never meets another's float in a float array
        assert infos["metrics"].dtype == object and infos["metrics"][0]["ade_m"] is None
        bad = np.zeros((2, 2), np.float32)
        bad[1, 0] = np.nan
        with pytest.raises(ActionError, match="finite"):
            vec.step(bad)
        if mode == "sync":  # the env refused the action before changing: the vector env goes on
            vec.step(np.zeros((2, 2), np.float32))
    finally:
        vec.close()


# ---------------------------------------------------------------- replays of hostile recordings

ZARA1_TEST = "zara1/test/crowds_zara01.txt"


@pytest.fixture(scope="module")
def own_root(tmp_path_factory) -> Path:
    """A data root whose ZARA1 test recording each example replaces, accepted as modified on purpose."""
    root = linked_layout(tmp_path_factory.mktemp("own") / "root")
    (root / ZARA1_TEST).unlink()
    (root / ZARA1_TEST).write_text("0\t1\t1.0\t1.0\n10\t1\t1.0\t1.0\n")
    data_root(root, verify=False)  # prints a warning naming the file
    return root


@st.composite
def recordings(draw) -> str:
    """A recording text: mostly valid rows (far-away, crowded, sparse), sometimes one broken row."""
    n_frames, n_agents = draw(st.integers(1, 30)), draw(st.integers(1, 12))
    centre = draw(st.tuples(st.floats(-900, 900), st.floats(-900, 900)) | st.just((5.0, 5.0)))
    rows = []
    for frame in range(n_frames):
        for agent in draw(st.sets(st.integers(0, n_agents), max_size=n_agents)):
            x, y = (np.clip(c + draw(st.floats(-50, 50)), -POSITION_LIMIT_M, POSITION_LIMIT_M) for c in centre)
            rows.append(f"{10 * frame}\t{agent * 1000}\t{x:.4f}\t{y:.4f}")
    if rows and draw(st.integers(0, 4)) == 4:
        rows[draw(st.integers(0, len(rows) - 1))] = draw(st.sampled_from(["0\t-1\t1\t1", "nan 1 1 1", "0 1 2"]))
    return "\n".join(rows) + "\n"


FAST_WALKER = "".join(f"{10 * f}\t0\t0.0\t0.0\n" for f in range(6)) + "60\t0\t0.0\t-48.0\n70\t0\t0.0\t33.0\n"
"""81 m in one step, inside the recording bound: its constant-velocity forecast reaches 1005 m (found in CI)"""


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=recordings(), ego=st.booleans(), seed=st.integers(0, 3))
@example(text=FAST_WALKER, ego=False, seed=0)
def test_any_recording_replays_inside_the_space_or_is_refused_by_name(own_root: Path, text: str, ego: bool,
                                                                      seed: int) -> None:
    path = own_root / ZARA1_TEST
    (own_root / "new.tmp").write_text(text)
    os.replace(own_root / "new.tmp", path)  # a new file: the replay cache reads it again
    try:
        env = gym.make("STCrowd-Zara1-v0", root=own_root, predictor="cvm", ego=ego).unwrapped
        obs, info = env.reset(seed=seed)
    except RecordingError as err:
        assert str(err).startswith(str(path)), str(err)
        event("refused: recording")
        return
    except EgoPlacementError as err:  # ego mode: no walkable pixel inside the recorded area
        assert ego and "walkable" in str(err), str(err)
        event("refused: ego placement")
        return
    event(f"replayed, ego={ego}")
    env.action_space.seed(seed)
    for t in range(30):
        assert env.observation_space.contains(obs), f"[step {t}] observation left its space"
        assert (info["agent_ids"] >= -1).all() and np.array_equal(info["agent_ids"] >= 0, obs["history_mask"][:, -1])
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        if terminated or truncated:
            break
