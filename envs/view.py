"""A fixed-size view of an STCrowd observation, walls included: the same space in every scene.

    from envs.view import FixedView
    env = FixedView(gym.make("STCrowd-Univ-v0", predictor="cvm"))   # what STCrowd-Suite-v1 shows of each scenario
    obs, info = env.reset(seed=0)               # obs["people"]: (K, T_obs, 2) whatever the scene's pedestrian slots
    obs, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))   # 1 m/s along the path to the goal

An env's own observation has one row per pedestrian slot (40 in the simulated crossing, 27 in ETH, 75 in UNIV) and
no walls. The view keeps the K pedestrians nearest to the robot and R range readings of the map, in the robot's
frame: origin at the robot, x along the shortest walkable path to the goal (``Terrain.direction_to``; the frame of
the shipped PPO planner's features), y to its left. Every entry is float32, in that frame:

- ``robot`` (4,): the goal relative to the robot (x, y) [m]; the robot's velocity (x, y) [m/s] (speeds up to the
  robots' 10 m/s limit are well inside the bounds, 2000); for a differential-drive robot (7,): then the unit vector
  it faces (x, y) and its turn rate [rad/s];
- ``walls`` (R,): free distance along R rays, ray r at angle 2 pi r / R from x (anticlockwise), until the robot's body
  would touch a wall (replays: until its centre leaves walkable ground), up to ``RAY_RANGE_M`` [m];
- ``people`` (K, T_obs, 2): the K nearest pedestrians present now, nearest first (ties in row order): their histories
  relative to the robot now [m], 0 where not observed; ``people_mask`` (K, T_obs): 1 where observed, else 0;
- ``futures`` (K, S, T_pred, 2): their S forecast paths relative to the robot now [m], 0 without a forecast;
  ``futures_mask`` (K,): 1 for a pedestrian with a forecast.

The action of a holonomic robot is a (2,) velocity [m/s] in the same frame, with the env's bounds; ``FixedView`` turns
it into the world frame for the env. A differential-drive robot's command (v, w) is its own frame's already: it goes
to the env as it is. The info arrays with one entry per observation row (``ROW_INFO_KEYS``: ``agent_ids``, ...)
come with one entry per view row, -1 for an empty slot. A model trained on the view (``FixedView``,
``STCrowd-Suite-v1``) runs in every scenario: ``python -m st_sim benchmark --policy sb3:PATH.zip`` sees the view's
keys in the model's observation space and shows it each scenario through ``fixed_view``.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs.common.ego import checked_command
from envs.common.errors import EnvInputError
from envs.common.terrain import Terrain
from replays.constants import FORECAST_LIMIT_M, POSITION_LIMIT_M, T_PRED
from st_sim.sim.exact import rounded_cos_sin

NEAREST = 8  # pedestrians in the view by default [-]
RAY_COUNT = 16  # wall rays by default, evenly spaced from the path direction [-]
RAY_RANGE_M = 3.0  # rays see this far [m]
RAY_STEP_M = 0.1  # ray sampling interval [m]
VIEW_KEYS: tuple[str, ...] = ("robot", "walls", "people", "people_mask", "futures", "futures_mask")
"""the view's keys: a Dict space holding exactly these is a view's (``view_sizes``)"""


ROBOT_FIELDS = (4, 7)  # size of the view's robot entry: a holonomic robot's, a differential drive's (heading, turn)
ROW_INFO_KEYS: tuple[str, ...] = ("agent_ids", "predicted_ids", "group_ids")
"""info arrays with one entry per observation row: ``FixedView`` gives them one per view row (-1: an empty slot)"""


def check_view_sizes(nearest: Any, rays: Any, where: str) -> None:
    """Refuse K = ``nearest`` or R = ``rays`` that is not an int >= 1 (``EnvInputError`` naming ``where``)."""
    for name, value in (("nearest", nearest), ("rays", rays)):
        if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer) or value < 1:
            raise EnvInputError(f"{where}: {name}={value!r}: expected an int >= 1")


def view_space(nearest: int, rays: int, t_obs: int, samples: int, turning: bool = False) -> spaces.Dict:
    """The view's space for K = ``nearest`` pedestrians, R = ``rays`` walls, T_obs observed steps, S samples, of a
    robot that turns (``turning``: a differential drive, whose ``robot`` entry holds its heading and turn rate too);
    its bounds are those of the envs' observations (positions within ``POSITION_LIMIT_M``, forecasts within
    ``FORECAST_LIMIT_M``) taken relative to the robot."""
    def box(shape: tuple[int, ...], high: float, low: float | None = None) -> spaces.Box:
        return spaces.Box(-high if low is None else low, high, shape, np.float32)

    near_m, far_m = 2 * POSITION_LIMIT_M, FORECAST_LIMIT_M + POSITION_LIMIT_M
    robot_fields = ROBOT_FIELDS[1] if turning else ROBOT_FIELDS[0]
    return spaces.Dict({"robot": box((robot_fields,), near_m), "walls": box((rays,), RAY_RANGE_M, 0.0),
                        "people": box((nearest, t_obs, 2), near_m), "people_mask": box((nearest, t_obs), 1.0, 0.0),
                        "futures": box((nearest, samples, T_PRED, 2), far_m),
                        "futures_mask": box((nearest,), 1.0, 0.0)})


def view_sizes(space: spaces.Space) -> tuple[int, int, int, int] | None:
    """(K, R, T_obs, S) of a view's space: a Dict of exactly ``VIEW_KEYS`` with the view's shapes and dtypes (bounds
    aside: a model file states none); None for any other space."""
    if not isinstance(space, spaces.Dict) or set(space.spaces) != set(VIEW_KEYS):
        return None
    people, walls, futures = space["people"].shape, space["walls"].shape, space["futures"].shape
    if len(people) != 3 or len(walls) != 1 or len(futures) != 4:
        return None
    sizes = (people[0], walls[0], people[1], futures[1])
    if min(sizes) < 1:
        return None
    view = view_space(*sizes, turning=space["robot"].shape == (ROBOT_FIELDS[1],))
    fits = all(isinstance(space[key], spaces.Box) and (space[key].shape, space[key].dtype) == (view[key].shape,
                                                                                              view[key].dtype)
               for key in VIEW_KEYS)
    return sizes if fits else None


def frames_along_path(ego: np.ndarray, terrain: Terrain, body_m: float) -> np.ndarray:
    """(B, 2, 2) robot frames of B observations' ego rows ``obs["ego"]`` (B, 6): row 0 the unit x axis along the
    shortest walkable path to the goal for a body of radius ``body_m`` (+x of the world at the goal), row 1 y, to its
    left; world frame."""
    xy, goal = ego[:, :2].astype(np.float64), ego[:, 4:6].astype(np.float64)
    x_axis = terrain.directions_to(xy, goal, body_m)
    x_axis[~x_axis.any(axis=1)] = (1.0, 0.0)
    return np.stack([x_axis, np.stack([-x_axis[:, 1], x_axis[:, 0]], axis=1)], axis=1)


def to_world(vectors: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """(B, 2) vectors given in B frames (B, 2, 2) -> (B, 2) the same vectors in the world frame."""
    return np.einsum("bi,bij->bj", vectors, frames)


def wall_readings_m(terrain: Terrain, xy_m: np.ndarray, frames: np.ndarray, body_m: float,
                    rays: int = RAY_COUNT) -> np.ndarray:
    """(B, R) free distances [m] from B points (B, 2) [m] along R rays per frame (B, 2, 2), ray r at angle 2 pi r / R
    from the frame's x axis, until a body of radius ``body_m`` would touch a wall; up to ``RAY_RANGE_M``."""
    cos, sin = _ray_cos_sin(rays)
    directions = cos[:, None] * frames[:, None, 0] + sin[:, None] * frames[:, None, 1]
    return terrain.free_distances_m(xy_m, directions, body_m, RAY_RANGE_M, RAY_STEP_M)


