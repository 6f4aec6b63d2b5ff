"""The PPO trainer's vector env (``training_envs.FeatureVecEnv``): the same transitions as stable-baselines3's own
``DummyVecEnv`` over single envs seen through ``NavFeatures``, through episode ends and resets."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from stable_baselines3.common.vec_env import DummyVecEnv

import envs  # noqa: F401  (registers the ids)
from envs.common.config import EnvConfig
from envs.common.errors import EnvInputError
from envs.shards import ProcessShard
from st_sim.apps.navigation.features import FeatureConfig, NavFeatures, drop_predictions, encode
from st_sim.apps.navigation.predictors import env_predictor
from st_sim.apps.navigation.training_envs import FeatureVecEnv, sub_env_info
from st_sim.apps.navigation.world import world_of

ENV_ID = "STCrowd-SimCrossing-v1"
FORECAST_ATOL = 1e-3
"""forecast features' tolerance (positions / 5 m, spreads / 2 m, ...): 5x the largest difference measured, 2e-4 on
one CI machine; on a dev machine the most is 1.2e-7 (one float32 ulp at 1), in the sharded test and in the
several-envs test over 11 seeds. Sub-envs or pedestrians mixed up would be off by whole units."""


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000), num_envs=st.integers(1, 3), sensor_range_m=st.sampled_from([3.0, np.inf]))
def test_feature_vec_env_equals_dummy_vec_env_over_single_envs(seed: int, num_envs: int, sensor_range_m: float
                                                                ) -> None:
    features = FeatureConfig(use_predictions=False, sensor_range_m=sensor_range_m)
    ours = FeatureVecEnv(ENV_ID, num_envs, features)
    config = EnvConfig(sensor_range_m=sensor_range_m)
    theirs = DummyVecEnv([lambda: NavFeatures(gym.make(ENV_ID, predictor=env_predictor("none"), config=config),
                                              features)] * num_envs)
    ours.seed(seed), theirs.seed(seed)
    np.testing.assert_array_equal(ours.reset(), theirs.reset())
    rng, ended = np.random.default_rng(seed), 0
    for t in range(60):
        actions = rng.uniform(-1.0, 1.0, (num_envs, 2)).astype(np.float32)
        actions[:, 0] = np.abs(actions[:, 0])  # mostly on towards the goal: episodes end by goal and collision too
        ours.step_async(actions), theirs.step_async(actions)
        (obs, rewards, dones, infos), (obs_t, rewards_t, dones_t, infos_t) = ours.step_wait(), theirs.step_wait()
        np.testing.assert_array_equal(obs, obs_t, err_msg=f"step {t}")
        np.testing.assert_array_equal(rewards, rewards_t, err_msg=f"step {t}")
        np.testing.assert_array_equal(dones, dones_t, err_msg=f"step {t}")
        for i in np.flatnonzero(dones):
            ended += 1
            np.testing.assert_array_equal(infos[i]["terminal_observation"], infos_t[i]["terminal_observation"])
            assert infos[i]["TimeLimit.truncated"] == infos_t[i]["TimeLimit.truncated"]
            assert infos[i]["termination"] == infos_t[i]["termination"]
    assert ended > 0, "some episode ended within 60 steps, so resets were compared"
    ours.close(), theirs.close()


class OneWorker:
    """All the sub-envs in one worker process: the ``FeatureShards`` a one-shard ``FeatureVecEnv`` steps in its own
    process, hosted like a shard, so that it and the shards run alike (``--perturb`` patches this process only)."""

    def __init__(self, parts: list[tuple[str, int]], features: FeatureConfig):
        self.worker = ProcessShard("st_sim.apps.navigation.training_envs:FeatureShards", parts, features, None,
                                   "auto", True)

    def call(self, method: str, *args):
        self.worker.send(method, *args)
        outcome, value = self.worker.receive()
        if outcome == "error":
            raise value
        return value


def test_feature_vec_env_in_worker_processes_equals_the_one_process_one() -> None:
    """Shards: the same features, rewards, ends and final infos as all sub-envs in one process, and attributes read
    from the sub-env that holds them.

    The features that do not come from forecasts are equal bit for bit. Those that do agree to FORECAST_ATOL only: a
    shard forecasts a smaller batch, float32 sums round with the batch's shape (by the CPU's kernels), and ten
    denoising steps carry the difference on (2e-4 seen on one CI machine); sub-envs or pedestrians mixed up would be
    off by whole units."""
    features = FeatureConfig(True, closest_approach=True)
    one, sharded = OneWorker([(ENV_ID, 5)], features), FeatureVecEnv(ENV_ID, 5, features, shards=2)
    sharded.seed(7)  # sub-env i resets with seed 7 + i
    np.testing.assert_allclose(one.call("reset", [7 + i for i in range(5)]), sharded.reset(), rtol=0,
                               atol=FORECAST_ATOL)
    rng, ended = np.random.default_rng(7), 0
    for t in range(40):
        actions = rng.uniform(-1.0, 1.0, (5, 2)).astype(np.float32)
        actions[:, 0] = np.abs(actions[:, 0])
        sharded.step_async(actions)
        (obs, rewards, dones, infos), (obs_s, rewards_s, dones_s, infos_s) = one.call("step", actions), \
            sharded.step_wait()
        np.testing.assert_array_equal(drop_predictions(obs, features), drop_predictions(obs_s, features),
                                      err_msg=f"step {t}")
        np.testing.assert_allclose(obs, obs_s, rtol=0, atol=FORECAST_ATOL, err_msg=f"step {t}")
        np.testing.assert_array_equal(rewards, rewards_s, err_msg=f"step {t}")
        np.testing.assert_array_equal(dones, dones_s, err_msg=f"step {t}")
        for i in np.flatnonzero(dones):
            ended += 1
            assert infos[i]["termination"] == infos_s[i]["termination"]
            np.testing.assert_allclose(infos[i]["terminal_observation"], infos_s[i]["terminal_observation"],
                                       rtol=0, atol=FORECAST_ATOL)
    assert ended > 0
    assert sharded.get_attr("num_samples", [0, 4]) == one.call("get_attr", "num_samples", [0, 4]) == [20, 20]
    assert [layout.name for layout in sharded.get_attr("layout", 3)] == ["crossing"]
    one.worker.close(), sharded.close()


def test_more_shards_than_sub_envs_are_refused() -> None:
    with pytest.raises(ValueError, match="shards=3"):
        FeatureVecEnv(ENV_ID, 2, FeatureConfig(False), shards=3)


def test_features_leave_out_pedestrians_beyond_the_sensor_range() -> None:
    env = gym.make(ENV_ID, predictor="cvm")
    obs, _ = env.reset(seed=3)
    for _ in range(10):
        obs, *_ = env.step(np.zeros(2, np.float32))
    world = world_of(env)
    present = obs["history_mask"][:, -1]
    distance_m = np.linalg.norm(obs["history"][present, -1] - obs["ego"][:2], axis=1)
    for range_m in (0.5, 2.0, 4.0, np.inf):
        slots = encode(obs, world, FeatureConfig(True, sensor_range_m=range_m))[19:].reshape(6, -1)
        assert slots[:, 0].sum() == min(6, int((distance_m <= range_m).sum())), range_m


@pytest.mark.parametrize("batched, i, expected", [
    ({"a": np.array([1, 2]), "_a": np.array([True, False])}, 0, {"a": 1}),
    ({"a": np.array([1, 2]), "_a": np.array([True, False])}, 1, {}),
    ({"f": {"b": np.array([3, 4]), "_b": np.array([True, True])}, "_f": np.array([False, True])}, 1, {"f": {"b": 4}}),
])
def test_sub_env_info_keeps_what_the_sub_env_set(batched: dict, i: int, expected: dict) -> None:
    assert sub_env_info(batched, i) == expected


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000), use_predictions=st.booleans())
def test_several_training_envs_share_the_sub_envs_and_step_as_each_alone(seed: int, use_predictions: bool) -> None:
    """Two reactive replay sub-envs, two of a simulated crossing and one of an encounter (three worlds, two predictor
    models) stepped as one batch: the same transitions as each training env alone, seeded as those sub-envs are; bit
    for bit but for the forecast features, which a larger batch rounds otherwise (FORECAST_ATOL). Every side runs in a
    worker process, as the sharded test's do (``--perturb`` patches this process only)."""
    features = FeatureConfig(use_predictions=use_predictions, closest_approach=use_predictions)
    specs, sizes = ["STCrowd-Hotel-v0:reactive", "STCrowd-SimCrossing-v1", "STCrowd-SimOvertaking-v1"], [2, 2, 1]
    starts = np.cumsum([0, *sizes[:-1]]).tolist()
    mixed = OneWorker(list(zip(specs, sizes, strict=True)), features)
    alone = [OneWorker([(spec, size)], features) for spec, size in zip(specs, sizes, strict=True)]

    def assert_same(ours: np.ndarray, theirs: np.ndarray, where: str) -> None:
        np.testing.assert_array_equal(drop_predictions(ours, features), drop_predictions(theirs, features),
                                      err_msg=where)
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=FORECAST_ATOL, err_msg=where)

    try:
        assert_same(mixed.call("reset", [seed + i for i in range(5)]),
                    np.concatenate([one.call("reset", [seed + start + i for i in range(size)])
                                    for one, start, size in zip(alone, starts, sizes, strict=True)]), "reset")
        rng, ended = np.random.default_rng(seed), 0
        for t in range(30):
            actions = rng.uniform(-1.0, 1.0, (5, 2)).astype(np.float32)
            actions[:, 0] = np.abs(actions[:, 0])
            ours = mixed.call("step", actions)
            theirs = [one.call("step", part) for one, part in zip(alone, np.split(actions, starts[1:]), strict=True)]
            assert_same(ours[0], np.concatenate([part[0] for part in theirs]), f"step {t}")
            for k in (1, 2):
                np.testing.assert_array_equal(ours[k], np.concatenate([part[k] for part in theirs]),
                                              err_msg=f"step {t}")
            theirs_infos = [info for part in theirs for info in part[3]]
            for i in np.flatnonzero(ours[2]):
                ended += 1
                assert ours[3][i]["termination"] == theirs_infos[i]["termination"]
                assert_same(ours[3][i]["terminal_observation"], theirs_infos[i]["terminal_observation"],
                            f"step {t}")
        assert ended > 0, "some episode ended within 30 steps, so autoresets were compared"
        assert mixed.call("get_attr", "pedestrians", [0, 1]) == ["reactive", "reactive"]
    finally:
        for one in [mixed, *alone]:
            one.worker.close()


