"""Run a planner through seeded episodes of an STCrowd env and collect each episode's metrics.

Episode i of a run starts from ``env.reset(seed=seed + i)``, so every planner and predictor meets the same
episodes (same crowd, start and goal) and runs can be compared pair by pair.
"""

from __future__ import annotations

import inspect
import re
import time
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import envs  # noqa: F401  (registers the ids)
from envs.common.config import EnvConfig
from replays import strict_json
from replays.atomic import write_text_atomic
from st_sim.apps.grid import Job
from st_sim.apps.navigation.metrics import NAN, EpisodeTrace, Outcome, episode_metrics, outcome_of, summarize
from st_sim.apps.navigation.mpc import MpcConfig
from st_sim.apps.navigation.planners import READS_POLICY_FILE, Planner
from st_sim.apps.navigation.policies import load_policy
from st_sim.apps.navigation.predictors import env_predictor
from st_sim.apps.navigation.world import NavWorld, world_of

SEE_EGO_KWARG = "pedestrians_see_ego"  # env keyword of the simulated envs: pedestrians steer around the ego
PEDESTRIANS_KWARG = "pedestrians"  # env keyword of the replays: log or reactive pedestrians


@dataclass(frozen=True)
class NavRun:
    """One cell of the benchmark: a planner with a predictor on an env, over seeded episodes."""

    env_id: str = "STCrowd-SimCrossing-v1"
    """gym id of an STCrowd env with an ego"""
    policy: str = "mpc"
    """a policy spec (``policies``): a shipped planner (straight, orca, mpc, ppo, ppo-reactive, ppo-suite,
    ppo-suite-shield, ppo-suite-2), package.module:name or sb3:PATH.zip"""
    predictor: str = "singular"
    """none, cvm, cvm-s or singular"""
    episodes: int = 100
    """number of episodes"""
    seed: int = 0
    """episode i is reset with seed + i"""
    pedestrians_see_ego: bool | None = None
    """pass this to envs that accept the keyword; None = the env's default"""
    pedestrians: str | None = None
    """replays: "log" (the recording) or "reactive" (pedestrians step round the robot); None = the env's default"""
    sensor_range_m: float | None = None
    """the robot senses, and the env forecasts, only the pedestrians this close (``EnvConfig.sensor_range_m``) [m];
    None = everyone"""
    rerun_dir: str | None = None
    """write one Rerun recording per episode into this folder"""
    data_root: str | None = None
    """ETH/UCY data root for replays (default: $STCROWD_DATA or the cache)"""
    mpc: MpcConfig | None = None
    """tunables of the MPC planner (None: the defaults); other planners take none"""
    policy_file: str | None = None
    """the PPO planner: a policy file (``train_ppo``'s policy.pt) instead of the shipped policy"""
    trust_policy_file: bool = False
    """an sb3: model: load it with stable-baselines3's own loader, which runs code stored in the file"""
    robot: str = "holonomic"
    """the robot, by kind (``st_sim.sim.robot.ROBOTS``)"""
    sensing: str = "oracle"
    """what the robot senses, by level (``st_sim.perception.SENSING_LEVELS``)"""


def accepts_keyword(env_id: str, name: str) -> bool:
    """True if the env class behind ``env_id`` takes the constructor keyword ``name``."""
    entry = gym.spec(env_id).entry_point
    if isinstance(entry, str):
        module, attr = entry.split(":")
        entry = getattr(__import__(module, fromlist=[attr]), attr)
    return name in inspect.signature(entry).parameters


def make_nav_env(run: NavRun, rerun_path: str | None = None) -> gym.Env:
    """The env of ``run``, with its predictor (``none``: pedestrians predicted to stand still)."""
    kwargs: dict[str, Any] = {"predictor": env_predictor(run.predictor), "robot": run.robot, "sensing": run.sensing}
    if run.pedestrians_see_ego is not None and accepts_keyword(run.env_id, SEE_EGO_KWARG):
        kwargs[SEE_EGO_KWARG] = run.pedestrians_see_ego
    if run.pedestrians is not None:
        if not accepts_keyword(run.env_id, PEDESTRIANS_KWARG):
            raise ValueError(f"{run.env_id} has no pedestrians= mode (only the replays do): drop --pedestrians")
        kwargs[PEDESTRIANS_KWARG] = run.pedestrians
    if run.data_root is not None:
        kwargs["root"] = run.data_root
    if run.sensor_range_m is not None:
        kwargs["config"] = EnvConfig(sensor_range_m=run.sensor_range_m)
    if rerun_path is not None:
        kwargs["rerun"] = rerun_path
    return gym.make(run.env_id, **kwargs)


