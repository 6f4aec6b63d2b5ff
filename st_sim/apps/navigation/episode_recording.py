"""Rerun recordings of navigation episodes, written once an episode has ended, from what it showed.

    env = EpisodeTape(make_scenario_env(...), forecasts=True)   # keeps the running episode's states in memory
    trace, _ = run_episode(env, policy, world, seed)
    line = episode_record(scenario, episode, seed, episode_metrics(trace))
    env.write("17.rrd", line, "mpc + singular")                  # only the episodes one wants cost a file

A recording holds what the env's own recording (``rerun=``) holds, step by step (``envs.common.crowd_env.rerun_step``:
the pedestrians, their trails and forecasts, the robot and its goal, the running metrics and the reward per unit),
plus the walls (the map's boundaries, ``map_wall_segments``), a marker where a collision happened (at the moment of
impact, labelled with who was at fault), and the episode's line of ``episodes.jsonl`` as notes beside the plots.
Writing after the end keeps an episode that is not chosen free of Rerun's cost, and the episode itself untouched (the
env records nothing, so it forecasts exactly as when not recorded).

Memory: one episode's states, the rows present only (the forecasts dropped with ``forecasts=False``), freed at the
next reset; the file is written through ``RerunLogger``, whose memory does not grow with the recording.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from envs.common.crowd_env import rerun_step
from replays import strict_json
from replays.constants import STEP_S
from st_sim.apps.navigation.metrics import RATES
from st_sim.sim.map_walls import map_wall_segments

RECORD_CHOICES: tuple[str, ...] = ("none", "failures", "all")
"""which benchmark episodes get a recording: none, those that did not reach the goal, or all"""
AT_FAULT_RGB = (230, 30, 30)  # marker of a collision the robot is at fault for
NOT_AT_FAULT_RGB = (255, 170, 0)  # marker of one it is not at fault for
COLLISIONS = ("pedestrian_collision", "wall_collision")  # the env's terminations that are collisions


def chosen(record: str, line: dict[str, Any]) -> bool:
    """True if an episode whose ``episodes.jsonl`` line is ``line`` gets a recording under ``--record record``."""
    if record not in RECORD_CHOICES:
        raise ValueError(f"record={record!r}: expected one of {', '.join(RECORD_CHOICES)}")
    return record == "all" or (record == "failures" and not line["success"])


def episode_notes(line: dict[str, Any], policy: str) -> str:
    """Markdown of an episode's ``episodes.jsonl`` line: what it was, how it ended, then every figure."""
    head = (f"**{line.get('scenario', '?')}**, episode {line.get('episode', '?')} (seed {line.get('seed', '?')}), "
            f"policy `{policy}`: {line.get('outcome', '?')}")
    if line.get("collision"):
        head += ", robot at fault" if RATES["collision_at_fault"](line) else ", robot not at fault"
    figures = [f"| {key} | {strict_json.dumps(value)} |" for key, value in line.items()
               if key not in ("scenario", "episode", "seed", "outcome")]
    return "\n".join([head, "", "| figure | value |", "|---|---|", *figures])


class EpisodeTape(gym.Wrapper):
    """An STCrowd env with an ego that keeps the states of the running episode, to write them to Rerun afterwards.

    Args:
        env: the env (made by ``gym.make``; its ``unwrapped`` is a ``CrowdEnv`` with an ego).
        forecasts: keep the forecasts (False: a policy run without them, ``--predictor none``; the env's
            stand-still forecasts would only clutter the recording).

    Attributes:
        states: per state since the last reset, the keywords of ``RerunLogger.log_step``.
        collision: (state index, where [m], termination) of the episode's collision, or None.
    """

    def __init__(self, env: gym.Env, forecasts: bool = True):
        super().__init__(env)
        self.forecasts = forecasts
        self.states: list[dict[str, Any]] = []
        self.collision: tuple[int, np.ndarray, str] | None = None
        self._walls_m: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.states, self.collision = [], None
        self._keep(obs, info, 0.0)
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        before_m = self.states[-1]["ego_xy_m"] if self.states else None
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._keep(obs, info, reward)
        termination = info.get("termination")
        if termination in COLLISIONS:
            where = self.states[-1]["ego_xy_m"]
            impact_s = info.get("contact_time_s")
            if termination == "pedestrian_collision" and before_m is not None and impact_s is not None:
                where = before_m + min(1.0, impact_s / STEP_S) * (where - before_m)  # the robot at the impact
            self.collision = (len(self.states) - 1, where, termination)
        return obs, reward, terminated, truncated, info

    def _keep(self, obs: dict[str, np.ndarray], info: dict[str, Any], reward: float) -> None:
        state = rerun_step(obs, info, reward, ego=True)
        if not self.forecasts:
            state["predictions"] = state["prediction_ids"] = None
        self.states.append(state)

    def write(self, target: str | os.PathLike, line: dict[str, Any], policy: str) -> Path | None:
        """Write the episode that just ended to ``target`` (a .rrd path, or "spawn" for a viewer); ``line`` is its
        ``episodes.jsonl`` line (for the notes and the collision's fault). Returns the file written (a numbered
        sibling if ``target`` existed; None for a viewer).

        Raises:
            RecordingPathError, RecordingWriteError: ``target`` cannot be written (``st_sim.rerun_log``).
        """
        from st_sim.rerun_log import RerunLogger

        scene = self.unwrapped.scene
        if self._walls_m is None:
            self._walls_m = map_wall_segments(scene)
        with RerunLogger(target, scene, notes=episode_notes(line, policy)) as log:
            log.log_walls(self._walls_m)
            for step, state in enumerate(self.states):
                log.log_step(step, **state)
            if self.collision is not None:
                step, where, termination = self.collision
                at_fault = bool(RATES["collision_at_fault"](line))
                label = f"{termination.replace('_', ' ')}, robot {'at fault' if at_fault else 'not at fault'}"
                log.log_marker(step, "collision", where, label, AT_FAULT_RGB if at_fault else NOT_AT_FAULT_RGB)
        return log.path


class BenchmarkRecorder:
    """The recordings of one benchmark chunk (``benchmark --record``): run the episodes in ``env``, and hand each
    episode's ``episodes.jsonl`` line to ``keep``, which writes ``<folder>/<episode>.rrd`` if the episode is chosen.

    Args:
        env: the scenario's env.  record: a ``RECORD_CHOICES`` value.  folder: the scenario's recordings folder.
        policy, predictor: what the run measures (the notes name them; no forecasts are kept for "none").
    """

    def __init__(self, env: gym.Env, record: str, folder: str | os.PathLike, policy: str, predictor: str):
        chosen(record, {"success": True})  # refuses an unknown choice before any episode
        self.record, self.folder = record, Path(folder)
        self.env = env if record == "none" else EpisodeTape(env, forecasts=predictor != "none")
        self.label = policy if predictor == "none" else f"{policy} + {predictor}"

    def keep(self, line: dict[str, Any]) -> Path | None:
        """Write the episode that just ended if ``--record`` chose it (replacing a recording of it that a killed run
        left); returns the file, or None."""
        if not chosen(self.record, line):
            return None
        path = self.folder / f"{line['episode']}.rrd"
        path.unlink(missing_ok=True)
        return self.env.write(path, line, self.label)
