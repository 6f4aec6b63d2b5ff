"""What a planner knows besides the observation: the robot's body and limits, the pedestrians' size, the map, and
how likely each predicted sample is."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import gymnasium as gym
import numpy as np

from replays.constants import STEP_S
from replays.scenes import Scene
from st_sim.apps.navigation.sample_prior import sample_prior
from st_sim.apps.navigation.terrain import Terrain


@dataclass(frozen=True, eq=False)
class NavWorld:
    """Static facts of one env for its planners (metres, seconds).

    Attributes:
        scene: the walkability map.  bounds_m: (xmin, ymin, xmax, ymax) where the ego can be [m].
        ego_radius_m, pedestrian_radius_m: body radii [m].
        max_speed_mps: the ego's speed limit [m/s].
        max_accel_mps2: how fast the ego's velocity follows the command [m/s^2] (the env's
            ``ego_max_accel_mps2``; inf for the replays' point robot).
        goal_radius_m: the goal counts as reached this close [m].
        wall_clearance_m: least distance the ego's centre keeps from non-walkable ground [m]: its radius
            where walls are solid (simulated crowds: touching one is a collision), 0 where they are only
            marked on the map (replays: an off-map step costs reward but does not end the episode).
        sample_prior: (S,) how likely each predicted sample index is (sums to 1), for a predictor whose samples
            are ordered (a shipped SingularTrajectory checkpoint, ``sample_prior.sample_prior``); None: the
            samples are equally likely.
    """

    scene: Scene
    bounds_m: tuple[float, float, float, float]
    ego_radius_m: float = 0.3
    pedestrian_radius_m: float = 0.25
    max_speed_mps: float = 1.5
    max_accel_mps2: float = float("inf")
    goal_radius_m: float = 0.5
    wall_clearance_m: float = 0.0
    sample_prior: np.ndarray | None = None
    step_s: float = STEP_S

    def __repr__(self) -> str:
        return f"NavWorld({self.scene.name}, ego {self.ego_radius_m} m, {self.max_speed_mps} m/s)"

    @property
    def action_space(self) -> gym.spaces.Box:
        """The env's action space: a (2,) velocity command, each axis within +-``max_speed_mps`` [m/s]."""
        return gym.spaces.Box(-self.max_speed_mps, self.max_speed_mps, (2,), np.float32)

    @property
    def contact_m(self) -> float:
        """Centre distance at which the ego touches a pedestrian [m]."""
        return self.ego_radius_m + self.pedestrian_radius_m

    @cached_property
    def terrain(self) -> Terrain:
        """Wall clearance and cost-to-go grid of the map (built on first use)."""
        return Terrain(self.scene, self.bounds_m)


def world_of(env: gym.Env) -> NavWorld:
    """The ``NavWorld`` of an STCrowd env with an ego (a replay or a simulated crowd)."""
    crowd_env = env.unwrapped
    cfg = crowd_env.cfg
    prior = sample_prior(getattr(crowd_env.predictor, "source", None), crowd_env.num_samples)
    if hasattr(crowd_env, "layout"):  # simulated: the simulator's bodies and layout bounds, solid walls
        return NavWorld(crowd_env.scene, tuple(crowd_env.layout.bounds_m), cfg.ego_radius_m,
                        crowd_env.crowd_cfg.radius_m, cfg.max_speed_mps, crowd_env.ego_max_accel_mps2,
                        cfg.goal_radius_m, cfg.ego_radius_m, prior)
    bounds = (*np.asarray(crowd_env.arena_low_m).tolist(), *np.asarray(crowd_env.arena_high_m).tolist())
    return NavWorld(crowd_env.scene, bounds, cfg.ego_radius_m, cfg.pedestrian_radius_m, cfg.max_speed_mps,
                    crowd_env.ego_max_accel_mps2, cfg.goal_radius_m, 0.0, prior)