class TraceRecorder:
    """An episode's trace from what a plain ``gym`` loop sees: the observations and infos of ``reset`` and ``step``.

        recorder = TraceRecorder(world)
        obs, info = env.reset(seed=seed); recorder.start(obs, info)
        ... obs, reward, terminated, truncated, info = env.step(action); recorder.add(obs, info)
        trace = recorder.finish(outcome_of(info["termination"], truncated), info.get("at_fault"))

    Pedestrians are who the observation holds (everyone, with the envs' default unlimited sensor range), named by
    ``info["agent_ids"]``; their groups come from ``info["group_ids"]`` where the env has them (simulated crowds).
    """

    def __init__(self, world: NavWorld):
        self.world = world
        self.xy: list[np.ndarray] = []  # ego positions [m]
        self.velocity: list[np.ndarray] = []  # ego velocities [m/s]
        self.seen: list[dict[int, np.ndarray]] = []  # per state: pedestrian id -> position [m]
        self.groups: dict[int, int] | None = None  # pedestrian id -> group id (-1 alone); None: the env has none
        self.goal_m = np.zeros(2)
        self.deviation: list[float] = []  # reactive replays: the pedestrians' mean distance from their logs [m]
        self.clipped: list[bool] = []  # per step: the robot's limits clipped its command
        self.last_info: dict[str, Any] = {}  # the newest info (the episode's tracking and forecast figures)

    def start(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        """The state after ``reset`` (forgets any earlier episode)."""
        self.xy, self.velocity, self.seen, self.deviation, self.clipped = [], [], [], [], []
        self.goal_m = obs["ego"][4:6].astype(np.float64)
        self.groups = {} if "group_ids" in info else None
        self._state(obs, info)

    def add(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        """The state after a ``step``."""
        self._state(obs, info)
        if "log_deviation_m" in info:
            self.deviation.append(info["log_deviation_m"])
        if info.get("robot") is not None:
            self.clipped.append(bool(info["robot"].clipped))

    def _state(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        self.last_info = info
        self.xy.append(obs["ego"][:2].astype(np.float64))
        self.velocity.append(obs["ego"][2:4].astype(np.float64))
        truth = info.get("perception")
        if truth is not None:  # the robot's sensor and tracker: every figure is judged on the truth beside them
            ids = truth["true_ids"].tolist()
            self.seen.append(dict(zip(ids, truth["true_xy_m"], strict=True)))
            if self.groups is not None:
                self.groups.update(zip(ids, truth["true_group_ids"].tolist(), strict=True))
            return
        rows = np.flatnonzero(obs["history_mask"][:, -1])
        ids = info["agent_ids"][rows].tolist()
        self.seen.append(dict(zip(ids, obs["history"][rows, -1].astype(np.float64), strict=True)))
        if self.groups is not None:
            self.groups.update(zip(ids, info["group_ids"][rows].tolist(), strict=True))

    def finish(self, outcome: Outcome, at_fault: bool | None) -> EpisodeTrace:
        """The trace of the states added so far, ended by ``outcome``."""
        ids = sorted({pid for state in self.seen for pid in state})
        column = {pid: k for k, pid in enumerate(ids)}
        pedestrians = np.full((len(self.seen), len(ids), 2), np.nan)
        for t, state in enumerate(self.seen):
            for pid, xy in state.items():
                pedestrians[t, column[pid]] = xy
        xy_m = np.array(self.xy)
        groups = None if self.groups is None else np.array([self.groups[pid] for pid in ids], np.int64)
        gaps = np.linalg.norm(pedestrians - xy_m[:, None], axis=-1) - self.world.contact_m
        clearance = np.min(np.where(np.isnan(gaps), np.inf, gaps), axis=1, initial=np.inf)
        return EpisodeTrace(ego_xy_m=xy_m, ego_velocity_mps=np.array(self.velocity), clearance_m=clearance,
                            off_map=~self.world.scene.is_walkable(xy_m), goal_m=self.goal_m, outcome=outcome,
                            at_fault=at_fault, log_deviation_m=np.array(self.deviation, np.float64),
                            pedestrians_xy_m=pedestrians, pedestrian_groups=groups,
                            ego_radius_m=self.world.ego_radius_m, pedestrian_radius_m=self.world.pedestrian_radius_m,
                            goal_radius_m=self.world.goal_radius_m, step_s=self.world.step_s,
                            clipped=np.array(self.clipped, bool), tracking=self._tracking(),
                            forecast_ade_m=self._figure("ade_m"), forecast_fde_m=self._figure("fde_m"))

    def _tracking(self) -> dict[str, float] | None:
        """The episode's tracking figures (the newest info's), None with the oracle's eyes."""
        truth = self.last_info.get("perception")
        return None if truth is None else dict(truth["mot"])

    def _figure(self, name: str) -> float:
        """A running figure of the newest info's ``metrics`` (NaN while it has none)."""
        value = self.last_info.get("metrics", {}).get(name) if self.last_info else None
        return NAN if value is None else float(value)


def run_episode(env: gym.Env, planner: Planner, world: NavWorld, seed: int) -> tuple[EpisodeTrace, float]:
    """One episode from ``reset(seed=seed)`` to its end; returns the trace and the seconds spent in ``act``."""
    recorder = TraceRecorder(world)
    obs, info = env.reset(seed=seed)
    planner.reset()
    recorder.start(obs, info)
    thinking_s, outcome = 0.0, None
    while outcome is None:
        start = time.perf_counter()
        action = planner.act(obs)
        thinking_s += time.perf_counter() - start
        obs, _, terminated, truncated, info = env.step(action)
        recorder.add(obs, info)
        outcome = outcome_of(info["termination"], truncated)
        assert outcome is not None or not terminated, "the env terminated without naming why"
    return recorder.finish(outcome, info.get("at_fault")), thinking_s


def planner_options(run: NavRun) -> dict[str, Any]:
    """Keyword options of ``run``'s planner class: the MPC's ``cfg``, the PPO planner's ``policy`` file.

    Raises:
        ValueError: options given for a planner that takes none of them.
    """
    if run.mpc is not None and run.policy != "mpc":
        raise ValueError(f"MPC settings given for the {run.policy} planner; they are the mpc planner's")
    if run.policy_file is not None and run.policy not in READS_POLICY_FILE:
        raise ValueError(f"a policy file ({run.policy_file}) given for the {run.policy} planner; only "
                         f"{', '.join(READS_POLICY_FILE)} read one")
    return {"cfg": run.mpc} if run.mpc is not None else {"policy": run.policy_file} if run.policy_file else {}


def run_navigation(run: NavRun, progress: bool = True) -> dict[str, Any]:
    """Run the episodes of ``run``; returns {run settings, planner_config, episodes: [seed + metrics], summary,
    speed}.

    ``pedestrians_see_ego`` in the result is the value passed to the env, or None when the env does not
    take the keyword (then its own behaviour applies) or none was asked; ``pedestrians`` is the replay's mode
    ("log" when none was asked), None for simulated envs.
    """
    see_ego = run.pedestrians_see_ego if accepts_keyword(run.env_id, SEE_EGO_KWARG) else None
    env = make_nav_env(run)
    world = world_of(env)
    planner = load_policy(run.policy, world, run.predictor, trust_file=run.trust_policy_file, **planner_options(run))
    planner.check_fits(env.observation_space, run.env_id)
    episodes, thinking_s, decisions = [], 0.0, 0
    start = time.perf_counter()
    for i in tqdm(range(run.episodes), desc=f"{run.policy}/{run.predictor} {run.env_id}", disable=not progress,
                  unit="episode"):
        seed = run.seed + i
        if run.rerun_dir is not None:
            env.close()
            name = re.sub(r"[^\w.-]+", "-", f"{run.env_id}_{run.policy}_{run.predictor}_seed{seed}")
            path = Path(run.rerun_dir) / f"{name}.rrd"
            env = make_nav_env(run, str(path))
        trace, seconds = run_episode(env, planner, world, seed)
        episodes.append({"seed": seed, **episode_metrics(trace)})
        thinking_s += seconds
        decisions += len(trace.ego_xy_m) - 1
    env.close()
    settings = getattr(planner.policy, "cfg", None)
    mode = (run.pedestrians or "log") if accepts_keyword(run.env_id, PEDESTRIANS_KWARG) else None
    return {**asdict(run), "pedestrians_see_ego": see_ego, "pedestrians": mode,
            "planner_config": asdict(settings) if is_dataclass(settings) else None,
            "episodes": episodes, "summary": summarize(episodes),
            "decisions_per_s": decisions / thinking_s if thinking_s > 0 else float("inf"),
            "wall_time_s": time.perf_counter() - start}


def navigation_job(output: str, mpc: dict[str, Any] | None = None, **run: Any) -> None:
    """Grid entry point (``st_sim.apps.grid``): ``run_navigation`` of ``NavRun(**run)`` (with ``MpcConfig(**mpc)``),
    written as JSON to ``output``."""
    cfg = None if mpc is None else MpcConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in mpc.items()})
    result = run_navigation(NavRun(**run, mpc=cfg), progress=False)
    write_text_atomic(output, strict_json.dumps(result, indent=1))


def grid_job(name: str, run: NavRun, output: Path) -> Job:
    """The grid job that runs ``run`` and writes its result to ``output`` (made absolute: a cluster's workers run
    in their own folders)."""
    fields = asdict(run)
    if fields["data_root"] is not None:
        fields["data_root"] = str(Path(fields["data_root"]).resolve())
    return Job(name, "st_sim.apps.navigation.episodes:navigation_job",
               {"output": str(output.resolve()), **fields}, str(output.resolve()))
