"""The fixed-size view (``envs.view``): walls seen where they are, people rotated into the robot's frame, the same
space whatever the scene's pedestrian slots, what the benchmark shows a model equal to what the wrapper showed it in
training, and hostile sizes refused."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from robot_obs import facing

import envs  # noqa: F401  (registers the ids)
from envs.common.errors import EnvInputError
from envs.common.terrain import Terrain
from envs.view import (
    RAY_COUNT,
    RAY_RANGE_M,
    FixedView,
    fixed_view,
    frames_along_path,
    to_world,
    view_sizes,
    view_space,
)
from replays.constants import T_PRED
from replays.scenes import Scene
from st_sim.apps.navigation.world import world_of

T_OBS, SAMPLES, SLOTS = 8, 3, 12
EAST = 0  # the ray along the frame's x axis
WEST = RAY_COUNT // 2


def observation(ego_xy: np.ndarray, goal_xy: np.ndarray, people_xy: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """An STCrowd observation by hand: the robot standing at ``ego_xy`` heading for ``goal_xy``, the people of
    ``people_xy`` (P, 2) standing still and forecast to walk 0.1 m per step along +y."""
    people_xy = np.zeros((0, 2)) if people_xy is None else people_xy
    count = len(people_xy)
    history = np.zeros((SLOTS, T_OBS, 2), np.float32)
    mask = np.zeros((SLOTS, T_OBS), bool)
    rows = np.arange(count) * 2 % SLOTS  # every other slot, so rows and ranks differ
    history[rows] = people_xy[:, None]
    mask[rows] = True
    futures = np.zeros((SLOTS, SAMPLES, T_PRED, 2), np.float32)
    steps = 0.1 * np.arange(1, T_PRED + 1)[:, None] * np.array([0.0, 1.0])
    futures[rows] = people_xy[:, None, None] + steps
    futures_mask = np.zeros(SLOTS, bool)
    futures_mask[rows] = True
    ego = np.array([*ego_xy, 0.0, 0.0, *goal_xy, *facing(ego_xy, np.zeros(2), goal_xy), 0.0], np.float32)
    return {"ego": ego, "history": history, "history_mask": mask, "futures": futures, "futures_mask": futures_mask}


@pytest.fixture(scope="module")
def open_terrain() -> Terrain:
    """A 20 m x 20 m map walkable everywhere (its border is the only wall)."""
    scene = Scene("open", np.diag([0.1, 0.1, 1.0]), np.ones((200, 200), bool))
    return Terrain(scene, (0.0, 0.0, 19.9, 19.9))


@pytest.mark.parametrize("body_m", [0.0, 0.3])
def test_wall_readings_shrink_as_the_robot_walks_toward_a_wall(toy_scene: Scene, body_m: float) -> None:
    """The toy map's right half (x >= 5 m) is a wall; the robot walks east along y = 5 m toward it."""
    terrain = Terrain(toy_scene, (0.0, 0.0, 9.9, 9.9))
    readings = []
    for x in np.arange(1.0, 4.6, 0.25):
        view = fixed_view(observation(np.array([x, 5.0]), np.array([4.7, 5.0])), terrain, body_m)
        readings.append(view["walls"][EAST])
        expected = min(RAY_RANGE_M, 5.0 - x - body_m)
        assert view["walls"][EAST] == pytest.approx(expected, abs=0.16), f"x={x:.2f} m: {view['walls'][EAST]}"
        assert view["walls"][WEST] == pytest.approx(min(RAY_RANGE_M, x - body_m), abs=0.16), f"x={x:.2f} m"
        assert view["walls"][RAY_COUNT // 4] == RAY_RANGE_M, f"x={x:.2f} m: nothing to the north within range"
    assert np.all(np.diff(readings) <= 0) and readings[-1] < readings[0] - 2.0, readings


@settings(max_examples=25, deadline=None)
@given(ego=st.tuples(st.floats(6.0, 14.0), st.floats(6.0, 14.0)), heading_rad=st.floats(-np.pi, np.pi),
       offsets=st.lists(st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)), min_size=0, max_size=6))