def test_a_training_env_that_is_not_an_id_or_mode_is_refused() -> None:
    with pytest.raises(EnvInputError, match="not a pedestrian mode"):
        FeatureVecEnv("STCrowd-Eth-v0:frozen", 2, FeatureConfig(False))
    with pytest.raises(EnvInputError, match="not a registered gym id"):
        FeatureVecEnv(["STCrowd-Eth-v0", "Nowhere-v0"], 2, FeatureConfig(False))
    with pytest.raises(EnvInputError, match="give each at least one"):
        FeatureVecEnv(["STCrowd-Eth-v0", "STCrowd-Hotel-v0"], 1, FeatureConfig(False))


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000), listed=st.sets(st.integers(0, 40), max_size=30))
def test_with_a_train_split_every_episode_starts_from_one_of_its_seeds(seed: int, listed: set) -> None:
    """Sub-envs of a simulated and a replayed scenario, their episodes ending often: every reset, the first and each
    autoreset, takes a seed of the split (in its range, in no published list); the first ones are the split's
    (seed + i)-th seeds, so the same seed gives the same episodes."""
    from envs.common.crowd_env import CrowdEnv
    from envs.suite import TrainSeeds

    split = TrainSeeds(0, 48, tuple(sorted(listed)))
    seen: list[int | None] = []

    def spy(original):
        def begin_reset_all(cls, batch, seeds, options):
            seen.extend(seeds)
            return original.__func__(cls, batch, seeds, options)
        return classmethod(begin_reset_all)

    patch = pytest.MonkeyPatch()
    patch.setattr(CrowdEnv, "begin_reset_all", spy(CrowdEnv.begin_reset_all))  # every env class's
    try:
        vec = FeatureVecEnv(["STCrowd-SimCorridor-v1", "STCrowd-Hotel-v0:log"], 4, FeatureConfig(False),
                            train_seeds=split)
        vec.seed(seed)
        first = vec.reset()
        assert seen == split.nth(np.arange(seed, seed + 4) % split.count).tolist()
        rng, ended = np.random.default_rng(seed), 0
        for _ in range(80):
            vec.step_async(rng.uniform(-1.0, 1.0, (4, 2)).astype(np.float32))
            ended += int(vec.step_wait()[2].sum())
        vec.seed(seed)
        np.testing.assert_array_equal(vec.reset(), first)
        vec.close()
    finally:
        patch.undo()
    assert ended > 0 and len(seen) == 8 + ended, "each autoreset went through the spy"
    assert all(isinstance(s, int) and 0 <= s < 48 and s not in listed for s in seen)


