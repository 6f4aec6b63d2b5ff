"""The ego's sensor range (``EnvConfig.sensor_range_m``), forecasts of the nearest only (``forecast_nearest``), the
discomfort reward part and the forecasts a log replay keeps, as properties over seeds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.config import ConfigError, EnvConfig, RewardWeights

STEPS = 25


@pytest.mark.parametrize("env_id", ["STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0"])
@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), range_m=st.floats(0.5, 8.0))
def test_only_pedestrians_in_range_are_observed_and_forecast(env_id: str, seed: int, range_m: float) -> None:
    near = gym.make(env_id, predictor="cvm", config=EnvConfig(sensor_range_m=range_m))
    full = gym.make(env_id, predictor="cvm")
    rng = np.random.default_rng(seed)
    (obs, info), (obs_full, _) = near.reset(seed=seed), full.reset(seed=seed)
    for t in range(STEPS):
        ego = obs["ego"][:2]
        distance = np.linalg.norm(obs_full["history"][:, -1] - ego, axis=1)
        present = obs_full["history_mask"][:, -1]
        sensed = present & (distance <= range_m)
        assert np.array_equal(obs["history_mask"][:, -1], sensed), f"[step {t}] sensed rows"
        assert not obs["history_mask"][~sensed].any() and not obs["history"][~sensed].any(), f"[step {t}] far rows"
        assert np.array_equal(obs["futures_mask"], obs_full["futures_mask"] & sensed), f"[step {t}] forecast rows"
        assert np.array_equal(obs["futures"][obs["futures_mask"]], obs_full["futures"][obs["futures_mask"]])
        assert np.array_equal(info["predicted_ids"] >= 0, obs["futures_mask"])
        action = rng.uniform(-1.5, 1.5, 2).astype(np.float32)
        (obs, _, end, cut, info), (obs_full, *_rest) = near.step(action), full.step(action)
        if end or cut:
            break


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), weight=st.floats(-20.0, -0.1), discomfort_m=st.floats(0.0, 2.0))
def test_discomfort_part_is_the_gap_shortfall_and_weighs_into_the_reward(seed: int, weight: float,
                                                                         discomfort_m: float) -> None:
    config = EnvConfig(discomfort_m=discomfort_m)
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm", config=config)
    weighted = gym.make("STCrowd-Zara1-v0", predictor="cvm",
                        config=EnvConfig(discomfort_m=discomfort_m, reward=RewardWeights(discomfort=weight)))
    rng = np.random.default_rng(seed)
    env.reset(seed=seed), weighted.reset(seed=seed)
    reach = config.ego_radius_m + config.pedestrian_radius_m
    for t in range(STEPS):
        action = rng.uniform(-1.5, 1.5, 2).astype(np.float32)
        obs, reward, end, cut, info = env.step(action)
        _, reward_weighted, *_ = weighted.step(action)
        people = obs["history"][obs["history_mask"][:, -1], -1]
        gap = np.linalg.norm(people - obs["ego"][:2], axis=1).min() - reach if len(people) else np.inf
        part = info["reward_parts"]["discomfort"]
        assert part == pytest.approx(max(0.0, discomfort_m - gap), abs=1e-5), f"[step {t}]"
        assert reward_weighted - reward == pytest.approx(weight * part, abs=1e-9), f"[step {t}]"
        if end or cut:
            break


@pytest.mark.parametrize("env_id", ["STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0"])
@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 10_000), nearest=st.integers(1, 8), range_m=st.sampled_from([4.0, np.inf]))
def test_only_the_nearest_are_forecast_and_exactly_as_with_everyone_forecast(env_id: str, seed: int, nearest: int,
                                                                          range_m: float) -> None:
    """``forecast_nearest``: futures for the k sensed pedestrians nearest to the robot only, and the same futures as
    when every sensed one is forecast (the others still condition the predictor)."""
    few = gym.make(env_id, predictor="singular", config=EnvConfig(sensor_range_m=range_m, forecast_nearest=nearest))
    every = gym.make(env_id, predictor="singular", config=EnvConfig(sensor_range_m=range_m))
    rng = np.random.default_rng(seed)
    (obs, info), (obs_every, _) = few.reset(seed=seed), every.reset(seed=seed)
    for t in range(12):
        for key in ("ego", "history", "history_mask"):
            assert np.array_equal(obs[key], obs_every[key]), f"[step {t}] {key}"
        sensed = np.flatnonzero(obs["history_mask"][:, -1])
        distance = np.linalg.norm(obs["history"][sensed, -1].astype(np.float64) - obs["ego"][:2], axis=1)
        closest = np.zeros(len(obs["futures_mask"]), bool)
        closest[sensed[np.argsort(distance, kind="stable")[:nearest]]] = True
        assert np.array_equal(obs["futures_mask"], obs_every["futures_mask"] & closest), f"[step {t}] forecast rows"
        assert np.array_equal(info["predicted_ids"] >= 0, obs["futures_mask"])
        np.testing.assert_allclose(obs["futures"][obs["futures_mask"]], obs_every["futures"][obs["futures_mask"]],
                                   rtol=0, atol=1e-4, err_msg=f"[step {t}]")
        assert not obs["futures"][~obs["futures_mask"]].any()
        action = rng.uniform(-1.5, 1.5, 2).astype(np.float32)
        (obs, _, end, cut, info), (obs_every, *_rest) = few.step(action), every.step(action)
        if end or cut:
            break


@pytest.mark.parametrize("field, value", [("sensor_range_m", 0.0), ("sensor_range_m", -1.0), ("discomfort_m", -0.1),
                                          ("discomfort_m", float("nan")), ("forecast_nearest", 0),
                                          ("forecast_nearest", 2.0), ("forecast_nearest", True),
                                          ("forecast_nearest", "6")])
def test_sensing_fields_are_range_checked(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=field):
        EnvConfig(**{field: value})


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_kept_forecasts_of_a_log_replay_equal_fresh_ones(seed: int) -> None:
    """Episodes that revisit frames reuse their forecasts (``ForecastCache``), which equal those computed afresh."""
    kept, fresh = (gym.make("STCrowd-Zara1-v0", predictor="singular") for _ in range(2))
    fresh.unwrapped.forecasts = None
    rng = np.random.default_rng(seed)
    for episode in range(3):  # the same start each time: every later episode revisits the first one's frames
        obs, _ = kept.reset(seed=seed, options={"start_index": 100})
        obs_fresh, _ = fresh.reset(seed=seed, options={"start_index": 100})
        for t in range(8):
            action = rng.uniform(-1.5, 1.5, 2).astype(np.float32)
            for key in obs:
                np.testing.assert_allclose(obs[key], obs_fresh[key], rtol=0, atol=1e-5, err_msg=f"{episode} {t} {key}")
            (obs, *_, end, cut, _), (obs_fresh, *_) = kept.step(action), fresh.step(action)
            if end or cut:
                break
    assert kept.unwrapped.forecasts.hits > 0, "later episodes must reuse the kept forecasts"


def test_reactive_replays_keep_no_forecasts() -> None:
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm", pedestrians="reactive")
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.zeros(2))
    assert env.unwrapped.forecasts.hits == env.unwrapped.forecasts.misses == 0


def test_simulated_crowds_keep_no_forecasts() -> None:
    """docs/environments.md, "Kept forecasts": simulated crowds never reuse forecasts, even in an episode that
    repeats one before it moment for moment."""
    env = gym.make("STCrowd-SimCrossing-v1", predictor="cvm")
    for _ in range(2):
        env.reset(seed=0)
        for _ in range(5):
            env.step(np.zeros(2))
    assert env.unwrapped.forecasts.hits == env.unwrapped.forecasts.misses == 0


def test_kept_forecasts_serve_a_recording_env_as_far_as_its_predictor_can() -> None:
    """A recording env needs anchor paths only from a predictor that gives them: without them a kept forecast is a
    miss (and is replaced by one with them), from a predictor without any it is a hit."""
    from envs.common.predictors import ForecastCache

    ids, futures = np.array([4, 2]), np.arange(2 * 3 * 12 * 2, dtype=np.float32).reshape(2, 3, 12, 2)
    paths = (futures + 1, futures + 2)
    cache = ForecastCache()
    cache.put(7, ids, (futures, None))
    assert cache.get(7, ids[::-1])[1] is None and cache.get(7, ids, anchors=True) is None
    assert (cache.hits, cache.misses) == (1, 1)
    cache.put(7, ids, (futures, paths))
    kept = cache.get(7, ids[::-1], anchors=True)
    np.testing.assert_array_equal(kept[0], futures[::-1])
    np.testing.assert_array_equal(kept[1][1], paths[1][::-1])
    cache.put(7, ids, (futures + 5, None))  # an entry with anchors stays
    np.testing.assert_array_equal(cache.get(7, ids)[0], futures)


def test_a_recording_replay_reuses_forecasts_of_a_predictor_without_anchors(tmp_path) -> None:
    from predictor.baselines import ConstantVelocity

    class Counted(ConstantVelocity):
        calls = 0

        def predict(self, *args, **kwargs):
            Counted.calls += 1
            return super().predict(*args, **kwargs)

    env = gym.make("STCrowd-Zara1-v0", predictor=Counted(), ego=False, rerun=str(tmp_path / "replay.rrd"))
    calls = []
    for _ in range(2):  # the same frames twice: the second time from the kept forecasts
        env.reset(seed=0, options={"start_index": 100})
        for _ in range(3):
            env.step(np.zeros(2, np.float32))
        calls.append(Counted.calls)
    env.close()
    assert calls[0] == 4 and calls[1] == calls[0]
