"""Policies by spec (``--policy``): shipped names, package.module:name plug-ins and stable-baselines3 models; every
policy that cannot be built, or acts wrongly, gives one ``PolicyError`` naming it."""

from __future__ import annotations

import importlib
import itertools
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from st_sim.apps.cli import main
from st_sim.apps.navigation.policies import CheckedPolicy, PolicyError, check_policy_spec, load_policy
from st_sim.apps.navigation.world import world_of

MODULE_NUMBERS = itertools.count()  # every throwaway module gets a new name (imports are cached per name)
HOSTILE = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
ENV = "STCrowd-SimCorridor-v1"


@pytest.fixture
def plugin_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


@pytest.fixture(scope="module")
def corridor() -> gym.Env:
    return gym.make(ENV, predictor="none")


def write_policy(folder: Path, source: str, attr: str = "Policy") -> str:
    """A throwaway module in ``folder`` (on sys.path); returns its spec ``module:attr``."""
    name = f"stcrowd_policy_{os.getpid()}_{next(MODULE_NUMBERS)}"
    (folder / f"{name}.py").write_text("import numpy as np\n" + source)
    importlib.invalidate_caches()
    return f"{name}:{attr}"


def test_a_class_is_built_with_world_and_predictions_and_a_bare_factory_without(plugin_dir: Path,
                                                                               corridor: gym.Env) -> None:
    world = world_of(corridor)
    spec = write_policy(plugin_dir, "class Policy:\n    def __init__(self, world, use_predictions):\n"
                        "        self.args = (world, use_predictions)\n"
                        "    def act(self, obs):\n        return np.zeros(2)\n")
    assert load_policy(spec, world, "cvm").policy.args == (world, True)
    assert load_policy(spec, world, "none").policy.args == (world, False)
    bare = write_policy(plugin_dir, "class Walker:\n    def act(self, obs):\n        return [0.5, 0.0]\n"
                        "def make():\n    return Walker()\n", "make")
    policy = load_policy(bare, world)
    policy.reset()  # no reset of its own: nothing to call
    obs, _ = corridor.reset(seed=0)
    assert policy.act(obs).tolist() == [0.5, 0.0]


@pytest.mark.parametrize(("source", "attr", "message"), [
    ("raise RuntimeError('broken module')\n", "Policy", "importing .* raised RuntimeError: broken module"),
    ("x = 1\n", "Policy", "has no Policy"),
    ("Policy = 3\n", "Policy", "is a int, not a callable"),
    ("class Policy:\n    def __init__(self, a, b, c):\n        pass\n", "Policy", r"name\(world, use_predictions\)"),
    ("class Policy:\n    def __init__(self, world, use):\n        raise ValueError('no')\n", "Policy",
     "building it raised ValueError: no"),
    ("class Policy:\n    pass\n", "Policy", "without a callable act"),
    ("class Policy:\n    act = 5\n", "Policy", "without a callable act"),
], ids=["import-error", "missing", "not-callable", "signature", "raises", "no-act", "act-not-callable"])
def test_a_policy_that_cannot_be_built_names_its_spec(plugin_dir: Path, corridor: gym.Env, source: str, attr: str,
                                                     message: str) -> None:
    spec = write_policy(plugin_dir, source, attr)
    with pytest.raises(PolicyError, match=message) as caught:
        load_policy(spec, world_of(corridor))
    assert spec in str(caught.value)


@pytest.mark.parametrize("spec", ["nothing", "no_such_module_xyz:Policy", "sb3:/no/such/model.zip", "a b:c"])
def test_a_spec_that_names_nothing_is_refused_before_any_work(spec: str) -> None:
    with pytest.raises(PolicyError, match="policy"):
        check_policy_spec(spec)


ACTIONS = st.one_of(
    st.lists(st.floats(allow_nan=False, allow_infinity=False, width=32), min_size=0, max_size=5)
    .filter(lambda v: len(v) != 2).map(np.array),
    st.tuples(st.sampled_from([np.nan, np.inf, -np.inf]), st.floats(-2, 2)).map(list),
    st.sampled_from([None, "fast", {"vx": 1.0}, np.zeros((2, 1)), np.zeros((1, 2)), object()]),
)


