"""What the replay and simulated crowd environments share: spaces, observation, predictions, reward, info.

A subclass provides the crowd (and moves the ego) through four hooks: ``_reset_worlds`` (every env's frames up
to now, drawn from its ``np_random``) and ``_step_worlds`` (one 0.4 s step of every env's world), each over a batch
of envs of the class, ``_ego_contact`` (the step's first pedestrian contact, wall contact, closest approach) and
``_world_ended``. It keeps ``ego_xy_m``,
``ego_velocity_mps`` and ``goal_m`` up to date, gives the robot model its world moves the ego with (``robot_model``:
``st_sim.sim.robot``, the same kind and limits in every world, ``robot``), lists the ``reset`` options it reads in
``RESET_OPTIONS`` and checks their values in ``_check_options``.

How an episode ends is in ``info["termination"]``: "goal", "pedestrian_collision", "wall_collision" (the
step that terminated the episode; a collision outranks the goal, a pedestrian outranks a wall) or None
while it goes on. Contacts are found along the step, not only at its end (``st_sim.sim.sweep``): on a pedestrian
collision ``info["contact_time_s"]`` is the moment of impact (seconds into the step) and ``info["at_fault"]`` says
whether the robot was at fault then (``envs.common.fault``: it moved at 0.05 m/s or more at the impact or in the
0.8 s before, and the person did not run into it from behind); a wall collision is always at fault
(``contact_time_s`` None). Both are None without a collision.
The env never ends an episode for time: "timeout" is the ``TimeLimit`` wrapper's truncation (``truncated``
with ``termination`` None), like the end of a replay's recording.

``reset`` and ``step`` each come in two halves around the forecast, ``begin_reset_all``/``end_reset`` and
``advance_all``/``end_step`` with ``forecast_all`` in between, each over a batch of envs: ``envs.batch_step`` steps
many envs (of any ids) with one world step per class and one forecast per predictor model; a single env is the
batch of one.

Input contract (both vectorisation modes of gymnasium): every check of an argument, option or action runs
before anything changes, and raises the env's own ``envs.common.errors.EnvInputError`` (a ValueError) or
``NeedsResetError``. A sync vector env stays usable after such an error; gymnasium's async vector env
re-raises it in the main process with the same type and message, but shuts the worker down, so an async
vector env must be closed and made again after an error.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from envs.common.config import EnvConfig
from envs.common.ego import checked_command, on_image, require_on_map
from envs.common.errors import ConfigError, EgoPlacementError, EnvInputError, NeedsResetError, ResetOptionsError
from envs.common.fault import RobotMotion, robot_at_fault
from envs.common.predictors import (
    Forecast,
    ForecastCache,
    ForecastRequest,
    forecast_all,
    gives_anchors,
    resolve_predictor,
    task_sizes,
)
from envs.common.running_metrics import RunningMetrics
from envs.common.tracks import Frame, TrackBuffer, lookup
from predictor.devices import DeviceError, check_device_name
from replays.constants import FORECAST_LIMIT_M, POSITION_LIMIT_M, STEP_S, T_PRED
from replays.scenes import Scene
from st_sim.perception import Perception, SensingSpec, SensingSpecError, sensing_spec
from st_sim.perception.perception import PerceptionInfo
from st_sim.sim.exact import length
from st_sim.sim.robot import Robot, RobotSpec, RobotSpecError, robot_spec
from st_sim.sim.sweep import Contact, closest_approach, first_contact

ROBOT_STREAM, SENSING_STREAM = 1, 2  # own_rng streams: the robot's actuation noise, the sensor's draws
TURN_BOUND_RADPS = 20.0  # obs["ego"] bound of a holonomic robot's turn rate (always 0): the largest a spec allows
EGO_FIELDS = ("x_m", "y_m", "vx_mps", "vy_mps", "goal_x_m", "goal_y_m", "heading_cos", "heading_sin",
              "yaw_rate_radps")
"""layout of ``obs["ego"]``: position, velocity, goal [m, m/s], the unit vector the robot faces, its turn rate [rad/s]
(a holonomic robot faces where it last moved and does not turn: 0)"""
REWARD_PARTS = ("progress", "goal", "pedestrian_collision", "wall_collision", "at_fault_collision", "off_map", "time",
                "discomfort", "predicted_collision")
WEIGHT_OF: dict[str, str] = {"pedestrian_collision": "collision", "wall_collision": "collision",
                              "at_fault_collision": "at_fault", "predicted_collision": "prediction"}
"""reward parts weighted by a ``RewardWeights`` field of another name (both collision kinds share its weight)"""
TERMINATIONS: tuple[str, ...] = ("pedestrian_collision", "wall_collision", "goal")
"""values of ``info["termination"]`` besides None, by precedence (the first part that is 1 names the end)"""


class CrowdEnv(gym.Env):
    """Base class; see ``ReplayCrowdEnv`` and ``SimCrowdEnv`` for the manual."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": round(1 / STEP_S, 1)}
    RESET_OPTIONS: ClassVar[dict[str, str]] = {}
    """reset options a subclass reads: name -> what it takes; any other key is refused"""

    def __init__(self, scene: Scene, n_max: int, where: str, predictor: Any = "auto",
                 task: str = "stochastic", ego: bool = True, render_mode: str | None = None,
                 config: EnvConfig | None = None, pretrained: str = "universal",
                 rerun: str | os.PathLike | None = None, root: str | os.PathLike | None = None, device: str = "auto",
                 robot: str | RobotSpec | None = None, sensing: str | SensingSpec | None = None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvInputError(f"render_mode={render_mode!r}: expected None or 'rgb_array'")
        check_flag("ego", ego)
        if config is not None and not isinstance(config, EnvConfig):
            raise ConfigError(f"config={config!r}: expected an envs.common.config.EnvConfig or None")
        if rerun is not None and not isinstance(rerun, str | os.PathLike):
            raise EnvInputError(f"rerun={rerun!r}: expected a .rrd path, 'spawn' or None")
        if rerun is not None:  # ~ expanded; an unwritable path is refused here, naming it, not at reset()
            from st_sim.rerun_log import checked_recording_target

            rerun = checked_recording_target(rerun)
        try:
            self.robot: RobotSpec = robot_spec(robot)
            """the robot in force: kind and limits (``st_sim.sim.robot.RobotSpec``)"""
            self.sensing: SensingSpec = sensing_spec(sensing)
            """what the robot senses (``st_sim.perception.SensingSpec``; the default, ``oracle``: everything)"""
        except (RobotSpecError, SensingSpecError) as err:
            raise EnvInputError(f"{where}: {err}") from None
        if not self.sensing.oracle and not ego:
            raise EnvInputError(f"{where}: sensing={sensing!r} needs a robot (ego=True); a spectator sees everything")
        self.scene, self.n_max, self.where = scene, n_max, where
        self.cfg = config or EnvConfig()
        self.t_obs, self.num_samples = task_sizes(task)
        self.task, self.ego, self.render_mode = task, bool(ego), render_mode
        try:
            self.predictor = resolve_predictor(predictor, task, pretrained, root, check_device_name(device))
        except DeviceError as err:
            raise EnvInputError(f"{where}: {err}") from None
        self.tracks = TrackBuffer(n_max, self.t_obs, where)
        """the truth: every pedestrian in the world (collisions, fault and evaluation read it)"""
        self.perception: Perception | None = None if self.sensing.oracle else Perception(
            self.sensing, n_max, scene, self.cfg.pedestrian_radius_m, self.cfg.ego_radius_m)
        self.observed = self.tracks if self.perception is None else TrackBuffer(n_max, self.t_obs, where)
        """what the observation shows: the truth (``oracle``), or the tracks of what the robot perceived"""
        self.metrics = RunningMetrics(scene)

        limit, reach, speed = POSITION_LIMIT_M, FORECAST_LIMIT_M, self.robot.max_speed_mps
        turn = self.robot.max_yaw_rate_radps if math.isfinite(self.robot.max_yaw_rate_radps) else TURN_BOUND_RADPS
        self._ego_high = np.array([limit, limit, speed, speed, limit, limit, 1, 1, turn], np.float32)  # EGO_FIELDS
        self.observation_space = spaces.Dict({
            "ego": spaces.Box(-self._ego_high, self._ego_high, dtype=np.float32),
            "history": spaces.Box(-limit, limit, (n_max, self.t_obs, 2), np.float32),
            "history_mask": spaces.Box(0, 1, (n_max, self.t_obs), np.bool_),
            "futures": spaces.Box(-reach, reach, (n_max, self.num_samples, T_PRED, 2), np.float32),
            "futures_mask": spaces.Box(0, 1, (n_max,), np.bool_),
        })
        self.action_space = spaces.Box(self.robot.command_low.astype(np.float32),
                                       self.robot.command_high.astype(np.float32), dtype=np.float32)

        self.ego_xy_m = np.zeros(2)
        self.ego_velocity_mps = np.zeros(2)
        self.goal_m = np.zeros(2)
        self._obs: dict[str, np.ndarray] | None = None
        self.forecasts: ForecastCache | None = ForecastCache()
        """forecasts kept for moments that recur (``_forecast_moment``); None: always predict afresh"""
        self._history: tuple[np.ndarray, np.ndarray] | None = None  # TrackBuffer.history() of the newest frame
        self._rows = np.zeros(0, np.int64)  # observation rows to forecast, chosen when the frame came (``_sense``)
        self._context_rows = np.zeros(0, np.int64)  # rows whose histories the forecast conditions on (_rows among them)
        self._previous_xy_m = np.zeros(2)  # the ego before this step
        self._contact: Contact | None = None  # the step's first pedestrian contact, if any
        self._motion = RobotMotion()  # the ego's past before this step, as the at-fault rule reads it
        self._episode_over = False  # terminated, or the world ended: step needs a reset first
        self._episode = 0  # episodes since the last seeded reset (own_rng)
        self._interrupted: str | None = None  # why the last step could not finish: step needs a reset first
        self.anchors: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (ids, prototype, adapted)
        self.rerun_target, self._rerun, self._rerun_step = rerun, None, 0
        self.rerun_paths: list[Path] = []
        """recordings this env has written (a step after ``close`` starts a new, numbered one)"""

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        self.begin_reset_all([self], [seed], options)
        return self.end_reset(*forecast_all([self])[0])  # if it fails, step is refused until a reset succeeds

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        command = self.check_step(action)
        self.advance_all([self], [command])
        return self.end_step(*forecast_or_interrupt([self])[0])

    @classmethod
    def begin_reset_all(cls, envs: Sequence[CrowdEnv], seeds: Sequence[int | None], options: dict | None) -> None:
        """First half of ``reset`` for several envs of this class: check the arguments (all before any env is
        reset), then start every episode's world (``_reset_worlds``); no forecast yet."""
        if any(type(env) is not cls for env in envs):
            raise TypeError(f"{cls.__name__}.begin_reset_all: every env must be a {cls.__name__}")
        for env, seed in zip(envs, seeds, strict=True):
            env.check_reset_options(options)
            env.check_reset_seed(seed)
        checked = [env._prepare_reset(seed, options) for env, seed in zip(envs, seeds, strict=True)]
        for env, frames in zip(envs, cls._reset_worlds(envs, checked), strict=True):
            env._finish_reset(frames)

    @classmethod
    def advance_all(cls, envs: Sequence[CrowdEnv], commands: Sequence[np.ndarray | None]) -> None:
        """First half of ``step`` for several envs of this class, after ``check_step``: move every world 0.4 s
        (``_step_worlds``), ego i's robot given ``commands[i]`` (2,); no forecast yet. If a world fails, every env
        refuses to step until it is reset (``interrupt``)."""
        for env in envs:
            env._previous_xy_m = env.ego_xy_m.copy()
        try:
            frames = cls._step_worlds(envs, commands)
        except Exception as err:
            for env in envs:
                env.interrupt(f"the world's step failed: {err}")
            raise
        for env, frame in zip(envs, frames, strict=True):
            env._advanced(frame)

    def check_reset_seed(self, seed: Any) -> None:
        """Refuse a seed that is not None or an int >= 0 (``EnvInputError``); nothing changes."""
        if not is_seed(seed):
            raise EnvInputError(f"{self.where}: seed={seed!r}: expected None or an int >= 0")

    def _prepare_reset(self, seed: int | None, options: dict | None) -> dict[str, Any]:
        """Check the arguments, seed ``np_random`` and clear the episode; returns the checked options."""
        options = self.check_reset_options(options)
        self.check_reset_seed(seed)
        super().reset(seed=None if seed is None else int(seed))
        self._obs, self._episode_over, self._interrupted = None, False, None
        self._motion = RobotMotion()
        self.tracks.clear()
        self.observed.clear()
        self._episode = 0 if seed is not None else self._episode + 1
        self.metrics.reset()
        return options

    def _finish_reset(self, frames: list[Frame]) -> None:
        """Take the world's first frames (oldest first) after ``_prepare_reset``; check the ego's placement."""
        if self.perception is not None:
            self.perception.reset(self.own_rng(SENSING_STREAM))
        for frame in frames:
            self._take(frame)
        if self.ego:
            require_on_map(self.scene, self.ego_xy_m, "the ego's start", walkable=True)
            require_on_map(self.scene, self.goal_m, "the ego's goal", walkable=True)
            self.metrics.update_ego(False, self._nearest_now_m())
        self._sense()

    def end_reset(self, predicted: np.ndarray, anchors: tuple[np.ndarray, np.ndarray] | None
                  ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Second half of ``reset``: the first observation and info, given the forecast (``forecast_all``) of
        ``forecast_request()``."""
        self._obs = self._observe(predicted, anchors)
        info = self._info(dict.fromkeys(REWARD_PARTS, 0.0), None, None)
        self._log_rerun(info, 0.0)
        return self._obs, info

    def _advanced(self, frame: Frame) -> None:
        """Take the world's frame after a step."""
        self._take(frame)
        self._sense()

    def _take(self, frame: Frame) -> None:
        """Keep the world's newest frame, and what the robot perceives of it (the tracks, as a frame of track ids)."""
        self.tracks.push(frame)
        if self.perception is not None:
            robot = self.robot_model
            tracks = self.perception.sense(frame.ids, frame.xy_m, self.ego_xy_m, robot.heading)
            self.observed.push(Frame(frame.frame, tracks.ids, tracks.xy_m))

    def interrupt(self, reason: str) -> None:
        """Refuse every ``step`` until ``reset``: the step in progress could not finish (``reason``), and as its world
        had already moved, the episode cannot go on without skipping a frame."""
        self._interrupted = f"{reason} (at frame {self.tracks.now.frame if self.tracks.frames else None})"

    def check_step(self, action: Any) -> np.ndarray | None:
        """The robot's command (2,) that ``action`` gives (None in spectator mode), after every check that ``step``
        makes before anything changes; raises ``EnvInputError`` or ``NeedsResetError``."""
        if self._interrupted is not None:
            raise NeedsResetError(f"{self.where}: the last step did not finish, {self._interrupted}; its world had "
                                  "already moved, so call reset() before stepping again")
        if self._obs is None:
            raise NeedsResetError(f"{self.where}: call reset() before step()")
        if self._episode_over:
            raise NeedsResetError(f"{self.where}: the episode has ended (goal, collision or end of the "
                                  "recording); call reset() before stepping again")
        command = checked_command(action, self.robot.command_names, finite=self.ego)
        if self.ego and not on_image(self.scene, self.ego_xy_m):
            raise EgoPlacementError(f"{self.where}: the ego is at {self.ego_xy_m.tolist()} m, off the scene's "
                                    "image; it can only be moved there by assigning ego_xy_m")
        return command if self.ego else None

    def end_step(self, predicted: np.ndarray, anchors: tuple[np.ndarray, np.ndarray] | None
                 ) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Second half of ``step``: observation, reward, terminated, truncated and info, given the forecast
        (``forecast_all``) of ``forecast_request()``."""
        self._obs = self._observe(predicted, anchors)
        parts = self._reward_parts(self._previous_xy_m) if self.ego else dict.fromkeys(REWARD_PARTS, 0.0)
        termination = next((name for name in TERMINATIONS if parts[name]), None)
        at_fault = self._at_fault(termination)
        parts["at_fault_collision"] = float(bool(at_fault))  # the judgement needs the termination
        reward = float(sum(getattr(self.cfg.reward, WEIGHT_OF.get(name, name)) * value
                           for name, value in parts.items()))
        terminated, truncated = termination is not None, self._world_ended()
        self._episode_over = terminated or truncated
        info = self._info(parts, termination, at_fault)
        if self.ego:
            self._motion = self._motion.after_step(self.ego_xy_m - self._previous_xy_m, STEP_S)
        self._log_rerun(info, reward)
        return self._obs, reward, terminated, truncated, info

    def _sense(self) -> None:
        """What the ego senses of the newest frame: the histories (pedestrians beyond ``sensor_range_m`` emptied)
        and the rows to forecast (``_predicted_rows`` among the sensed; with ``forecast_nearest`` k, among the k
        sensed nearest to the ego, measured as a policy measures them in the observation)."""
        history, mask = self.observed.history()
        rows = targets = self._predicted_rows()
        if self.ego and (math.isfinite(self.cfg.sensor_range_m) or self.cfg.forecast_nearest is not None):
            ego_m = np.clip(self.ego_xy_m, -self._ego_high[:2], self._ego_high[:2]).astype(np.float32)
            distance_m = length(history[:, -1].astype(np.float64) - ego_m)
            far = distance_m > self.cfg.sensor_range_m
            history[far], mask[far] = 0.0, False
            rows = targets = rows[~far[rows]]
            if self.cfg.forecast_nearest is not None:
                sensed = np.flatnonzero(mask[:, -1])
                nearest = np.zeros(len(mask), bool)
                nearest[sensed[np.argsort(distance_m[sensed], kind="stable")[:self.cfg.forecast_nearest]]] = True
                targets = rows[nearest[rows]]
        self._history, self._context_rows, self._rows = (history, mask), rows, targets

    def forecast_request(self) -> ForecastRequest:
        """What to forecast now (after ``begin_reset_all`` or ``advance_all``): every sensed agent with T_obs frames
        conditions the forecast, ``targets`` of them get futures (the ``forecast_nearest`` nearest, or all)."""
        targets = np.zeros(len(self._history[0]), bool)
        targets[self._rows] = True
        return ForecastRequest(self._history[0][self._context_rows], targets[self._context_rows],
                               self.rerun_target is not None)

    def cached_forecast(self) -> Forecast | None:
        """The forecast of ``forecast_request()`` kept from an earlier visit of this moment, if any."""
        moment = self._forecast_moment()
        if moment is None or self.forecasts is None:
            return None
        return self.forecasts.get(moment, self.observed.row_ids[self._rows], self.observed.row_ids[self._context_rows],
                                  anchors=self.rerun_target is not None and gives_anchors(self.predictor))

    def remember_forecast(self, forecast: Forecast) -> None:
        """Keep the forecast of ``forecast_request()`` for later visits of this moment (if it can recur)."""
        moment = self._forecast_moment()
        if moment is not None and self.forecasts is not None:
            self.forecasts.put(moment, self.observed.row_ids[self._rows], forecast,
                               self.observed.row_ids[self._context_rows])

    def close(self) -> None:
        """Finish the Rerun recording, if any; a later step starts a new, numbered one."""
        if self._rerun is not None:
            self._rerun.close()
            self._rerun = None

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array":
            return None
        if self._obs is None:
            raise NeedsResetError(f"{self.where}: call reset() before render()")
        from envs.common.render import draw_observation

        return draw_observation(self.scene, self._obs, self.ego, self.cfg.ego_radius_m)

    # hooks -------------------------------------------------------------------------------------------

    def _check_options(self, options: dict[str, Any]) -> None:
        """Raise ``ResetOptionsError`` for a reset option value this env cannot use (keys are checked already)."""

    @classmethod
    def _reset_worlds(cls, envs: Sequence[CrowdEnv], options: Sequence[dict]) -> list[list[Frame]]:
        """Start every env's new episode (after ``_prepare_reset``, which checked ``options[i]``; randomness from
        each env's ``np_random``); each env's frames, oldest first, the last is now."""
        raise NotImplementedError

    @classmethod
    def _step_worlds(cls, envs: Sequence[CrowdEnv], commands: Sequence[np.ndarray | None]) -> list[Frame]:
        """Advance every env's world 0.4 s, ego i's robot (``robot_model``) driven by ``commands[i]`` (2,) (None in
        spectator mode); each env's new frame."""
        raise NotImplementedError

    def _ego_contact(self) -> tuple[Contact | None, bool, float]:
        """(the first pedestrian contact of this step or None, whether the ego touched a wall, the least centre
        distance between the ego and a pedestrian during the step [m]).

        Default (replays): no walls; the ego and every pedestrian present in both frames move in a straight line
        between them, and they touch when their centres come closer than ``ego_radius_m + pedestrian_radius_m``;
        a pedestrian who appears this frame is tested where it appears, at the end of the step, with an unknown
        velocity (it walked in: not the robot's fault, ``envs.common.fault``).
        """
        before, now = self.tracks.frames[-2], self.tracks.now
        if len(now.ids) == 0:
            return None, False, np.inf
        reach_m = self.cfg.ego_radius_m + self.cfg.pedestrian_radius_m
        row = lookup(before.ids, now.ids)
        stayed = row >= 0
        start = before.xy_m[row[stayed]]
        nearest, _ = closest_approach(start - self._previous_xy_m, now.xy_m[stayed] - self.ego_xy_m)
        nearest_m = float(np.min(nearest, initial=self._nearest_now_m()))
        contact = first_contact(self._previous_xy_m, self.ego_xy_m, start, now.xy_m[stayed], now.ids[stayed],
                                reach_m, STEP_S)
        if contact is None:  # newcomers, where they appear
            new = ~stayed & (length(now.xy_m - self.ego_xy_m) < reach_m)
            if new.any():
                contact = Contact(STEP_S, self.ego_xy_m.copy(), self.ego_velocity_mps.copy(), now.ids[new],
                                  now.xy_m[new], np.full((int(new.sum()), 2), np.nan))  # their velocity: unknown
        return contact, False, nearest_m

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) where the ego can be [m]: a replay's arena, a simulated layout's bounds."""
        raise NotImplementedError

    @property
    def robot_model(self) -> Robot:
        """The ego's robot model now (its motion, heading, pending commands and last report; ``st_sim.sim.robot``),
        held by the world that moves it."""
        raise NotImplementedError

    def _new_robot(self, start_m: np.ndarray, goal_m: np.ndarray) -> Robot:
        """A robot of ``robot`` at rest facing from ``start_m`` to ``goal_m`` (2,) [m]; with actuation noise, its own
        generator (``own_rng``)."""
        rng = self.own_rng(ROBOT_STREAM) if self.robot.actuation_noise > 0 else None
        return Robot(self.robot, np.asarray(goal_m, np.float64) - start_m, rng)

    @property
    def wall_clearance_m(self) -> float:
        """Least distance the ego's centre keeps from non-walkable ground [m]: its radius where walls are solid
        (simulated crowds: touching one is a collision), 0 where they are only marked on the map (replays: an off-map
        step costs reward but does not end the episode)."""
        raise NotImplementedError

    def _world_ended(self) -> bool:
        """No further step possible (a recording's last frame)."""
        return False

    def _forecast_moment(self) -> Any:
        """A hashable name of the scene moment now if its histories recur exactly on every visit (a log-mode
        replay's frame), so that its forecasts can be kept (``forecasts``); None (default): they cannot."""
        return None

    def _predicted_rows(self) -> np.ndarray:
        """Observation rows that get predictions this step (default: every agent, or track, with T_obs frames)."""
        return self.observed.predictable_rows()

    # helpers -----------------------------------------------------------------------------------------

    def check_reset_options(self, options: Any) -> dict[str, Any]:
        """``options`` as a dict after refusing a non-mapping, keys this env does not read and values it cannot use
        (``ResetOptionsError``); nothing changes."""
        if options is None:
            return {}
        if not isinstance(options, Mapping):
            raise ResetOptionsError(f"{self.where}: reset options must be a dict, got {type(options).__name__}")
        unknown = [key for key in options if key not in self.RESET_OPTIONS]
        if unknown:
            accepted = ", ".join(f"{k!r} ({v})" for k, v in self.RESET_OPTIONS.items()) or "none"
            raise ResetOptionsError(f"{self.where}: unknown reset option {unknown[0]!r}; this env accepts {accepted}")
        options = dict(options)
        self._check_options(options)
        return options

    def _observe(self, predicted: np.ndarray, anchors: tuple[np.ndarray, np.ndarray] | None
                 ) -> dict[str, np.ndarray]:
        """Observation of the newest frame, with ``predicted`` (P, S, 12, 2) futures of the rows chosen when the
        frame came (``_sense``, ``_predicted_rows``: every agent with T_obs frames by default)."""
        (history, history_mask), rows = self._history, self._rows
        self.anchors = None if anchors is None else (self.observed.row_ids[rows], *anchors)
        if self.perception is None:
            self.metrics.update_predictions(self.tracks, self.tracks.row_ids[rows], predicted)
        else:  # a false track's forecast has no truth to meet; two tracks of one person count once
            truth = self.true_ids(rows)
            scored = (truth >= 0) & first_of_each(truth)
            self.metrics.update_predictions(self.tracks, truth[scored], predicted[scored])
        futures = np.zeros((self.n_max, self.num_samples, T_PRED, 2), np.float32)
        futures[rows] = predicted
        futures_mask = np.zeros(self.n_max, bool)
        futures_mask[rows] = True
        ego = np.zeros(len(EGO_FIELDS), np.float32)
        if self.ego:
            robot = self.robot_model
            state = np.concatenate([self.ego_xy_m, self.ego_velocity_mps, self.goal_m, robot.heading,
                                    [robot.yaw_rate_radps]])
            ego[:] = np.clip(state, -self._ego_high, self._ego_high)
        return {"ego": ego, "history": history, "history_mask": history_mask,
                "futures": futures, "futures_mask": futures_mask}

    def _reward_parts(self, previous_xy_m: np.ndarray) -> dict[str, float]:
        """Named reward parts of the step from ``previous_xy_m`` (ego mode); also updates the ego metrics.

        The collision kinds exclude each other (a step that touched both counts as a pedestrian collision),
        so a step costs the collision weight at most once.
        """
        distance_m = float(length(self.goal_m - self.ego_xy_m))
        self._contact, wall, closest_m = self._ego_contact()
        pedestrian = self._contact is not None
        walkable = bool(self.scene.is_walkable(self.ego_xy_m))
        gap_m = self._nearest_now_m() - self.cfg.ego_radius_m - self.cfg.pedestrian_radius_m
        parts = {"progress": float(length(self.goal_m - previous_xy_m)) - distance_m,
                 "goal": float(distance_m <= self.cfg.goal_radius_m),
                 "pedestrian_collision": float(pedestrian), "wall_collision": float(wall and not pedestrian),
                 "off_map": float(not walkable), "time": 1.0,
                 "discomfort": float(max(0.0, self.cfg.discomfort_m - gap_m)),
                 "predicted_collision": self._predicted_collision()}
        self.metrics.update_ego(pedestrian or wall, closest_m)
        return parts

    def _predicted_collision(self) -> float:
        """0.5^(k - 1) for the soonest future step k (1..12) at which the ego, held at its velocity, would be within
        the contact distance of a pedestrian's mean predicted position (over the S samples of the newest forecast);
        0 if never (CrowdNav++'s prediction-aware term)."""
        predicted = self._obs["futures_mask"]
        if not predicted.any():
            return 0.0
        mean = self._obs["futures"][predicted].mean(axis=1)  # (P, 12, 2)
        ahead = STEP_S * np.arange(1, T_PRED + 1)[:, None] * self.ego_velocity_mps  # (12, 2)
        reach = self.cfg.ego_radius_m + self.cfg.pedestrian_radius_m
        meets = (length(mean - (self.ego_xy_m + ahead)) < reach).any(axis=0)  # (12,)
        return float(np.ldexp(1.0, -int(np.argmax(meets)))) if meets.any() else 0.0

    def _nearest_now_m(self) -> float:
        """Centre distance from the ego to the nearest pedestrian of the newest frame [m] (inf: nobody)."""
        xy_m = self.tracks.now.xy_m
        return float(length(xy_m - self.ego_xy_m).min()) if len(xy_m) else np.inf

    def _log_rerun(self, info: dict[str, Any], reward: float) -> None:
        """Append this step to the Rerun recording (``rerun=`` path or "spawn"); one recording per env."""
        if self.rerun_target is None:
            return
        if self._rerun is None:
            from st_sim.rerun_log import RerunLogger

            self._rerun = RerunLogger(self.rerun_target, self.scene)
            self._rerun_step = 0
            if self._rerun.path is not None:
                self.rerun_paths.append(self._rerun.path)
        self._rerun.log_step(self._rerun_step, **rerun_step(self._obs, info, reward, self.ego, self.anchors))
        self._rerun_step += 1

    def _at_fault(self, termination: str | None) -> bool | None:
        """The fault rule's judgement of the step's collision (``envs.common.fault``): True for a wall collision,
        the rule's for a pedestrian collision, None when the step ended in none."""
        if termination == "wall_collision":
            return True
        return robot_at_fault(self._contact, self._motion) if termination == "pedestrian_collision" else None

    def _info(self, reward_parts: dict[str, float], termination: str | None, at_fault: bool | None
              ) -> dict[str, Any]:
        """Fresh info dict; ``agent_ids[i]``/``predicted_ids[i]`` name the agent of observation row i (-1: none);
        ``termination`` is what ended the episode this step (see ``TERMINATIONS``), None otherwise; on a pedestrian
        collision ``contact_time_s`` is the moment of impact [s into the step] and ``at_fault`` the judgement then
        (``envs.common.fault``), on a wall collision ``at_fault`` is True; ``robot`` what became of the step's command
        (``st_sim.sim.robot.Actuation``, an object rather than a dict, so that gymnasium's vector envs keep each
        sub-env's; None at a reset and in spectator mode)."""
        row_ids = self.observed.row_ids.copy()
        hit = self._contact if termination == "pedestrian_collision" else None
        return {
            "frame": int(self.tracks.now.frame),
            "agent_ids": row_ids,
            "predicted_ids": np.where(self._obs["futures_mask"], row_ids, -1),
            "reward_parts": dict(reward_parts),
            "termination": termination,
            "contact_time_s": None if hit is None else float(hit.time_s),
            "at_fault": at_fault,
            "metrics": self.metrics.summary(),
            "robot": self.robot_model.last if self.ego else None,
            **({} if self.perception is None else {"perception": PerceptionInfo(self._perception_info())}),
        }

    def _perception_info(self) -> dict[str, Any]:
        """The step's truth beside the perception (``Perception.last``); a world adds what it knows of the truth."""
        return dict(self.perception.last)

    def true_ids(self, rows: np.ndarray) -> np.ndarray:
        """(R,) int64 the true pedestrian id behind each observation row of ``rows`` (-1: an empty row, or a track of
        false detections): the row's id itself with the ``oracle``, else the true id of its track's last detection
        (evaluation only)."""
        ids = self.observed.row_ids[rows]
        if self.perception is None:
            return ids.copy()
        last = self.perception.last
        order = np.argsort(last["track_ids"])
        index = lookup(last["track_ids"][order], ids)
        source = np.append(last["track_from"][order], -1)  # index -1 (no such track) reads the -1 at the end
        return source[index]

    def own_rng(self, stream: int) -> np.random.Generator:
        """A generator of its own for ``stream`` (the robot's noise, the sensor's draws), seeded from the episode's seed
        and the episodes since, without drawing from ``np_random``: what it draws never changes the crowd."""
        seeds = self.np_random.bit_generator.seed_seq
        return np.random.default_rng(np.random.SeedSequence(seeds.entropy, spawn_key=(*seeds.spawn_key, stream,
                                                                                          self._episode)))


def forecast_or_interrupt(envs: Sequence[CrowdEnv]) -> list[Forecast]:
    """``forecast_all`` of envs within a step; if the predictor fails, every env, whose world has moved, refuses to
    step until it is reset (``CrowdEnv.interrupt``)."""
    try:
        return forecast_all(envs)
    except Exception as err:
        for env in envs:
            env.interrupt(f"the predictor failed: {err}")
        raise


def first_of_each(ids: np.ndarray) -> np.ndarray:
    """(N,) bool: True at the first occurrence of each value of ``ids`` (N,)."""
    first = np.zeros(len(ids), bool)
    first[np.unique(ids, return_index=True)[1]] = True
    return first


def is_seed(value: Any) -> bool:
    """True for a seed ``reset`` takes: None or an int >= 0 (not a bool)."""
    return value is None or (not isinstance(value, bool | np.bool_) and isinstance(value, int | np.integer)
                             and value >= 0)


def rerun_step(obs: dict[str, np.ndarray], info: dict[str, Any], reward: float, ego: bool,
               anchors: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> dict[str, Any]:
    """The arguments of ``RerunLogger.log_step`` (after the step index) for one state of an env: the agents present,
    their trails, the forecasts, the ego and its goal (if ``ego``), the running metrics that have a value and the
    reward, the anchors (``CrowdEnv.anchors``) if given. Arrays are copies of the present rows only, so a caller may
    keep them."""
    present, predicted = info["agent_ids"] >= 0, obs["futures_mask"]
    metrics = {name: float(value) for name, value in info["metrics"].items()
               if value is not None and np.isfinite(value)}  # nothing logged until there is a value
    return {"positions_m": obs["history"][present, -1], "ids": info["agent_ids"][present],
            "trails": obs["history"][present], "trail_mask": obs["history_mask"][present],
            "predictions": obs["futures"][predicted], "prediction_ids": info["predicted_ids"][predicted],
            "ego_xy_m": obs["ego"][:2].copy() if ego else None, "ego_goal_m": obs["ego"][4:6].copy() if ego else None,
            "ego_heading": obs["ego"][6:8].copy() if ego else None,
            "truth_xy_m": info["perception"]["true_xy_m"].copy() if "perception" in info else None,
            "detections_xy_m": info["perception"]["detected_xy_m"].copy() if "perception" in info else None,
            "metrics": {**metrics, "reward": float(reward)},
            "prototype_anchors": None if anchors is None else anchors[1],
            "adapted_anchors": None if anchors is None else anchors[2]}


def check_flag(name: str, value: Any) -> None:
    """Refuse a non-boolean for a yes/no argument (``ego="no"`` would otherwise be true)."""
    if not isinstance(value, bool | np.bool_):
        raise EnvInputError(f"{name}={value!r}: expected True or False")
