"""What the learned policy reads and is paid for: the attention over pedestrians (any order, any number present),
the predicted-closest-approach features, the features of a batch of observations, and the prediction-aware reward
part."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces
from hypothesis import given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.common.config import EnvConfig, RewardWeights
from envs.common.crowd_env import WEIGHT_OF
from replays.constants import STEP_S, T_PRED
from st_sim.apps.navigation.attention import EMBED, PedestrianAttention
from st_sim.apps.navigation.features import (
    NEAREST,
    PREDICTED_STEPS,
    RAY_COUNT,
    SPREAD_STEPS,
    FeatureConfig,
    encode,
    encode_batch,
    path_frame,
    path_frames,
    to_velocities,
)
from st_sim.apps.navigation.pedestrians import pedestrians_of
from st_sim.apps.navigation.ppo import build_policy, load_policy, save_policy
from st_sim.apps.navigation.world import world_of
from st_sim.sim.robot import RobotSpec

CONFIGS = [FeatureConfig(True), FeatureConfig(False), FeatureConfig(True, closest_approach=True)]

AGILE = RobotSpec(max_accel_mps2=100.0, max_brake_mps2=100.0)  # reaches any command within a 0.2 s substep


def _features(cfg: FeatureConfig, rng: np.random.Generator, batch: int, present: np.ndarray) -> torch.Tensor:
    """(batch, cfg.size) random features whose pedestrian slot k is present where present[:, k]."""
    x = rng.normal(size=(batch, cfg.size)).astype(np.float32)
    slots = x[:, 3 + RAY_COUNT:].reshape(batch, NEAREST, cfg.slot_size)
    slots[:, :, 0] = present
    slots[~present] = 0.0
    return torch.from_numpy(x)


@settings(max_examples=30, deadline=None)
@given(cfg=st.sampled_from(CONFIGS), seed=st.integers(0, 2**32 - 1), batch=st.integers(1, 5))
def test_attention_is_blind_to_slot_order_and_to_absent_slots(cfg: FeatureConfig, seed: int, batch: int) -> None:
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed % 1000)
    extractor = PedestrianAttention(spaces.Box(-np.inf, np.inf, (cfg.size,), np.float32), cfg).eval()
    present = rng.random((batch, NEAREST)) < 0.6
    x = _features(cfg, rng, batch, present)
    with torch.no_grad():
        out = extractor(x)
        assert out.shape == (batch, 2 * EMBED) and torch.isfinite(out).all()
        order = rng.permutation(NEAREST)
        slots = x[:, 3 + RAY_COUNT:].reshape(batch, NEAREST, cfg.slot_size)[:, order]
        permuted = torch.cat([x[:, :3 + RAY_COUNT], slots.reshape(batch, -1)], dim=1)
        torch.testing.assert_close(extractor(permuted), out, rtol=1e-5, atol=1e-5)
        noise = torch.from_numpy(rng.normal(size=slots.shape).astype(np.float32))
        absent = torch.from_numpy(~present[:, order])
        noise[..., 0] = 0.0  # the present flag stays "absent"
        noisy = torch.where(absent[..., None], noise, slots)
        changed = torch.cat([x[:, :3 + RAY_COUNT], noisy.reshape(batch, -1)], dim=1)
        torch.testing.assert_close(extractor(changed), out, rtol=1e-5, atol=1e-5)


def test_attention_reads_an_empty_street() -> None:
    cfg = FeatureConfig(True)
    extractor = PedestrianAttention(spaces.Box(-np.inf, np.inf, (cfg.size,), np.float32), cfg)
    out = extractor(_features(cfg, np.random.default_rng(0), 3, np.zeros((3, NEAREST), bool)))
    assert torch.isfinite(out).all()


def test_an_attention_policy_saves_and_loads_with_its_extractor(tmp_path) -> None:
    cfg = FeatureConfig(True, 5.0, closest_approach=True)
    policy = build_policy(cfg, [32], "attention")
    save_policy(policy, cfg, [32], tmp_path / "p.pt", "attention")
    loaded, loaded_cfg = load_policy(tmp_path / "p.pt")
    assert loaded_cfg == cfg and isinstance(loaded.features_extractor, PedestrianAttention)
    x = _features(cfg, np.random.default_rng(1), 4, np.ones((4, NEAREST), bool))
    with torch.no_grad():
        torch.testing.assert_close(loaded.get_distribution(x).mode(), policy.eval().get_distribution(x).mode())


class CourseCrossing:
    """A predictor whose every sample of every agent stands still at ``where`` (world metres), set by the test."""

    where = np.zeros(2)

    def predict(self, obs, group, scene, num_samples):
        return np.broadcast_to(self.where, (len(obs), num_samples, T_PRED, 2)).astype(np.float32).copy()


@pytest.mark.parametrize("k", [1, 3, 7])
def test_the_prediction_reward_part_halves_with_each_step_to_the_predicted_meeting(k: int) -> None:
    predictor = CourseCrossing()
    env = gym.make("STCrowd-Zara1-v0", predictor=predictor, config=EnvConfig(reward=RewardWeights(prediction=-3.0)),
                   robot=AGILE)
    env.reset(seed=2)
    unwrapped = env.unwrapped
    velocity = np.array([0.0, 1.5])  # 0.6 m a step: the 0.55 m contact distance covers one step of its course
    after = unwrapped.ego_xy_m + STEP_S * velocity  # the agile robot moves at the commanded velocity at once
    predictor.where = after + k * STEP_S * velocity  # where its course will be k steps after this one
    _, reward, terminated, _, info = env.step(velocity)
    assert np.allclose(unwrapped.ego_xy_m, after) and not terminated
    assert info["reward_parts"]["predicted_collision"] == pytest.approx(0.5 ** (k - 1))
    assert reward == pytest.approx(sum(getattr(RewardWeights(prediction=-3.0), WEIGHT_OF.get(name, name)) * value
                                       for name, value in info["reward_parts"].items()))
    predictor.where = after + np.array([5.0, 0.0])  # off its course
    _, _, _, _, info = env.step(velocity)
    assert info["reward_parts"]["predicted_collision"] == 0.0


def test_closest_approach_features_say_how_near_and_when() -> None:
    predictor = CourseCrossing()
    env = gym.make("STCrowd-Zara1-v0", predictor=predictor, robot=AGILE)
    obs, _ = env.reset(seed=5)
    velocity = np.array([1.0, 0.0])
    predictor.where = env.unwrapped.ego_xy_m + STEP_S * velocity + 6 * STEP_S * velocity + np.array([0.0, 0.3])
    obs, *_ = env.step(velocity)
    cfg = FeatureConfig(True, closest_approach=True)
    features = encode(obs, world_of(env), cfg)
    slots = features[3 + RAY_COUNT:].reshape(NEAREST, cfg.slot_size)
    present = slots[:, 0] > 0.5
    assert present.any()
    gap, when = slots[present, -2], slots[present, -1]
    assert np.allclose(gap * 5.0, 0.3, atol=0.02) and np.allclose(when, 6 / T_PRED)


def reference_slots(obs: dict[str, np.ndarray], frame: np.ndarray, cfg: FeatureConfig, max_speed_mps: float
                    ) -> np.ndarray:
    """(NEAREST, slot_size) the pedestrian slots as the module docstring defines them, one pedestrian at a time."""
    horizon = T_PRED if cfg.use_predictions and cfg.closest_approach else max(PREDICTED_STEPS)
    peds = pedestrians_of(obs, horizon, cfg.use_predictions)
    ego_xy, ego_v = obs["ego"][:2].astype(np.float64), obs["ego"][2:4].astype(np.float64)
    distance_m = np.linalg.norm(peds.xy_m - ego_xy, axis=1)
    slots = np.zeros((NEAREST, cfg.slot_size))
    for slot, p in enumerate(p for p in np.argsort(distance_m, kind="stable")[:NEAREST]
                             if distance_m[p] <= cfg.sensor_range_m):
        row = [1.0, *(frame @ (peds.xy_m[p] - ego_xy) / 5.0), *(frame @ (peds.velocity_mps[p] - ego_v) / max_speed_mps)]
        if cfg.use_predictions:
            mean = peds.futures_m[p].mean(axis=0)  # (H, 2)
            spread = np.sqrt(((peds.futures_m[p] - mean) ** 2).sum(axis=-1).mean(axis=0))
            row += [*((mean[[s - 1 for s in PREDICTED_STEPS]] - ego_xy) @ frame.T / 5.0).ravel(),
                    *(spread[[s - 1 for s in SPREAD_STEPS]] / 2.0)]
            if cfg.closest_approach:
                gap = np.linalg.norm(mean - (ego_xy + STEP_S * np.arange(1, horizon + 1)[:, None] * ego_v), axis=-1)
                row += [gap.min() / 5.0, (np.argmin(gap) + 1) / horizon]
        slots[slot] = row
    return slots


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 10_000), cfg=st.sampled_from([*CONFIGS, FeatureConfig(True, 3.0, True)]),
       env_id=st.sampled_from(["STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0"]))
def test_batched_features_are_each_observations_own(seed: int, cfg: FeatureConfig, env_id: str) -> None:
    """``encode_batch`` over observations of different moments (and goals) gives each one's features, its pedestrian
    slots as defined pedestrian by pedestrian, and ``to_velocities`` each one's velocity."""
    env = gym.make(env_id, predictor="cvm-s")
    world, rng = world_of(env), np.random.default_rng(seed)
    observations = []
    for episode in range(3):
        obs, _ = env.reset(seed=seed + episode)
        for _ in range(rng.integers(1, 12)):
            obs, _, end, cut, _ = env.step(rng.uniform(-1.5, 1.5, 2).astype(np.float32))
            if end or cut:
                break
        observations.append(obs)
    batch = {key: np.stack([obs[key] for obs in observations]) for key in observations[0]}
    frames = path_frames(batch["ego"], world)
    features = encode_batch(batch, world, cfg, frames)
    actions = rng.uniform(-1.2, 1.2, (len(observations), 2)).astype(np.float32)
    velocities = to_velocities(actions, frames, world.max_speed_mps)
    for b, obs in enumerate(observations):
        frame = path_frame(obs, world)
        np.testing.assert_array_equal(frames[b], frame)
        np.testing.assert_array_equal(features[b], encode(obs, world, cfg))
        slots = features[b, 3 + RAY_COUNT:].reshape(NEAREST, cfg.slot_size)
        np.testing.assert_allclose(slots, reference_slots(obs, frame, cfg, world.max_speed_mps), rtol=0, atol=1e-6)
        np.testing.assert_allclose(velocities[b], np.clip(actions[b], -1, 1) @ frame * world.max_speed_mps, atol=1e-6)


@settings(max_examples=10, deadline=None)
@given(cfg=st.sampled_from(CONFIGS), seed=st.integers(0, 2**32 - 1), batch=st.integers(1, 9))
def test_the_fused_attention_is_the_multi_head_attention_of_its_weights(cfg: FeatureConfig, seed: int,
                                                                        batch: int) -> None:
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed % 2**31)
    extractor = PedestrianAttention(spaces.Box(-np.inf, np.inf, (cfg.size,), np.float32), cfg)
    x = _features(cfg, rng, batch, rng.random((batch, NEAREST)) < 0.5)
    robot = extractor.robot(x[:, :extractor.robot_size])
    slots = x[:, extractor.robot_size:].reshape(-1, NEAREST, extractor.slot_size)
    keys = torch.cat([extractor.nobody.expand(batch, -1, -1), extractor.pedestrian(slots)], dim=1)
    absent = torch.cat([torch.zeros(batch, 1, dtype=torch.bool), slots[:, :, 0] < 0.5], dim=1)
    expected, _ = extractor.attend(robot[:, None], keys, keys, key_padding_mask=absent, need_weights=False)
    torch.testing.assert_close(extractor(x)[:, EMBED:], expected[:, 0], rtol=0, atol=1e-6)