@cache
def _ray_cos_sin(rays: int) -> tuple[np.ndarray, np.ndarray]:
    """(R,) cosines and sines of the R ray angles 2 pi r / R, the same on every CPU (libm's are not)."""
    return rounded_cos_sin(np.arange(rays) * 2 * np.pi / rays)


def nearest_pedestrians(obs: dict[str, np.ndarray], ego_xy_m: np.ndarray, sensor_range_m: float, count: int
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The ``count`` present pedestrians of B batched observations nearest to the robots at ``ego_xy_m`` (B, 2) [m],
    nearest first (ties in row order), and which of them are within ``sensor_range_m``: ((B, count) observation
    rows, (B, count) bool; False for slots beyond the pedestrians present, whose rows point at a real, absent row)."""
    present = obs["history_mask"][:, :, -1]  # (B, N)
    distance_m = np.linalg.norm(obs["history"][:, :, -1].astype(np.float64) - ego_xy_m[:, None], axis=-1)
    distance_m[~present] = np.inf
    if distance_m.shape[1] < count:
        distance_m = np.pad(distance_m, ((0, 0), (0, count - distance_m.shape[1])), constant_values=np.inf)
    nearest = np.argsort(distance_m, axis=1, kind="stable")[:, :count]
    chosen = np.take_along_axis(distance_m, nearest, axis=1)
    nearest = np.minimum(nearest, obs["history"].shape[1] - 1)
    return nearest, np.isfinite(chosen) & (chosen <= sensor_range_m)


def fixed_view(obs: dict[str, np.ndarray], terrain: Terrain, body_m: float, nearest: int = NEAREST,
               rays: int = RAY_COUNT, frame: np.ndarray | None = None, turning: bool = False) -> dict[str, np.ndarray]:
    """The view (see the module docstring) of one STCrowd observation with an ego, on the env's ``terrain`` with its
    ``wall_clearance_m`` as ``body_m``; ``frame``: its ``frames_along_path`` (2, 2) if already computed; ``turning``:
    the robot entry of a differential drive (with its heading and turn rate)."""
    ego = obs["ego"].astype(np.float64)
    xy = ego[:2]
    frame = frames_along_path(ego[None], terrain, body_m)[0] if frame is None else frame
    rows, sensed = nearest_pedestrians({key: obs[key][None] for key in ("history", "history_mask")}, xy[None],
                                       np.inf, nearest)
    rows, sensed = rows[0], sensed[0]
    people_mask = obs["history_mask"][rows] & sensed[:, None]  # (K, T_obs)
    people = np.where(people_mask[..., None], (obs["history"][rows].astype(np.float64) - xy) @ frame.T, 0.0)
    futures_mask = obs["futures_mask"][rows] & sensed  # (K,)
    futures = np.where(futures_mask[:, None, None, None],
                       (obs["futures"][rows].astype(np.float64) - xy) @ frame.T, 0.0)
    robot = np.concatenate([frame @ (ego[4:6] - xy), frame @ ego[2:4]]
                           + ([frame @ ego[6:8], ego[8:9]] if turning else []))
    walls = wall_readings_m(terrain, xy[None], frame[None], body_m, rays)[0]
    return {"robot": robot.astype(np.float32), "walls": walls.astype(np.float32), "people": people.astype(np.float32),
            "people_mask": people_mask.astype(np.float32), "futures": futures.astype(np.float32),
            "futures_mask": futures_mask.astype(np.float32)}


class FixedView(gym.Wrapper):
    """An STCrowd env with an ego seen through ``fixed_view``, acting in the robot's frame (module docstring): a
    holonomic robot's velocity turned into the world frame, a differential drive's (v, w) as it is.

    Args:
        env: a replay or simulated crowd env (``gym.make`` of an STCrowd id) with ``ego=True``.
        nearest: K, pedestrians in the view, an int >= 1.  rays: R, wall readings, an int >= 1.
    """

    def __init__(self, env: gym.Env, nearest: int = NEAREST, rays: int = RAY_COUNT):
        super().__init__(env)
        check_view_sizes(nearest, rays, "FixedView")
        crowd = env.unwrapped
        if not hasattr(crowd, "wall_clearance_m") or not getattr(crowd, "ego", False):
            raise EnvInputError(f"FixedView: {crowd!r} is not an STCrowd crowd env with an ego (ego=True)")
        self.nearest, self.rays = int(nearest), int(rays)
        self.terrain = Terrain(crowd.scene, crowd.bounds_m)
        self.body_m = crowd.wall_clearance_m
        self.turning = crowd.robot.kind == "diff-drive"
        self.observation_space = view_space(self.nearest, self.rays, crowd.t_obs, crowd.num_samples, self.turning)
        self._frame: np.ndarray | None = None  # the robot's frame of the last observation, for the next action

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        return self._see(*self.env.reset(seed=seed, options=options))

    def step(self, action: Any):
        if self._frame is None:  # not reset yet: the env says so
            return self.env.step(action)
        command = checked_command(action, self.env.unwrapped.robot.command_names)
        if not self.turning:
            command = to_world(command[None], self._frame[None])[0]
        obs, reward, terminated, truncated, info = self.env.step(command)
        obs, info = self._see(obs, info)
        return obs, reward, terminated, truncated, info

    def _see(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """The view of ``obs``, and ``info`` with its ``ROW_INFO_KEYS`` arrays on the view's rows."""
        self._frame = frames_along_path(obs["ego"][None], self.terrain, self.body_m)[0]
        rows, sensed = nearest_pedestrians({key: obs[key][None] for key in ("history", "history_mask")},
                                           obs["ego"][None, :2].astype(np.float64), np.inf, self.nearest)
        info = {**info, **{key: np.where(sensed[0], info[key][rows[0]], -1) for key in ROW_INFO_KEYS if key in info}}
        return fixed_view(obs, self.terrain, self.body_m, self.nearest, self.rays, self._frame, self.turning), info
