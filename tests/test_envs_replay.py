"""Replay environments: positions follow the recording, the prediction stream equals the benchmark windows."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import envs  # noqa: F401  (registers the ids)
import predictor
from envs.common.errors import ActionError
from envs.common.predictors import PredictorUnavailableError
from envs.common.tracks import Frame, TooManyAgentsError, TrackBuffer
from predictor.baselines import ConstantVelocity
from replays import load_windows, read_recording
from replays.constants import COORD_DECIMALS, T_PRED, TASKS
from st_sim.metrics import ade_fde

SCENE_IDS = ("Eth", "Hotel", "Univ", "Zara1", "Zara2")
DESIGN_N_MAX = {"Eth": 27, "Hotel": 18, "Univ": 75, "Zara1": 20, "Zara2": 20}  # DESIGN.md section 6


def full_replay(task: str, scene: str = "Zara1", predictor_name: str = "cvm") -> list[dict]:
    """Spectator run over the whole recording; per step: frame, predicted ids, present ids, metrics."""
    env = gym.make(f"STCrowd-{scene}-v0", ego=False, task=task, predictor=predictor_name,
                   max_episode_steps=100_000)
    _, info = env.reset(seed=0, options={"start_index": 0})
    steps = [info]
    truncated = False
    while not truncated:
        _, _, _, truncated, info = env.step(env.action_space.sample())
        steps.append(info)
    return steps


def matured_samples(steps: list[dict], t_obs: int) -> set[tuple[int, int]]:
    """(first frame of window, agent) of predictions present in all 12 later frames, >= 2 per step."""
    present = [set(info["agent_ids"][info["agent_ids"] >= 0].tolist()) for info in steps]
    samples = set()
    for t in range(len(steps) - T_PRED):
        predicted = steps[t]["predicted_ids"][steps[t]["predicted_ids"] >= 0].tolist()
        matured = [a for a in predicted if all(a in present[t + k] for k in range(1, T_PRED + 1))]
        if len(matured) >= 2:
            samples |= {(steps[t - t_obs + 1]["frame"], a) for a in matured}
    return samples


@pytest.mark.parametrize("task", ["stochastic", "momentary"])
def test_replay_spectator_stream_equals_benchmark_windows(task: str) -> None:
    steps = full_replay(task)
    windows = load_windows(task, "zara1", "test")
    expected = set(zip(windows.frame.tolist(), windows.agent.tolist(), strict=True))
    got = matured_samples(steps, TASKS[task]["obs_len"])
    assert got == expected, f"{len(got - expected)} extra, {len(expected - got)} missing samples"
    ade, fde = ade_fde(ConstantVelocity().predict(windows.obs, windows.group, None, 20), windows.fut)
    metrics = steps[-1]["metrics"]
    assert metrics["matured"] == len(windows)
    assert metrics["ade_m"] == pytest.approx(ade.mean(), abs=1e-6)
    assert metrics["fde_m"] == pytest.approx(fde.mean(), abs=1e-6)


@pytest.mark.parametrize("scene", SCENE_IDS, ids=SCENE_IDS)
def test_replay_positions_equal_recording(scene: str) -> None:
    env = gym.make(f"STCrowd-{scene}-v0")
    unwrapped = env.unwrapped
    recording = read_recording(unwrapped.replay.path)
    obs, info = env.reset(seed=5)
    for t in range(25):
        rows = recording.frame == info["frame"]
        expected = dict(zip(recording.agent[rows].tolist(), recording.xy_m[rows], strict=True))
        present = info["agent_ids"] >= 0
        assert sorted(info["agent_ids"][present].tolist()) == sorted(expected), f"[step {t}] agents differ"
        for row in np.flatnonzero(present):
            want = np.round(expected[int(info["agent_ids"][row])], COORD_DECIMALS).astype(np.float32)
            assert np.array_equal(obs["history"][row, -1], want), f"[step {t}] row {row} position"
        obs, _, terminated, truncated, info = env.step(np.zeros(2))
        assert not truncated, f"[step {t}] truncated early"
        if terminated:
            break


@pytest.mark.parametrize("scene", SCENE_IDS, ids=SCENE_IDS)
def test_replay_n_max_is_the_scenes_busiest_frame(scene: str) -> None:
    env = gym.make(f"STCrowd-{scene}-v0")
    assert env.observation_space["history"].shape[0] == DESIGN_N_MAX[scene]


def test_replay_univ_recording_is_selectable() -> None:
    env = gym.make("STCrowd-Univ-v0", recording="students003")
    assert env.unwrapped.replay.path.stem == "students003"
    assert env.observation_space["history"].shape[0] == DESIGN_N_MAX["Univ"]  # same spaces for both
    with pytest.raises(ValueError, match="students001"):
        gym.make("STCrowd-Univ-v0", recording="crowds_zara01")


@pytest.mark.parametrize("task, t_obs, samples", [("deterministic", 8, 1), ("momentary", 2, 20)])
def test_replay_task_sets_history_and_sample_counts(task: str, t_obs: int, samples: int) -> None:
    env = gym.make("STCrowd-Hotel-v0", task=task)
    obs, _ = env.reset(seed=0)
    assert obs["history"].shape[1] == t_obs
    assert obs["futures"].shape[1:] == (samples, T_PRED, 2)
    with pytest.raises(ValueError, match="task"):
        gym.make("STCrowd-Hotel-v0", task="fewshot")


def test_replay_spectator_ignores_action_and_gives_no_reward() -> None:
    env = gym.make("STCrowd-Eth-v0", ego=False)
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.array([np.nan, np.inf]))
    assert reward == 0.0 and not terminated
    assert not obs["ego"].any()
    assert set(info["reward_parts"].values()) == {0.0}
    with pytest.raises(ActionError, match="dtype"):  # the value is unused, but the kind is still checked
        env.step(np.array([1 + 1j, 0]))


def test_a_replay_reports_no_groups() -> None:
    """docs/environments.md: replays have no groups and no ``info["group_ids"]`` entry (the simulated envs do)."""
    for pedestrians in ("log", "reactive"):
        env = gym.make("STCrowd-Hotel-v0", predictor="cvm", pedestrians=pedestrians)
        _, info = env.reset(seed=0)
        _, _, _, _, stepped = env.step(np.zeros(2))
        assert "group_ids" not in info and "group_ids" not in stepped, pedestrians
    _, info = gym.make("STCrowd-SimCorridor-v1", predictor="cvm").reset(seed=0)
    assert info["group_ids"].shape == info["agent_ids"].shape


def test_replay_collision_terminates_with_penalty() -> None:
    env = gym.make("STCrowd-Zara1-v0")
    _, info = env.reset(seed=0, options={"start_index": 100})
    unwrapped = env.unwrapped
    next_frame = unwrapped.replay.frame(101)
    unwrapped.ego_xy_m = next_frame.xy_m[0].copy()  # stand where a pedestrian will be
    _, reward, terminated, _, info = env.step(np.zeros(2))
    assert terminated and info["reward_parts"]["pedestrian_collision"] == 1.0
    assert info["metrics"]["ego_collisions"] == 1
    assert reward <= unwrapped.cfg.reward.collision + 1.0


def test_replay_goal_reached_terminates() -> None:
    env = gym.make("STCrowd-Zara2-v0")
    env.reset(seed=0)
    unwrapped = env.unwrapped
    unwrapped.goal_m = unwrapped.ego_xy_m + np.array([0.5, 0.0])
    _, _, terminated, _, info = env.step(np.array([1.0, 0.0]))
    assert info["reward_parts"]["goal"] == 1.0 and terminated
    # from standing, 2 m/s^2 over two 0.2 s substeps: 0.4 m/s then 0.8 m/s, 0.24 m in all
    assert info["reward_parts"]["progress"] == pytest.approx(0.24)


def test_replay_ego_spawns_free_and_walkable() -> None:
    env = gym.make("STCrowd-Univ-v0")
    for seed in range(5):
        obs, info = env.reset(seed=seed)
        unwrapped = env.unwrapped
        assert unwrapped.scene.is_walkable(obs["ego"][:2]) and unwrapped.scene.is_walkable(obs["ego"][4:6])
        peds = obs["history"][obs["history_mask"][:, -1], -1]
        assert np.min(np.linalg.norm(peds - obs["ego"][:2], axis=1)) >= unwrapped.cfg.spawn_clearance_m - 1e-5
        assert info["metrics"]["min_ego_ped_distance_m"] >= unwrapped.cfg.spawn_clearance_m - 1e-5


def test_replay_render_draws_on_the_photo() -> None:
    env = gym.make("STCrowd-Zara1-v0", render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    photo = env.unwrapped.scene.photo
    assert image.shape == photo.shape and image.dtype == np.uint8
    assert (image != photo).any(), "nothing drawn"


class ShiftedCVM(ConstantVelocity):
    """CVM moved 1 m along x: a user-supplied predictor object."""

    def predict(self, obs, group, scene, num_samples):
        assert (group == group[0]).all(), "agents of one step share a group"
        return super().predict(obs, group, scene, num_samples) + np.float32(1.0)


class NaNPredictor(ConstantVelocity):
    def predict(self, obs, group, scene, num_samples):
        return np.full((len(obs), num_samples, T_PRED, 2), np.nan, np.float32)


def test_replay_uses_a_user_predictor_object() -> None:
    own = gym.make("STCrowd-Zara1-v0", predictor=ShiftedCVM())
    cvm = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    (obs_own, _), (obs_cvm, _) = own.reset(seed=2), cvm.reset(seed=2)
    assert obs_own["futures_mask"].any()
    rows = obs_own["futures_mask"]
    assert np.allclose(obs_own["futures"][rows], obs_cvm["futures"][rows] + 1.0)


def test_replay_rejects_predictor_returning_nan() -> None:
    env = gym.make("STCrowd-Zara1-v0", predictor=NaNPredictor())
    with pytest.raises(ValueError, match="NaN"):
        env.reset(seed=0)


class ShippedStandIn(ShiftedCVM):
    """Stands in for a shipped SingularTrajectory checkpoint: moves to a device as one does."""

    def to(self, device: str) -> ShippedStandIn:
        self.device = device
        return self


def test_replay_singular_loads_the_scenes_leave_one_out_checkpoint(monkeypatch: pytest.MonkeyPatch) -> None:
    asked = []
    monkeypatch.setattr(predictor, "load_pretrained", lambda name: asked.append(name) or ShippedStandIn(),
                        raising=False)
    env = gym.make("STCrowd-Zara1-v0", predictor="singular")
    assert asked == ["stochastic/zara1"] and isinstance(env.unwrapped.predictor, ShippedStandIn)
    assert env.unwrapped.predictor.device == "auto"  # the env's default device
    gym.make("STCrowd-Hotel-v0")  # the default ("auto") is SingularTrajectory for the stochastic task
    assert asked[-1] == "stochastic/hotel"
    gym.make("STCrowd-Hotel-v0", task="momentary")  # 2 observed frames: the 2-frame leave-one-out model
    assert asked[-1] == "momentary/hotel"


def test_replay_singular_without_checkpoint_gives_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    def missing(name: str):
        raise FileNotFoundError(f"no checkpoint {name}")

    monkeypatch.setattr(predictor, "load_pretrained", missing, raising=False)
    with pytest.raises(PredictorUnavailableError, match="'stochastic/zara1' SingularTrajectory checkpoint"):
        gym.make("STCrowd-Zara1-v0", predictor="singular")
    with pytest.raises(ValueError, match="cvm"):
        gym.make("STCrowd-Zara1-v0", predictor="nonsense")


def test_replay_start_index_out_of_range_is_rejected() -> None:
    env = gym.make("STCrowd-Zara1-v0")
    n_frames = len(env.unwrapped.replay.frames)
    with pytest.raises(ValueError, match="start_index"):
        env.reset(options={"start_index": n_frames - 1})


def test_tracks_refuse_more_agents_than_rows() -> None:
    tracks = TrackBuffer(n_max=2, t_obs=8, where="toy")
    with pytest.raises(TooManyAgentsError, match="N_max = 2"):
        tracks.push(Frame(0, np.arange(3), np.zeros((3, 2))))


def test_tracks_keep_an_agents_row_while_present() -> None:
    tracks = TrackBuffer(n_max=3, t_obs=2, where="toy")
    tracks.push(Frame(0, np.array([5, 7]), np.zeros((2, 2))))
    row_of_7 = int(np.flatnonzero(tracks.row_ids == 7)[0])
    tracks.push(Frame(1, np.array([9, 7]), np.ones((2, 2))))  # 5 left, 9 arrived
    assert tracks.row_ids[row_of_7] == 7
    assert sorted(tracks.row_ids[tracks.row_ids >= 0].tolist()) == [7, 9]
    _, mask = tracks.history()
    assert mask[row_of_7].all() and mask[tracks.row_ids == 9].tolist() == [[False, True]]
    assert tracks.run_of(np.array([7, 9, 5])).tolist() == [2, 1, 0]

