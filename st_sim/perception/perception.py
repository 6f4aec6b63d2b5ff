"""What one robot perceives of the crowd over an episode: the sensor (``sensor``), the tracker (``tracker``), the
latency between them, and the truth beside them for evaluation (``mot``)."""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np

from replays.scenes import Scene
from st_sim.frozen_mapping import FrozenMapping
from st_sim.perception.mot import MotAccumulator
from st_sim.perception.sensor import Detections, detect, in_field
from st_sim.perception.spec import SensingSpec
from st_sim.perception.tracker import Tracker, Tracks


class PerceptionInfo(FrozenMapping):
    """One step's truth beside the perception (``info["perception"]``), read-only: a ``FrozenMapping``, so that a
    gymnasium vector env keeps each sub-env's (their arrays differ in length) instead of stacking them."""


class Perception:
    """The robot's people sensor and tracker (``SensingSpec``, not an oracle), stepped once per env step.

    Args:
        spec: the sensor's settings.  capacity: most tracks reported (the observation's rows).
        scene: the walkable map that walls occlude on.  radius_m: a person's body radius [m] (occlusion).
        robot_radius_m: the robot's [m] (lines of sight start at its edge).
    """

    def __init__(self, spec: SensingSpec, capacity: int, scene: Scene, radius_m: float, robot_radius_m: float):
        if spec.oracle:
            raise ValueError("Perception: an oracle spec needs no sensor (the env reads the truth)")
        self.spec, self.scene, self.radius_m, self.robot_radius_m = spec, scene, radius_m, robot_radius_m
        self.tracker = Tracker(capacity)
        self.rng = np.random.default_rng(0)
        self.mot = MotAccumulator()
        self._seen: deque[Detections] = deque()
        self.last: dict[str, Any] | None = None
        """the last step's truth beside the perception (``sense``)"""

    def reset(self, rng: np.random.Generator) -> None:
        """A new episode: no tracks, no pending detections, fresh counts; ``rng`` the sensor's own generator."""
        self.tracker.reset()
        self.rng = rng
        self.mot = MotAccumulator()
        self._seen.clear()
        self.last = None

    def sense(self, ids: np.ndarray, xy_m: np.ndarray, robot_xy: np.ndarray, heading: np.ndarray) -> Tracks:
        """One step: detect the true people ``ids`` (N,) at ``xy_m`` (N, 2) [m] from a robot at ``robot_xy`` facing
        ``heading`` (unit vector); the tracker takes what was detected ``latency_steps`` steps ago (nothing before
        then); returns the tracks reported now. ``last`` holds the step's truth and perception."""
        robot_xy, heading = np.asarray(robot_xy, np.float64), np.asarray(heading, np.float64)
        seen = detect(self.spec, robot_xy, heading, ids, xy_m, self.scene, self.radius_m, self.robot_radius_m,
                      self.rng)
        self._seen.append(seen)
        if len(self._seen) > self.spec.latency_steps:
            arrived = self._seen.popleft()
        else:
            arrived = Detections(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64))
        sd = self.spec.noise_m + self.spec.noise_per_m * arrived.distance_m
        tracks = self.tracker.step(arrived.xy_m, sd, arrived.source)
        xy_m = np.asarray(xy_m, np.float64).reshape(-1, 2)
        people = in_field(self.spec, robot_xy, heading, xy_m)  # evaluated where the sensor looks: its field
        reported = in_field(self.spec, robot_xy, heading, tracks.xy_m)
        self.mot.update(np.asarray(ids)[people], xy_m[people], tracks.ids[reported], tracks.xy_m[reported])
        self.last = {"true_ids": np.asarray(ids, np.int64).copy(), "true_xy_m": np.asarray(xy_m, np.float64).copy(),
                     "detected_xy_m": arrived.xy_m, "detected_from": arrived.source,
                     "track_ids": tracks.ids.copy(), "track_xy_m": tracks.xy_m.copy(),
                     "track_from": tracks.source.copy(), "mot": self.mot.summary()}
        return tracks