def test_the_view_rotates_people_into_the_robots_frame(open_terrain: Terrain, ego: tuple[float, float],
                                                       heading_rad: float, offsets: list) -> None:
    ego_xy = np.array(ego)
    goal_xy = ego_xy + 4.0 * np.array([np.cos(heading_rad), np.sin(heading_rad)])
    people_xy = ego_xy + np.array(offsets, dtype=np.float64).reshape(-1, 2)
    obs = observation(ego_xy, goal_xy, people_xy)
    frame = frames_along_path(obs["ego"][None], open_terrain, 0.0)[0]
    # on an open map x points at the goal, within the 64 headings and the grid's geodesic (measured: 14 degrees)
    assert frame[0] @ (goal_xy - ego_xy) / 4.0 > np.cos(np.radians(20)), "x points to the goal"
    assert np.allclose(frame @ frame.T, np.eye(2)) and np.linalg.det(frame) > 0, "a rotation, y to the left of x"
    view = fixed_view(obs, open_terrain, 0.0, nearest=4)
    robot_xy = obs["ego"][:2].astype(np.float64)
    offsets_m = obs["history"][obs["history_mask"][:, -1], -1].astype(np.float64) - robot_xy  # in row order
    ranks = np.argsort(np.linalg.norm(offsets_m, axis=1), kind="stable")[:4]
    shown = int(view["people_mask"][:, -1].sum())
    assert shown == min(4, len(offsets)) and view["futures_mask"].sum() == shown
    for slot, person in enumerate(ranks):
        rotated = frame @ offsets_m[person]
        assert np.allclose(view["people"][slot, -1], rotated, atol=1e-4), f"[slot {slot}] position"
        walked = frame @ np.array([0.0, 0.1 * T_PRED])  # the forecast's last step, turned the same way
        assert np.allclose(view["futures"][slot, :, -1], rotated + walked, atol=1e-4), f"[slot {slot}] forecast"
    assert not view["people"][shown:].any() and not view["futures"][shown:].any(), "empty slots are zeros"
    assert np.allclose(view["robot"][:2], frame @ (goal_xy - robot_xy), atol=1e-4)
    assert np.allclose(to_world(view["robot"][None, :2].astype(np.float64), frame[None])[0], goal_xy - robot_xy,
                       atol=1e-4), "to_world undoes the rotation"


def test_the_view_has_one_space_whatever_the_pedestrian_slots_and_info_follows_its_rows() -> None:
    made = {env_id: FixedView(gym.make(env_id, predictor="cvm")) for env_id in ("STCrowd-SimCrossing-v1",
                                                                                "STCrowd-Univ-v0")}
    crossing, univ = (env.observation_space for env in made.values())
    assert crossing == univ and view_sizes(crossing) == (8, RAY_COUNT, 8, 20)
    for env_id, env in made.items():
        assert env.unwrapped.n_max != 8
        obs, info = env.reset(seed=4)
        for t in range(4):
            assert env.observation_space.contains(obs), f"[{env_id} step {t}]"
            assert info["agent_ids"].shape == (8,) and info["predicted_ids"].shape == (8,), f"[{env_id} step {t}]"
            assert np.array_equal(info["agent_ids"] >= 0, obs["people_mask"][:, -1] > 0), f"[{env_id} step {t}]"
            obs, _, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
            if terminated or truncated:
                break
        env.close()


