"""The suite's train split and the suite env ``STCrowd-Suite-v1``: train seeds never val or test ones, a scenario per
episode through one fixed-size view, deterministic for a seed, ``check_env``, a sync vector env, SB3 training on it,
and hostile keywords refused in one line."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs
from envs.common.errors import EnvInputError, NeedsResetError, ResetOptionsError
from envs.suite import LISTED_SPLITS, SPLITS, SuiteError, TrainSeeds, load_suite
from envs.view import view_sizes

SUITE = load_suite()
LISTED = set(SUITE.seeds["val"]) | set(SUITE.seeds["test"])
SIMULATED = ["doorway", "sim-corridor"]  # two scenarios that need no data, for the quick tests
ACTION_SPACE_ADVICE = ".*symmetric and normalized.*"  # the action is a velocity in m/s, on purpose


def test_the_published_lists_are_still_the_ones_drawn_once() -> None:
    """The train rule came later: the val and test episodes, and so the version and every committed result, are
    those of suite stcrowd-nav 1.0 as first published."""
    drawn = np.random.default_rng(20261127).choice(2**31 - 1, 2000, replace=False).tolist()
    assert (SUITE.name, SUITE.version) == ("stcrowd-nav", "1.0")
    assert list(SUITE.seeds["val"]) == drawn[:1000] and list(SUITE.seeds["test"]) == drawn[1000:]
    assert ("train", *LISTED_SPLITS) == SPLITS and (SUITE.train.first, SUITE.train.below) == (0, 2**31 - 1)


@settings(max_examples=60, deadline=None)
@given(draw_seed=st.integers(0, 2**32 - 1), episodes=st.integers(1, 3000))
def test_train_seeds_are_never_val_or_test_seeds(draw_seed: int, episodes: int) -> None:
    rng = np.random.default_rng(draw_seed)
    drawn = [SUITE.draw_seed("train", rng) for _ in range(20)]
    assert not set(drawn) & LISTED and all(0 <= s < 2**31 - 1 for s in drawn)
    first = SUITE.seeds_of("train", episodes)
    assert len(set(first)) == episodes and list(first) == sorted(first) and not set(first) & LISTED
    assert SUITE.seeds_of("train", 1) == (0,), "the rule's seeds in increasing order"


@settings(max_examples=80, deadline=None)
@given(first=st.integers(0, 40), length=st.integers(1, 60), listed=st.sets(st.integers(0, 120), max_size=40))
def test_the_train_rule_holds_exactly_the_range_without_the_lists(first: int, length: int, listed: set) -> None:
    below = first + length
    inside = tuple(sorted(v for v in listed if first <= v < below))
    expected = [s for s in range(first, below) if s not in listed]
    rule = TrainSeeds(first, below, inside)
    assert rule.count == len(expected)
    assert rule.nth(np.arange(rule.count)).tolist() == expected


RULES = {"list": [1, 2], "no below": {"from": 0}, "reversed": {"from": 5, "below": 5}, "negative": {"from": -1,
         "below": 9}, "text": {"from": "0", "below": 9}, "bool": {"from": False, "below": 9},
         "extra key": {"from": 0, "below": 9, "step": 2}, "past 2^63": {"from": 0, "below": 2**63 + 1}}


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(sorted(RULES)))
def test_a_train_rule_that_is_not_a_range_is_refused_naming_the_file(tmp_path: Path, name: str) -> None:
    raw = json.loads(SUITE.path.read_text())
    raw["seeds"]["train"] = RULES[name]
    path = tmp_path / "suite.json"
    path.write_text(json.dumps(raw))
    with pytest.raises(SuiteError, match=r"suite\.json: seeds\['train'\] must be"):
        load_suite(path)


def test_a_train_range_inside_the_lists_and_a_suite_without_a_rule_are_refused(tmp_path: Path) -> None:
    raw = json.loads(SUITE.path.read_text())
    listed = SUITE.seeds["val"][0]
    raw["seeds"]["train"] = {"from": listed, "below": listed + 1}
    (tmp_path / "full.json").write_text(json.dumps(raw))
    with pytest.raises(SuiteError, match="holds no seed outside"):
        load_suite(tmp_path / "full.json")
    del raw["seeds"]["train"]
    (tmp_path / "none.json").write_text(json.dumps(raw))
    older = load_suite(tmp_path / "none.json")
    assert older.seeds_of("val", 3) == SUITE.seeds_of("val", 3), "a suite without a train rule still scores"
    with pytest.raises(SuiteError, match="states no train seeds"):
        older.seeds_of("train", 3)
    with pytest.raises(EnvInputError, match="states no train seeds"):
        gym.make(envs.SUITE_ID, suite_file=tmp_path / "none.json")


@pytest.fixture(scope="module")
def every_scenario() -> tuple[gym.Env, dict[str, tuple[dict, dict]]]:
    """A suite env reset once to each scenario, and the first observation and info of each."""
    env = gym.make(envs.SUITE_ID, predictor="none")
    firsts = {scenario.name: env.reset(seed=i, options={"scenario": scenario.name})
              for i, scenario in enumerate(SUITE.scenarios)}
    yield env, firsts
    env.close()


def test_the_suite_env_resets_to_each_scenario_in_one_space(every_scenario: tuple) -> None:
    env, firsts = every_scenario
    assert view_sizes(env.observation_space) == (8, 16, 8, 20) and len(firsts) == len(SUITE.scenarios) == 18
    for name, (obs, info) in firsts.items():
        assert info["scenario"] == name and info["scenario_seed"] not in LISTED, name
        assert env.observation_space.contains(obs), f"{name}: the view is not in the suite env's space"
        assert env.unwrapped._envs[name].observation_space == env.observation_space, name
    replays = [name for name in firsts if name.endswith(("-log", "-reactive"))]
    assert any(firsts[name][0]["walls"].min() < 3.0 for name in replays), "replays' non-walkable ground is seen"


def rollout(env: gym.Env, seed: int, steps: int) -> list:
    """(scenario, scenario seed, observation, reward) of ``steps`` steps from ``reset(seed)``, later resets unseeded."""
    obs, info = env.reset(seed=seed)
    out = [(info["scenario"], info["scenario_seed"], obs, 0.0)]
    for t in range(steps):
        obs, reward, terminated, truncated, info = env.step(np.array([1.2, 0.4 * np.sin(t)], np.float32))
        if terminated or truncated:
            obs, info = env.reset()
        out.append((info["scenario"], info["scenario_seed"], obs, reward))
    return out


def test_the_suite_env_is_deterministic_for_a_seed_and_follows_its_weights() -> None:
    make = lambda **kw: gym.make(envs.SUITE_ID, scenarios=SIMULATED, predictor="none", **kw)  # noqa: E731
    a, b = rollout(make(), 7, 25), rollout(make(), 7, 25)
    for t, (one, two) in enumerate(zip(a, b, strict=True)):
        assert one[:2] == two[:2] and one[3] == two[3], f"[step {t}] {one[:2]} {two[:2]}"
        assert all(np.array_equal(one[2][key], two[2][key]) for key in one[2]), f"[step {t}] observations differ"
    env = make(weights=[0.0, 2.0], split="val")
    for seed in range(8):
        _, info = env.reset(seed=seed)
        assert info["scenario"] == "sim-corridor" and info["scenario_seed"] in SUITE.seeds["val"], seed
    env = make()
    drawn = {env.reset(seed=seed)[1]["scenario"] for seed in range(12)}
    assert drawn == set(SIMULATED), "equal weights draw both"


def test_the_suite_env_passes_check_env() -> None:
    env = gym.make(envs.SUITE_ID, scenarios=SIMULATED, predictor="none", render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=ACTION_SPACE_ADVICE)
        check_env(env.unwrapped)
    env.close()


def test_the_suite_env_runs_in_a_sync_vector_env_across_scenarios_of_other_slot_counts() -> None:
    vec = gym.make_vec(envs.SUITE_ID, num_envs=2, vectorization_mode="sync", scenarios=["zara1-log", "doorway"],
                       predictor="cvm")
    obs, info = vec.reset(seed=[3, 11])
    assert obs["people"].shape == (2, 8, 8, 2) and obs["walls"].shape == (2, 16)
    for t in range(6):
        obs, _, _, _, info = vec.step(np.tile([1.0, 0.0], (2, 1)).astype(np.float32))
        assert vec.observation_space.contains(obs), f"[step {t}]"
        assert info["agent_ids"].shape == (2, 8), f"[step {t}] per-row info on the view's rows"
    vec.close()


def test_sb3_ppo_trains_on_the_suite_env_and_the_model_fits_every_scenario(tmp_path: Path,
                                                                           every_scenario: tuple) -> None:
    from stable_baselines3 import PPO

    from st_sim.apps.navigation.policies import load_policy, observation_fits
    from st_sim.apps.navigation.world import world_of

    env = gym.make(envs.SUITE_ID, scenarios=["frontal-approach", "doorway"], predictor="cvm")  # few people: quick
    model = PPO("MultiInputPolicy", env, n_steps=128, batch_size=64, n_epochs=2, seed=0, device="cpu")
    model.learn(total_timesteps=256)
    assert model.num_timesteps >= 256
    model.save(tmp_path / "suite.zip")
    suite_env, _ = every_scenario
    for name, scenario_env in suite_env.unwrapped._envs.items():  # each scenario's own env, behind the view
        raw_space = scenario_env.env.observation_space
        assert observation_fits(model.observation_space, raw_space), f"{name}: the model does not fit {raw_space}"
    raw = suite_env.unwrapped._envs["univ-reactive"].env
    policy = load_policy(f"sb3:{tmp_path / 'suite.zip'}", world_of(raw), "none")  # read without running the file
    obs, _ = raw.reset(seed=5)
    velocity = policy.act(obs)
    assert velocity.shape == (2,) and np.isfinite(velocity).all()


WEIGHTS = st.one_of(st.lists(st.floats(0.0, 5.0), min_size=0, max_size=1),
                    st.lists(st.floats(0.0, 5.0), min_size=3, max_size=4),
                    st.tuples(st.floats(max_value=-1e-9, allow_infinity=False), st.floats(0.0, 5.0)).map(list),
                    st.tuples(st.sampled_from([math.nan, math.inf]), st.floats(0.0, 5.0)).map(list),
                    st.just([0.0, 0.0]), st.just(["1", 2]), st.just([True, 1.0]), st.just("11"), st.just(3.0))


@settings(max_examples=30, deadline=None)
@given(keywords=st.one_of(
    st.fixed_dictionaries({"weights": WEIGHTS}),
    st.fixed_dictionaries({"split": st.sampled_from(["training", "TEST", "", None, 1])}),
    st.fixed_dictionaries({"scenarios": st.sampled_from([["doorway", "nowhere"], ["doorway", "doorway"], [],
                                                         "doorway", 3])}),
    st.fixed_dictionaries({"nearest": st.sampled_from([0, -3, 2.5, "8", True])}),
    st.fixed_dictionaries({"rays": st.sampled_from([0, None, 1.5])})))
def test_hostile_keywords_give_one_line_naming_the_env(keywords: dict) -> None:
    kwargs = {"scenarios": SIMULATED, "predictor": "none", **keywords}
    with pytest.raises(EnvInputError) as caught:
        gym.make(envs.SUITE_ID, **kwargs)
    message = str(caught.value)
    assert message.startswith("STCrowd-Suite-v1: ") and "\n" not in message, message
    assert next(iter(keywords)) in message or "split" in message or "scenario" in message, message


def test_hostile_reset_and_step_calls_are_refused_before_anything_changes() -> None:
    env = gym.make(envs.SUITE_ID, scenarios=SIMULATED, predictor="none").unwrapped
    with pytest.raises(NeedsResetError, match="reset"):
        env.step(np.zeros(2, np.float32))
    for options in ({"scenario": "univ-log"}, {"start_index": 3}, ["scenario"]):
        with pytest.raises(ResetOptionsError, match="STCrowd-Suite-v1"):
            env.reset(seed=0, options=options)
    for seed in (-1, 1.5, True):
        with pytest.raises(EnvInputError, match="seed"):
            env.reset(seed=seed)
    assert env._envs == {}, "nothing was made"


@pytest.mark.parametrize("name", ["sim-corridor", "zara1-reactive"])
def test_the_scenario_and_its_seed_start_the_episode_again(name: str) -> None:
    """docs/environments.md: ``info["scenario"]`` and ``info["scenario_seed"]`` name the episode: the scenario's env
    (the benchmark's, behind the view) reset with that seed starts it again, step for step."""
    from envs.suite import make_scenario_env
    from envs.view import FixedView

    suite_env = gym.make(envs.SUITE_ID, scenarios=[name], predictor="cvm")
    obs, info = suite_env.reset(seed=11)
    (scenario,) = SUITE.select([info["scenario"]])
    again = FixedView(make_scenario_env(scenario, "cvm"))
    obs_again, _ = again.reset(seed=info["scenario_seed"])
    for t in range(8):
        assert all(np.array_equal(obs[key], obs_again[key]) for key in obs), f"[step {t}] observations differ"
        action = np.array([1.0, 0.5 * np.sin(t)], np.float32)
        obs, reward, terminated, truncated, _ = suite_env.step(action)
        obs_again, reward_again, *_ = again.step(action)
        assert reward == reward_again, f"[step {t}]"
        if terminated or truncated:
            break
    suite_env.close()
    again.close()