def test_suite_scenarios_with_a_hold_out_train_on_the_rest() -> None:
    from st_sim.apps.navigation.train_ppo import parse_args

    cfg = parse_args(["--scenarios", "all", "--hold-out", "zara1", "univ"])
    assert cfg.scenarios and not any(name.startswith(("zara1-", "univ-")) for name in cfg.scenarios)
    assert "STCrowd-Eth-v0:reactive" in cfg.env_ids and len(cfg.env_ids) == len(cfg.scenarios) == 14
    assert not any(env.startswith(("STCrowd-Zara1", "STCrowd-Univ")) for env in cfg.env_ids)
    assert parse_args(["--scenarios", "sim-crossing", "eth-log"]).env_ids == ("STCrowd-SimCrossing-v1",
                                                                              "STCrowd-Eth-v0:log")


@pytest.mark.parametrize("argv, match", [(["--scenarios", "moon"], "no scenario 'moon'"),
                                         (["--hold-out", "eth"], "add --scenarios"),
                                         (["--scenarios", "all", "--hold-out", "mars"], "neither a scenario"),
                                         (["--scenarios", "eth-log", "--hold-out", "eth"], "leaves no scenario")])
def test_bad_suite_scenarios_are_refused_naming_the_flag(argv: list[str], match: str,
                                                         capsys: pytest.CaptureFixture) -> None:
    from st_sim.apps.navigation.train_ppo import parse_args

    with pytest.raises(SystemExit):
        parse_args(argv)
    assert match in capsys.readouterr().err