def test_the_benchmark_shows_a_model_what_the_wrapper_showed_it() -> None:
    """``fixed_view`` on the raw observation with the planners' ``NavWorld`` (the benchmark's sb3 path) equals the
    wrapper's observation, and an action in the robot's frame moves the robot the same way in both."""
    wrapped = FixedView(gym.make("STCrowd-Zara1-v0", predictor="cvm"), nearest=5, rays=12)
    raw = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    world = world_of(raw)
    (seen, _), (obs, _) = wrapped.reset(seed=2), raw.reset(seed=2)
    for t in range(5):
        frame = frames_along_path(obs["ego"][None], world.terrain, world.wall_clearance_m)[0]
        benchmark_view = fixed_view(obs, world.terrain, world.wall_clearance_m, 5, 12, frame)
        for key, value in seen.items():
            assert np.array_equal(value, benchmark_view[key]), f"[step {t}] {key} differs"
        action = np.array([0.8, -0.3])
        seen, *_ = wrapped.step(action)
        obs, *_ = raw.step(to_world(action[None], frame[None])[0])


@pytest.mark.parametrize("sizes", [{"nearest": 0}, {"rays": -2}, {"nearest": True}, {"rays": 2.5},
                                   {"nearest": "8"}], ids=str)
def test_view_sizes_that_are_not_counts_are_refused(sizes: dict) -> None:
    with pytest.raises(EnvInputError, match=f"FixedView: {next(iter(sizes))}="):
        FixedView(gym.make("STCrowd-SimCorridor-v1", predictor="none"), **sizes)


def test_a_spectator_env_has_no_view() -> None:
    with pytest.raises(EnvInputError, match="with an ego"):
        FixedView(gym.make("STCrowd-SimCorridor-v1", predictor="none", ego=False))


def test_only_a_views_space_is_taken_for_one() -> None:
    space = view_space(6, 10, 8, 20)
    assert view_sizes(space) == (6, 10, 8, 20)
    unbounded = gym.spaces.Dict({key: gym.spaces.Box(-np.inf, np.inf, box.shape, np.float32)
                                 for key, box in space.spaces.items()})
    assert view_sizes(unbounded) == (6, 10, 8, 20), "a model file states no bounds"
    wrong = dict(space.spaces, futures=gym.spaces.Box(-1, 1, (6, 20, 5, 2), np.float32))
    assert view_sizes(gym.spaces.Dict(wrong)) is None
    assert view_sizes(gym.spaces.Dict({k: v for k, v in space.spaces.items() if k != "walls"})) is None
    assert view_sizes(gym.spaces.Box(-1, 1, (4,))) is None


@pytest.mark.parametrize("env_id", ["STCrowd-SimBottleneck-v1", "STCrowd-Univ-v0"])
def test_the_view_reads_the_walls_the_shipped_ppo_planner_reads(env_id: str) -> None:
    """docs/environments.md and docs/training.md: the view's wall readings are the shipped PPO planner's (its
    features call the same ``envs.view.wall_readings_m``): the same distances along the same rays."""
    from st_sim.apps.navigation.features import FeatureConfig, encode

    viewed = FixedView(gym.make(env_id, predictor="cvm"))
    raw = gym.make(env_id, predictor="cvm")
    world = world_of(raw)
    (seen, _), (obs, _) = viewed.reset(seed=5), raw.reset(seed=5)
    assert seen["walls"].shape == (RAY_COUNT,)
    walls_in_reach = 0
    for t in range(6):
        features = encode(obs, world, FeatureConfig())
        np.testing.assert_allclose(features[3:3 + RAY_COUNT] * RAY_RANGE_M, seen["walls"], rtol=0, atol=1e-5,
                                   err_msg=f"[step {t}]")
        walls_in_reach += bool(seen["walls"].min() < RAY_RANGE_M)
        frame = frames_along_path(obs["ego"][None], world.terrain, world.wall_clearance_m)[0]
        action = np.array([1.2, 0.3 * t - 0.6])  # in the robot's frame
        seen, _, terminated, truncated, _ = viewed.step(action)
        obs, *_ = raw.step(to_world(action[None], frame[None])[0])
        if terminated or truncated:
            break
    assert walls_in_reach, "no wall was in reach: nothing was compared"
