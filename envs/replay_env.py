"""Replay of one ETH/UCY scene: the pedestrians walk exactly as recorded, an ego robot walks among them."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from envs.common.config import EnvConfig
from envs.common.crowd_env import CrowdEnv, check_flag
from envs.common.ego import SpawnPoints, move_along, spawn_start_goal, walkable_points
from envs.common.errors import EnvInputError, ResetOptionsError
from envs.common.predictors import shipped_checkpoint
from envs.common.tracks import Frame
from replays.constants import COORD_DECIMALS, MIN_AGENTS_PER_WINDOW, STEP_S, T_PRED
from replays.data_root import data_root
from replays.errors import RecordingError
from replays.recording import read_recording
from replays.scenes import load_scene, scene_info
from st_sim.perception import SensingSpec
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import draw_traits, fitted_spread
from st_sim.reactive.reactive import ReactiveCrowd
from st_sim.reactive.routes import Routes
from st_sim.sim.exact import length
from st_sim.sim.map_depth import MapDepth
from st_sim.sim.robot import Robot, RobotSpec

MIN_REPLAY_STEPS = 50  # a random start leaves at least this many steps (20 s) of recording
MIN_FRAMES = 2  # a replay starts at one listed frame and steps to the next
PEDESTRIAN_MODES: tuple[str, ...] = ("log", "reactive")  # the recording exactly, or stepping round the robot
REACTION_TRAITS: tuple[str, ...] = ("fitted", "drawn")  # everybody the fitted pedestrian, or each its own traits


@dataclass(frozen=True, eq=False)
class Replay:
    """A recording on its grid of listed frames (frame gaps ignored, as the benchmark windows do).

    Attributes:
        path: the recording file.
        frames: (F,) int64 frame ids.  agents: (A,) int64 agent ids.
        xy_m: (F, A, 2) float64 metres rounded to 4 decimals (as the windows are), NaN where absent.
        present: (F, A) bool.
    """

    path: Path
    frames: np.ndarray
    agents: np.ndarray
    xy_m: np.ndarray
    present: np.ndarray

    def frame(self, index: int) -> Frame:
        """The pedestrians of listed frame ``index``."""
        cols = np.flatnonzero(self.present[index])
        return Frame(int(self.frames[index]), self.agents[cols], self.xy_m[index, cols])


def load_replay(path: Path) -> Replay:
    """Read a recording once per process (again if its size or times change) and lay it on its frame grid.

    Raises:
        RecordingError: the file is malformed, or has fewer than 2 listed frames (nothing to step to).
    """
    stat = path.stat()
    return _load_replay(path, (stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns))


@cache
def _load_replay(path: Path, version: tuple[int, int, int]) -> Replay:
    recording = read_recording(path)
    if len(recording.frames) < MIN_FRAMES:
        raise RecordingError(f"{path}: {len(recording.frames)} listed frame(s); a replay needs at least {MIN_FRAMES}",
                             path=path)
    xy_m, present = recording.dense(COORD_DECIMALS)
    return Replay(path, recording.frames, recording.agents, xy_m, present)


@cache
def scene_depth(scene: str, root: Path) -> MapDepth:
    """How deep points lie in a scene's non-walkable area, as reactive pedestrians check it (built once)."""
    return MapDepth(load_scene(scene, root))


@cache
def reactive_routes(replay: Replay, scene: str, root: Path, body: Body, touch_m: float) -> Routes:
    """The reactive pedestrians' tables of a replay (built once, shared by every env replaying it, so that a vector
    env steps their crowds together)."""
    return Routes(replay.xy_m, replay.present, scene_depth(scene, root), body, touch_m)


