"""What a planner knows besides the observation: the robot's body and limits, the pedestrians' size, the map, and
how likely each predicted sample is."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import gymnasium as gym
import numpy as np

from envs.common.terrain import Terrain
from replays.constants import STEP_S
from replays.scenes import Scene
from st_sim.apps.navigation.sample_prior import sample_prior
from st_sim.sim.robot import ROBOTS, RobotSpec, command_toward


@dataclass(frozen=True, eq=False)
class NavWorld:
    """Static facts of one env for its planners (metres, seconds).

    Attributes:
        scene: the walkability map.  bounds_m: (xmin, ymin, xmax, ymax) where the ego can be [m].
        ego_radius_m, pedestrian_radius_m: body radii [m].
        robot: the robot's kind and limits (the env's ``robot``, ``st_sim.sim.robot.RobotSpec``).
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
    robot: RobotSpec = ROBOTS["holonomic"]
    goal_radius_m: float = 0.5
    wall_clearance_m: float = 0.0
    sample_prior: np.ndarray | None = None
    step_s: float = STEP_S

    def __repr__(self) -> str:
        return f"NavWorld({self.scene.name}, ego {self.ego_radius_m} m, {self.max_speed_mps} m/s)"

    @property
    def max_speed_mps(self) -> float:
        """The robot's speed limit [m/s]."""
        return self.robot.max_speed_mps

    @property
    def action_space(self) -> gym.spaces.Box:
        """The env's action space: the robot's (2,) command within its limits (a holonomic robot's velocity [m/s])."""
        return gym.spaces.Box(self.robot.command_low.astype(np.float32), self.robot.command_high.astype(np.float32),
                              dtype=np.float32)

    def command_for(self, obs: dict[str, np.ndarray], velocity_mps: np.ndarray) -> np.ndarray:
        """(2,) the robot's command that drives it toward the (2,) velocity [m/s] a planner wishes
        (``st_sim.sim.robot.command_toward``, from the heading in ``obs["ego"]``): the velocity itself for a
        holonomic robot."""
        if self.robot.kind == "holonomic":
            return np.asarray(velocity_mps)
        heading = np.asarray(obs["ego"][6:8], np.float64)
        return command_toward(self.robot, heading[None], np.asarray(velocity_mps, np.float64)[None])[0]

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
    # the pedestrians' size: a simulated crowd's bodies, else the replay collision test's radius
    crowd = getattr(crowd_env, "crowd_cfg", None)
    pedestrian_radius_m = cfg.pedestrian_radius_m if crowd is None else crowd.radius_m
    return NavWorld(crowd_env.scene, crowd_env.bounds_m, cfg.ego_radius_m, pedestrian_radius_m, crowd_env.robot,
                    cfg.goal_radius_m, crowd_env.wall_clearance_m, prior)
