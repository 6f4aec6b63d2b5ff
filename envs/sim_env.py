"""A pymunk-simulated crowd in a synthetic layout or a real scene's geometry, or a scripted encounter, with an ego
robot among it."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from envs.common.config import EnvConfig
from envs.common.crowd_env import CrowdEnv
from envs.common.errors import EnvInputError
from envs.common.layouts import build_layout
from envs.common.predictors import shipped_checkpoint
from envs.common.tracks import Frame, lookup
from replays.constants import STEP_S
from replays.scenes import SCENES
from st_sim.perception import SensingSpec
from st_sim.sim import CrowdConfig, CrowdSim, EgoConfig, Layout, PopulationConfig
from st_sim.sim import population_cap as sim_population_cap
from st_sim.sim.crowd import step_crowds
from st_sim.sim.encounters import ENCOUNTERS, EgoMotion, draw_encounter
from st_sim.sim.robot import Robot, RobotSpec
from st_sim.sim.sweep import Contact


def population_cap(crowd: CrowdConfig, layout: Layout) -> int:
    """Most pedestrians the simulator admits at once (its ``max_pedestrians``), known before it is built."""
    return sim_population_cap(crowd, layout)


def default_crowd(layout: str, encounter: str | None = None) -> CrowdConfig:
    """The crowd of a layout: calibrated steering; in a real scene's geometry, that scene's fitted population; in an
    encounter, nobody arrives besides its scripted pedestrians."""
    if encounter is not None:
        return CrowdConfig(spawn_rate_hz=0.0)
    return CrowdConfig(population=PopulationConfig.fitted(layout)) if layout in SCENES else CrowdConfig()


def check_encounter(encounter: Any, layout: Any) -> None:
    """Refuse an unknown ``encounter`` (naming the choices), or one given with a ``layout`` (``EnvInputError``)."""
    if encounter is None:
        return
    if not isinstance(encounter, str) or encounter not in ENCOUNTERS:
        raise EnvInputError(f"encounter={encounter!r}: expected None or one of {', '.join(map(repr, ENCOUNTERS))}")
    if layout is not None:
        raise EnvInputError(f"layout={layout!r} with encounter={encounter!r}: an encounter runs in its own layout "
                            f"({ENCOUNTERS[encounter].layout}); leave layout unset")


class SimCrowdEnv(CrowdEnv):
    """A pymunk crowd walking between entries and exits of a layout; the ego robot crosses it.

    ## Description
    Pedestrians (discs of 0.2 m, steered by the calibrated collision-free speed model, pymunk contacts;
    ``st_sim.sim.CrowdSim``) enter at the layout's entries and leave at its exits; one step is 0.4 s. In a real
    scene's geometry the population (walking speeds, people standing, groups) is the one fitted to that scene's
    recording. The ego is a heavy disc of radius 0.3 m whose body follows its robot model (``robot``,
    ``st_sim.sim.robot``: the same in every world; holonomic by default, 2 m/s^2). With ``pedestrians_see_ego=True``
    (default) pedestrians steer around it as around another pedestrian; with False it is an invisible robot that
    they meet only by contact (the setting CrowdNav-style benchmarks also report). Every pedestrian present is in the
    observation; one with T_obs consecutive steps of presence also gets S predicted futures (one batched predictor
    call per step).

    ## Action Space
    As ``ReplayCrowdEnv``: the robot's command (a holonomic robot's velocity (vx, vy) [m/s], world frame; a
    differential drive's (v [m/s], w [rad/s])). NaN/inf actions raise ValueError. Ignored when ``ego=False``.

    ## Observation Space
    As ``ReplayCrowdEnv`` (ego, history, history_mask, futures, futures_mask; metres, world frame), with
    N_max = the simulator's population cap (``crowd.max_pedestrians``, 40 by default).

    ## Rewards
    As ``ReplayCrowdEnv``: progress to the goal [m] x 1, goal reached x 10, ``pedestrian_collision`` (the ego
    touched a pedestrian: a pymunk contact of the two bodies) and ``wall_collision`` (it came within 1 cm of a
    wall and touched no pedestrian that step) x -10 each (``config.reward.collision``; the two exclude each
    other, so a step pays the weight at most once), off the walkable map x -1 per step, time x -0.1 per step.

    ## Starting State
    A fresh crowd drawn from ``np_random`` that has walked T_obs - 1 steps (so histories are full at
    reset) with the ego standing at the layout's start; the goal is the layout's ego goal. With ``encounter``, the
    ego's start and goal and the scripted pedestrians (positions, exits, walking speeds, group) are drawn from
    ``np_random`` (``st_sim.sim.encounters``): they are placed so that they would meet an ego that drives straight to
    its goal at full speed after the warm-up, and nobody else arrives.

    ## Episode End
    Terminated when the ego reaches its goal (0.5 m) or touches a pedestrian or a wall;
    ``info["termination"]`` names which ("goal", "pedestrian_collision", "wall_collision"; a collision
    outranks the goal). Truncated by the registered time limit (200 steps), with ``termination`` None: that is
    a timeout; the crowd itself never ends.

    ## Info
    As ``ReplayCrowdEnv``; ``frame`` is the simulator's step count; ``pedestrians_see_ego`` (bool) says
    whether pedestrians steer around the ego; ``group_ids`` (N_max,) int64, aligned with the rows of ``agent_ids``:
    the group of each row's pedestrian (members of a group that walks together share an id), -1 for one walking
    alone or an empty row.

    ## Arguments
    layout (crossing (default), corridor, bottleneck, plaza, doorway, or eth, hotel, univ, zara1, zara2 for a real
    scene's walls and openings, which needs the data root), predictor ("auto" (default): the universal
    SingularTrajectory checkpoint, trained on all five scenes, for 8 or 2 observed frames; or as
    ``ReplayCrowdEnv``), task, ego, render_mode, config (``EnvConfig``; its ego radius goes to the simulator), crowd
    (``st_sim.sim.CrowdConfig``; default: calibrated steering and, in a real scene, its fitted population; in an
    encounter, nobody arriving), root (data root), rerun (a .rrd path or "spawn": log every step to Rerun),
    pedestrians_see_ego (True: pedestrians steer around the ego; False: invisible robot), device (as
    ``ReplayCrowdEnv``: where a SingularTrajectory the env loads runs, "auto" by default), encounter (None, or a
    scripted encounter, which runs in its own layout, so with no layout given: "frontal_approach", "overtaking",
    "crossing_angle", "doorway", "group"), robot (the robot, the same kind and limits in every world: "holonomic"
    (default), "diff-drive", or an ``st_sim.sim.robot.RobotSpec``; ``robot`` holds the spec in force), sensing (as
    ``ReplayCrowdEnv``).

    ## Version History
    - v1 (2026-11-23): calibrated speed-model steering, 0.2 m pedestrians, fitted populations in real scenes,
      ``pedestrians_see_ego`` (default True). Same day, same id (reward, observation and dynamics unchanged):
      ``info["termination"]``, the ``collision`` reward part split into ``pedestrian_collision`` and
      ``wall_collision``, and the ``ego_max_accel_mps2`` attribute.
      2026-11-27, same id (an info addition; observation, reward and dynamics unchanged): ``info["group_ids"]``;
      the ``encounter`` argument, its ids ``STCrowd-Sim{FrontalApproach,Overtaking,CrossingAngle,Doorway,Group}-v1``
      and the ``plaza`` and ``doorway`` layouts.
      2026-12-02, same id (benchmark version 4; the holonomic default moves as before): ``robot=`` ("diff-drive"),
      ``obs["ego"]`` gains the heading and turn rate (its first six fields keep their meaning) and its velocity is the
      robot model's, ``info["robot"]``; ``ego_max_accel_mps2`` gives way to ``robot``.
    - v0: social-force steering; pedestrians reacted to the ego only by contact.
    """

    def __init__(self, layout: str | None = None, predictor: Any = "auto", task: str = "stochastic",
                 ego: bool = True, render_mode: str | None = None, config: EnvConfig | None = None,
                 crowd: CrowdConfig | None = None, root: str | os.PathLike | None = None,
                 rerun: str | None = None, pedestrians_see_ego: bool = True, device: str = "auto",
                 encounter: str | None = None, robot: str | RobotSpec | None = None,
                 sensing: str | SensingSpec | None = None):
        check_encounter(encounter, layout)
        self.encounter = encounter
        if encounter is not None:
            layout = ENCOUNTERS[encounter].layout
        elif layout is None:
            layout = "crossing"
        self.layout = build_layout(layout, root)
        self.crowd_cfg = crowd or default_crowd(layout, encounter)
        self.pedestrians_see_ego = bool(pedestrians_see_ego)
        n_max = population_cap(self.crowd_cfg, self.layout)
        where = f"sim layout {layout}" if encounter is None else f"sim encounter {encounter}"
        if encounter is not None and n_max < ENCOUNTERS[encounter].group_size[1]:
            raise EnvInputError(f"{where}: crowd holds at most {n_max} pedestrians, fewer than the encounter's "
                                f"{ENCOUNTERS[encounter].group_size[1]}")
        super().__init__(self.layout.scene, n_max, where, predictor, task, ego, render_mode, config,
                         shipped_checkpoint(task, None), rerun=rerun, root=root, device=device, robot=robot,
                         sensing=sensing)
        self.sim: CrowdSim | None = None

    @classmethod
    def _reset_worlds(cls, envs: Sequence[SimCrowdEnv], options: Sequence[dict]) -> list[list[Frame]]:
        """New crowds, those of each world (layout and crowd config) warming up together (``_warm_up``)."""
        frames_of: dict[int, list[Frame]] = {}
        for world in cls._by_world(envs):
            frames_of.update({id(env): frames for env, frames in zip(world, cls._warm_up(world), strict=True)})
        return [frames_of[id(env)] for env in envs]

    @classmethod
    def _step_worlds(cls, envs: Sequence[SimCrowdEnv], commands: Sequence[np.ndarray | None]) -> list[Frame]:
        """One ``step_crowds`` call moves the crowds of each world (layout and crowd config), each ego's body
        following its robot model."""
        command_of = {id(env): command for env, command in zip(envs, commands, strict=True)}
        for world in cls._by_world(envs):
            step_crowds([env.sim for env in world], [command_of[id(env)] for env in world])
        return [env._sim_frame() for env in envs]

    @staticmethod
    def _by_world(envs: Sequence[SimCrowdEnv]) -> list[list[SimCrowdEnv]]:
        """The envs grouped by world (the same ``Layout`` object and an equal crowd config), in order."""
        worlds: dict[tuple[int, CrowdConfig], list[SimCrowdEnv]] = {}
        for env in envs:
            worlds.setdefault((id(env.layout), env.crowd_cfg), []).append(env)
        return list(worlds.values())

    @staticmethod
    def _warm_up(envs: Sequence[SimCrowdEnv]) -> list[list[Frame]]:
        """Fresh crowds (drawn from each env's ``np_random``) that walk T_obs - 1 steps together with the egos
        standing; every env's frames, oldest first."""
        for env in envs:
            env.sim, env.goal_m = env._new_crowd()
        frames = [[env._sim_frame()] for env in envs]
        for _ in range(envs[0].t_obs - 1 if envs else 0):  # warm-up: the egos stand while the crowds get going
            step_crowds([env.sim for env in envs], [None] * len(envs))
            for env, kept in zip(envs, frames, strict=True):
                kept.append(env._sim_frame())
        return frames

    def _new_crowd(self) -> tuple[CrowdSim, np.ndarray]:
        """A fresh crowd drawn from ``np_random`` (the layout's, or the encounter's scripted pedestrians round the
        drawn ego route) and the ego's goal (2,) [m]."""
        plan = None if self.encounter is None else draw_encounter(self.encounter, self.layout, self.np_random)
        ego_cfg = EgoConfig(radius_m=self.cfg.ego_radius_m, robot=self.robot,
                            pedestrians_see_ego=self.pedestrians_see_ego,
                            start_m=None if plan is None else tuple(plan.ego_start_m.tolist())) if self.ego else None
        start_m = np.asarray(self.layout.ego_start_m if plan is None else plan.ego_start_m, np.float64)
        goal_m = np.array(self.layout.ego_goal_m if plan is None else plan.ego_goal_m, dtype=np.float64)
        robot = self._new_robot(start_m, goal_m) if self.ego else None
        if plan is None:
            return CrowdSim(self.layout, self.crowd_cfg, self.np_random, ego=ego_cfg, robot=robot), goal_m
        sim = CrowdSim(self.layout, self.crowd_cfg, self.np_random, ego=ego_cfg, n_initial=0, robot=robot)
        motion = EgoMotion((self.t_obs - 1) * STEP_S, self.robot.max_speed_mps, self.robot.max_accel_mps2)
        keep_clear_m = self.crowd_cfg.radius_m + self.cfg.ego_radius_m + self.crowd_cfg.spawn_gap_m
        sim.add(plan.pedestrians(sim.nav, motion, keep_clear_m))
        return sim, goal_m

    def _ego_contact(self) -> tuple[Contact | None, bool, float]:
        """The simulator's record of the last step: first pedestrian contact within its substeps, wall touched,
        least ego-pedestrian distance."""
        return self.sim.ego_contact, self.sim.ego_touched_wall, self.sim.ego_nearest_m

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        return tuple(self.layout.bounds_m)

    @property
    def wall_clearance_m(self) -> float:
        return self.cfg.ego_radius_m

    @property
    def robot_model(self) -> Robot:
        return self.sim.robot

    def _info(self, reward_parts: dict[str, float], termination: str | None, at_fault: bool | None
              ) -> dict[str, Any]:
        return {**super()._info(reward_parts, termination, at_fault), "pedestrians_see_ego": self.pedestrians_see_ego,
                "group_ids": self._group_ids()}

    def _perception_info(self) -> dict[str, Any]:
        """The truth beside the perception, with the true people's groups (``true_group_ids``, -1: alone)."""
        info = super()._perception_info()
        index = lookup(self.sim.ids, info["true_ids"])
        info["true_group_ids"] = np.where(index >= 0, self.sim.groups[np.maximum(index, 0)], -1)
        return info

    def _group_ids(self) -> np.ndarray:
        """(N_max,) int64 group of each observation row's pedestrian (rows of ``info["agent_ids"]``), -1 for one
        alone or an empty row."""
        groups = np.full(self.n_max, -1, np.int64)
        index = lookup(self.sim.ids, self.true_ids(np.arange(self.n_max)))
        groups[index >= 0] = self.sim.groups[index[index >= 0]]
        return groups

    def _sim_frame(self) -> Frame:
        """The simulator's pedestrians now; also refreshes the ego state (its velocity: its robot model's, which the
        body follows)."""
        if self.ego:
            self.ego_xy_m = self.sim.ego_position_m
            self.ego_velocity_mps = self.sim.robot.velocity_mps
        return Frame(int(self.sim.step_count), self.sim.ids, self.sim.positions_m)