class ReplayCrowdEnv(CrowdEnv):
    """Replay one ETH/UCY test recording; the ego robot walks among the recorded pedestrians.

    ## Description
    One step is one listed frame of the recording (0.4 s; frame gaps are ignored, as the benchmark windows ignore
    them). Every pedestrian of the current frame is in the observation; one with T_obs consecutive listed frames
    up to now also gets S predicted futures (one batched predictor call per step, all agents in one group). The
    ego is a robot of radius 0.3 m that moves as its robot model (``robot``, ``st_sim.sim.robot``: the same in every
    world) turns each command into motion within its limits, and cannot leave the arena (recorded area + 1 m, within
    the scene's image: a move off the image keeps only the axis that stays on it; the edge holds the body back, the
    robot's velocity stays its model's). With ``pedestrians="log"`` (default) the pedestrians walk exactly as recorded
    and do not react to it; with ``"reactive"`` each one walks its own log until it has noticed the robot (in its
    field of view or hearing), reacted (a reaction time later) and the robot is in its way, then steps aside or slows
    down along its logged route and catches up with its log; noticed or not, nobody walks into the robot's body
    (``st_sim.reactive.reactive``; the reaction fitted on CITR, ``st_sim.reactive.reaction``).

    ## Action Space
    The robot's command. Holonomic (default): Box(-1.5, 1.5, (2,), float32), velocity (vx, vy) [m/s], world frame,
    scaled down to 1.5 m/s if faster and followed within 2 m/s^2. Differential drive: Box([-0.5, -2], [1.5, 2]),
    (v [m/s], w [rad/s]), forward speed and turn rate (counter-clockwise), clipped to those ranges and followed
    within 2 m/s^2 and 4 rad/s^2. Anything but 2 real numbers (complex, text, bools, objects, another shape) raises
    ``ActionError`` (a ValueError); so does NaN/inf, except when ``ego=False``, where the action's value is ignored.

    ## Observation Space
    Dict, all positions in metres, world frame, N_max = most pedestrians in one frame of the scene's
    recordings (ETH 27, HOTEL 18, UNIV 75, ZARA1/2 20; with reactive pedestrians, also counting those who may still
    be on their way to where their log ended, ``ReactiveCrowd.capacity``):
    - "ego": (9,) float32 x, y [m], vx, vy [m/s], goal x, y [m], the unit vector the robot faces (cos, sin; a
      holonomic robot faces where it last moved, every robot starts facing its goal), turn rate [rad/s] (0 for a
      holonomic robot); zeros when ``ego=False`` (``envs.common.crowd_env.EGO_FIELDS``).
    - "history": (N_max, T_obs, 2) float32, oldest first, last column = now; 0 where unobserved.
    - "history_mask": (N_max, T_obs) bool, agent present in that frame.
    - "futures": (N_max, S, 12, 2) float32 predicted positions, 12 steps of 0.4 s; 0 where not predicted.
    - "futures_mask": (N_max,) bool, row has predictions.
    Row i belongs to agent ``info["agent_ids"][i]`` (-1: empty row; recordings hold ids >= 0 only); an agent
    keeps its row while present. Every value lies in the space: positions are within +-1000 m (the parser
    refuses recordings beyond), and histories are also clipped to that bound.

    ## Rewards
    Weighted sum of ``info["reward_parts"]`` (weights in ``config.reward``): progress to the goal [m] x 1,
    goal reached x 10, pedestrian_collision x -10 (``config.reward.collision``), off the walkable map x -1 per
    step, time x -0.1 per step. ``wall_collision`` is always 0 here: the map's walls are not solid (an off-map
    step costs ``off_map``) and the image border stops the ego without a collision. All zero when ``ego=False``.

    ## Starting State
    A listed frame drawn from ``np_random`` (at least T_obs - 1 frames in, 50 before the end) or
    ``options["start_index"]`` (an int in [0, F - 2]; the only reset option: other keys, and values that are
    not ints - "5", 3.7, True, lists - raise ``ResetOptionsError``, a ValueError); histories are filled from
    the recording's earlier frames. The ego starts at a walkable point at least 1 m from every pedestrian,
    its goal at least half the arena diagonal away; an ego start or goal off the walkable map raises
    ``EgoPlacementError``.

    ## Episode End
    Terminated when the ego reaches its goal (0.5 m) or touches a pedestrian (centre distance < 0.55 m);
    ``info["termination"]`` names which ("goal" or "pedestrian_collision"; a collision outranks the goal).
    Truncated at the recording's last frame, or by the registered time limit (200 steps: a timeout), with
    ``termination`` None. ``step`` before ``reset``, or after the env ended the episode, raises
    ``NeedsResetError`` (gymnasium's ResetNeeded).

    ## Info
    frame (recording frame id), agent_ids and predicted_ids (N_max,) int64 (-1 where none), reward_parts,
    termination (what ended the episode on this step, else None), metrics: a read-only mapping
    (``envs.common.running_metrics.Metrics``) of the running ADE/FDE of matured predictions, map violation, ego
    collisions and least ego-pedestrian distance; a value with nothing to measure yet is None ("n/a"), never 0.0;
    robot: what became of the step's command (``st_sim.sim.robot.Actuation``: command, applied (after latency and
    noise), reached (the robot's speeds at the step's end, in the command's terms), gap = |command - reached| per
    component, clipped: its limits held it back), None after a reset and without an ego.

    ## Errors and vector envs
    Every argument, option and action is checked before anything changes, and a bad one raises the env's
    own error (``envs.common.errors``: ValueError subclasses, and ``NeedsResetError``) with the field at fault
    in the message. ``gym.make_vec(..., vectorization_mode="sync")`` re-raises it and stays usable;
    ``"async"`` re-raises it with the same type and message, but gymnasium then shuts that worker down, so an
    async vector env must be closed and made again after an error. Validate actions first to avoid that.

    ## Arguments
    scene (eth, hotel, univ, zara1, zara2), recording (univ: students001 (default) or students003),
    predictor ("auto" (default): SingularTrajectory's leave-one-out checkpoint of this scene, which never
    saw it, for 8 or 2 observed frames; "cvm", "cvm-s", "linear", "singular" or an object with ``predict``),
    task (stochastic:
    T_obs 8, S 20; deterministic: 8, 1; momentary: 2, 20), ego, render_mode ("rgb_array"), config
    (``EnvConfig``; its fields are checked, ``ConfigError`` names a bad one), root: the ETH/UCY data root
    (default $STCROWD_DATA or the user cache; checked against the project's SHA-256 sums on first use),
    benchmark_windows (spectator only: predict exactly the agents of each benchmark window, as the
    offline evaluation does, instead of every agent with T_obs frames), rerun (a .rrd path or "spawn": log
    every step, with predictions and SingularTrajectory's anchors, to Rerun; an existing recording is never
    overwritten: the new one is numbered, ``run-1.rrd``, and ``rerun_paths`` lists what was written),
    pedestrians ("log": the recording exactly; "reactive": recorded pedestrians step round the robot),
    reaction_traits (reactive only; "fitted" (default): every pedestrian reacts as fitted; "drawn": at each reset
    every pedestrian draws its own noticing distance, reaction time, room and willingness to wait from the fitted
    spread, ``st_sim.reactive.reaction.fitted_spread``, with the env's ``np_random``: seeded by the reset's seed),
    device (where a SingularTrajectory the env loads runs: "auto" (default: a CUDA GPU when torch sees one, else the
    CPU), "cpu", "cuda", "cuda:N" or "mps"; a predictor object passed in runs where it is), robot (the robot, the
    same kind and limits in every world: "holonomic" (default), "diff-drive", or an ``st_sim.sim.robot.RobotSpec``;
    ``robot`` holds the spec in force), sensing (what the robot senses: "oracle" (default: every pedestrian's exact
    past), "range", "occluded", "noisy",
    "realistic", or an ``st_sim.perception.SensingSpec``; the observation then holds the tracker's tracks, and
    ``info["perception"]`` the truth beside them).

    ## Version History
    - v0: initial version. 2026-12-02, same id (benchmark version 4): the robot moves through its robot model, the
      simulated crowds' one (2 m/s^2; before, it took any velocity at once), ``robot=`` ("diff-drive"),
      ``obs["ego"]`` gains the heading and turn rate (its first six fields keep their meaning), ``info["robot"]``;
      the ``ego_max_accel_mps2`` attribute gives way to ``robot`` (and ``EnvConfig.max_speed_mps`` to its
      ``max_speed_mps``). 2026-11-28, same id (the default is unchanged): ``reaction_traits``. 2026-11-26, same
      id (the default is unchanged): reactive pedestrians notice the robot within a field of view or hearing,
      react a reaction time later and keep a room that grows with the robot's speed, all fitted on CITR.
      2026-11-25, same id (the default is unchanged): ``pedestrians="reactive"``, ``info["pedestrians"]``,
      ``info["off_log"]``, ``info["log_deviation_m"]``. 2026-11-23, same id (reward, observation and dynamics
      unchanged): ``info["termination"]``, the ``collision`` reward part renamed ``pedestrian_collision`` (and a
      ``wall_collision`` part, always 0), the ``ego_max_accel_mps2`` attribute.
    """

    RESET_OPTIONS: ClassVar[dict[str, str]] = {"start_index": "int, the listed frame to start at"}

    def __init__(self, scene: str = "zara1", recording: str | None = None, predictor: Any = "auto",
                 task: str = "stochastic", ego: bool = True, render_mode: str | None = None,
                 config: EnvConfig | None = None, root: str | os.PathLike | None = None,
                 benchmark_windows: bool = False, rerun: str | os.PathLike | None = None,
                 pedestrians: str = "log", device: str = "auto", reaction_traits: str = "fitted",
                 robot: str | RobotSpec | None = None, sensing: str | SensingSpec | None = None):
        check_flag("benchmark_windows", benchmark_windows)
        if not isinstance(pedestrians, str) or pedestrians not in PEDESTRIAN_MODES:
            raise EnvInputError(f"pedestrians={pedestrians!r}: expected one of {', '.join(PEDESTRIAN_MODES)}")
        self.pedestrians = pedestrians
        if not isinstance(reaction_traits, str) or reaction_traits not in REACTION_TRAITS:
            raise EnvInputError(f"reaction_traits={reaction_traits!r}: expected one of {', '.join(REACTION_TRAITS)}")
        if reaction_traits != "fitted" and pedestrians != "reactive":
            raise EnvInputError(f"reaction_traits={reaction_traits!r} needs pedestrians='reactive' (got "
                                f"{pedestrians!r}): pedestrians of a log do not react")
        self.reaction_traits = reaction_traits
        self.spread = fitted_spread() if reaction_traits == "drawn" else None  # a broken spread file fails here
        check_flag("ego", ego)
        if benchmark_windows and ego:
            raise EnvInputError("benchmark_windows=True is a spectator mode: pass ego=False")
        self.benchmark_windows = benchmark_windows
        info = scene_info(scene)
        root = data_root(root)
        recording = info.recordings[0] if recording is None else recording
        if recording not in info.recordings:
            raise EnvInputError(f"recording={recording!r}: scene {info.name} has {', '.join(info.recordings)}")
        replays = {name: load_replay(root / info.name / "test" / f"{name}.txt") for name in info.recordings}
        self.replay = replays[recording]
        n_max = max(int(r.present.sum(axis=1).max()) if pedestrians == "log" else ReactiveCrowd.capacity(r.present)
                    for r in replays.values())
        super().__init__(load_scene(info.name, root), n_max, str(self.replay.path), predictor, task, ego,
                         render_mode, config, pretrained=shipped_checkpoint(task, info.name), rerun=rerun,
                         root=root, device=device, robot=robot, sensing=sensing)
        observed = self.replay.xy_m[self.replay.present]
        margin = self.cfg.arena_margin_m  # checked by EnvConfig: [0, 100] m
        self.arena_low_m, self.arena_high_m = observed.min(axis=0) - margin, observed.max(axis=0) + margin
        self.spawn_points = SpawnPoints(walkable_points(self.scene, (*self.arena_low_m, *self.arena_high_m)))
        self.index = 0
        self._robot: Robot | None = None  # the ego's robot model, made at each reset
        self.reactive: ReactiveCrowd | None = None
        if pedestrians == "reactive":
            self.reactive = ReactiveCrowd.on(reactive_routes(self.replay, info.name, root,
                                                             Body(radius_m=self.cfg.ego_radius_m),
                                                             self.cfg.pedestrian_radius_m))

    @property
    def candidates_m(self) -> np.ndarray:
        """(M, 2) the walkable points the robot may start on and aim at [m] (set: others, tree rebuilt)."""
        return self.spawn_points.xy_m

    @candidates_m.setter
    def candidates_m(self, xy_m: np.ndarray) -> None:
        self.spawn_points = SpawnPoints(xy_m)

    def _check_options(self, options: dict[str, Any]) -> None:
        if "start_index" not in options:
            return
        start, last = options["start_index"], len(self.replay.frames) - 1
        if isinstance(start, bool | np.bool_) or not isinstance(start, int | np.integer) or not 0 <= start < last:
            raise ResetOptionsError(f"{self.replay.path}: reset option start_index={start!r}: expected an int "
                                    f"in [0, {last - 1}]")

    @classmethod
    def _reset_worlds(cls, envs: Sequence[ReplayCrowdEnv], options: Sequence[dict]) -> list[list[Frame]]:
        return [env._start_episode(env_options) for env, env_options in zip(envs, options, strict=True)]

    def _start_episode(self, options: dict) -> list[Frame]:
        """Pick the start frame (``start_index``, or drawn), place the ego and its goal, put a reactive crowd on its
        log; the frames up to the start, oldest first."""
        last = len(self.replay.frames) - 1
        if "start_index" in options:
            self.index = int(options["start_index"])  # checked by _check_options
        else:
            low = min(self.t_obs - 1, last - 1)
            self.index = int(self.np_random.integers(low, max(low, last - MIN_REPLAY_STEPS) + 1))
        now = self.replay.frame(self.index)
        if self.ego:
            diagonal_m = float(length(self.arena_high_m - self.arena_low_m))
            self.ego_xy_m, self.goal_m = spawn_start_goal(
                self.spawn_points, now.xy_m, self.cfg.spawn_clearance_m,
                self.cfg.goal_min_fraction * diagonal_m, self.np_random)
            self.ego_velocity_mps = np.zeros(2)
            self._robot = self._new_robot(self.ego_xy_m, self.goal_m)
        if self.reactive is not None:
            agents = self.reactive.routes.present.shape[1]
            self.reactive.reset(self.index, None if self.spread is None else draw_traits(self.np_random, agents,
                                                                                         self.spread))
        first = max(0, self.index - self.t_obs + 1)
        return [self.replay.frame(i) for i in range(first, self.index + 1)]

    @classmethod
    def _step_worlds(cls, envs: Sequence[ReplayCrowdEnv], commands: Sequence[np.ndarray | None]) -> list[Frame]:
        """Every replay's next frame, its ego moved by its robot model; the reactive crowds stepped in one batched call
        (``ReactiveCrowd.step_all``)."""
        moves = [env._move_ego(command) for env, command in zip(envs, commands, strict=True)]
        reactive = [(env, move) for env, move in zip(envs, moves, strict=True) if env.reactive is not None]
        if reactive:
            ReactiveCrowd.step_all([env.reactive for env, _ in reactive], [env.index for env, _ in reactive],
                                   [start for _, (start, _) in reactive], [end for _, (_, end) in reactive],
                                   [None] * len(reactive))
        return [env._frame_now() for env in envs]

    def _move_ego(self, command: np.ndarray | None) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Step to the next frame and move the ego by its robot model's substeps (the edges of the arena and the image
        hold the body back; the robot's velocity stays its model's, as wheels that push against a wall); returns the
        robot's move over the step as the pedestrians expect it, (from, to) (2,) [m] each (None, None without an
        ego)."""
        self.index += 1  # the base class refuses a step once the recording has ended
        start_m, seen_mps = self.ego_xy_m.copy(), self.ego_velocity_mps.copy()
        if command is not None:
            moves = self._robot.drive(command)
            self.ego_xy_m = move_along(self.scene, self.ego_xy_m, moves, STEP_S / len(moves), self.arena_low_m,
                                       self.arena_high_m)
            self.ego_velocity_mps = self._robot.velocity_mps
        # Pedestrians see where the robot is and how it moved in the last step, not its command for this one: they
        # expect it to keep that velocity over the step (a robot that turns into them can still hit them).
        return (start_m, start_m + seen_mps * STEP_S) if self.ego else (None, None)

    def _frame_now(self) -> Frame:
        """The pedestrians of the current frame: the recording's, or the reactive crowd's."""
        if self.reactive is None:
            return self.replay.frame(self.index)
        cols = np.flatnonzero(self.reactive.state.present)
        return Frame(int(self.replay.frames[self.index]), self.replay.agents[cols], self.reactive.state.xy_m[cols])

    def _info(self, reward_parts: dict[str, float], termination: str | None, at_fault: bool | None
              ) -> dict[str, Any]:
        info = {**super()._info(reward_parts, termination, at_fault), "pedestrians": self.pedestrians}
        if self.reactive is not None:
            deviation = self.reactive.deviation_m(self.index)
            info["off_log"] = int(self.reactive.state.off_log.sum())
            info["log_deviation_m"] = float(deviation.mean()) if deviation.size else 0.0
        return info

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        return (*self.arena_low_m.tolist(), *self.arena_high_m.tolist())

    @property
    def wall_clearance_m(self) -> float:
        return 0.0

    @property
    def robot_model(self) -> Robot:
        return self._robot

    def _world_ended(self) -> bool:
        return self.index >= len(self.replay.frames) - 1

    def _forecast_moment(self) -> Any:
        """In log mode with the oracle's eyes the frame index: the recording shows the same histories whenever it
        reaches it (what a sensor perceives depends on the robot and its draws)."""
        return self.index if self.reactive is None and self.perception is None else None

    def _predicted_rows(self) -> np.ndarray:
        """In benchmark mode, only the agents forming a Social-GAN window that ends its observation now.

        Those are agents with T_obs observed frames that the recording keeps for the next 12 frames, and
        only when at least two qualify. The replay knows the future, and the benchmark protocol uses it
        to pick its samples, so the stream sees exactly the samples and groups of ``load_windows``.
        """
        rows = self.observed.predictable_rows()
        if not self.benchmark_windows or len(rows) == 0:
            return rows
        future = self.replay.present[self.index + 1:self.index + 1 + T_PRED]
        if len(future) < T_PRED:
            return rows[:0]
        columns = np.searchsorted(self.replay.agents, self.tracks.row_ids[rows])
        kept = rows[future[:, columns].all(axis=0)]
        return kept if len(kept) >= MIN_AGENTS_PER_WINDOW else rows[:0]