@HOSTILE
@given(action=ACTIONS)
def test_an_action_that_is_not_two_finite_numbers_is_refused(corridor: gym.Env, action) -> None:
    class Returns:
        def act(self, obs):
            return action

    obs, _ = corridor.reset(seed=1)
    with pytest.raises(PolicyError, match=r"policy 'mine': act returned"):
        CheckedPolicy("mine", Returns()).act(obs)


@HOSTILE
@given(error=st.sampled_from([RuntimeError("boom"), KeyError("ego"), ZeroDivisionError(), SystemExit(3),
                              AssertionError("x")]))
def test_an_exception_inside_act_or_reset_becomes_a_policy_error(corridor: gym.Env, error: BaseException) -> None:
    class Raises:
        def reset(self):
            raise error

        def act(self, obs):
            raise error

    obs, _ = corridor.reset(seed=2)
    policy = CheckedPolicy("mine", Raises())
    with pytest.raises(PolicyError, match=f"act raised {type(error).__name__}"):
        policy.act(obs)
    with pytest.raises(PolicyError, match=f"reset raised {type(error).__name__}"):
        policy.reset()


def test_a_policy_cannot_touch_the_envs_observation(corridor: gym.Env) -> None:
    class Scribbles:
        def act(self, obs):
            for value in obs.values():
                value[...] = 0
            return np.zeros(2)

    obs, _ = corridor.reset(seed=3)
    kept = {key: value.copy() for key, value in obs.items()}
    CheckedPolicy("scribbles", Scribbles()).act(obs)
    assert all(np.array_equal(obs[key], kept[key]) for key in obs)


def test_an_sb3_model_acts_on_the_keys_it_was_trained_on_and_refuses_an_env_it_does_not_fit(tmp_path: Path) -> None:
    from stable_baselines3 import PPO

    env = gym.wrappers.FilterObservation(gym.make(ENV, predictor="none"), ["ego", "history", "history_mask"])
    PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, device="cpu").save(tmp_path / "raw.zip")
    spec = f"sb3:{tmp_path / 'raw.zip'}"
    corridor = gym.make(ENV, predictor="none")
    policy = load_policy(spec, world_of(corridor))
    policy.check_fits(corridor.observation_space, "corridor")
    obs, _ = corridor.reset(seed=0)
    assert policy.act(obs).shape == (2,)
    zara = gym.make("STCrowd-Zara1-v0", predictor="none")
    with pytest.raises(PolicyError, match="does not fit scenario 'zara1-log'") as caught:
        policy.check_fits(zara.observation_space, "zara1-log")
    assert "(20, 8, 2)" in str(caught.value) and "(40, 8, 2)" in str(caught.value), "both spaces are named"
    (tmp_path / "junk.zip").write_bytes(b"not a zip")
    with pytest.raises(PolicyError, match="not a stable-baselines3 model"):
        load_policy(f"sb3:{tmp_path / 'junk.zip'}", world_of(corridor))


def test_navigate_runs_a_plug_in_policy_and_names_a_broken_one(plugin_dir: Path, capsys) -> None:
    good = write_policy(plugin_dir, "class Policy:\n    def act(self, obs):\n"
                        "        return obs['ego'][4:6] - obs['ego'][:2]\n")
    assert main(["navigate", "--env", ENV, "--policy", good, "--predictor", "none", "--episodes", "1",
                 "--quiet"]) == 0
    bad = write_policy(plugin_dir, "class Policy:\n    def act(self, obs):\n        return np.zeros(3)\n")
    assert main(["navigate", "--env", ENV, "--policy", bad, "--predictor", "none", "--episodes", "1",
                 "--quiet"]) == 1
    assert f"policy {bad!r}: act returned shape (3,)" in capsys.readouterr().err
