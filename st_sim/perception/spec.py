"""What the robot's people sensor can do: range, field of view, occlusion, noise, misses, false detections, latency.

``SENSING_LEVELS`` names a ladder that adds one effect at a time: ``oracle`` (every pedestrian's exact past under a
stable id, as the envs gave before sensing existed; the default), ``range`` (a 10 m, 270 degree sensor), ``occluded``
(walls and other people hide those behind them), ``noisy`` (positions off by a normal error that grows with distance)
and ``realistic`` (some people missed, some ghosts seen). Every level but ``oracle`` goes through the tracker
(``st_sim.perception.tracker``), so the histories a predictor gets are tracks: short, gappy and noisy where the
sensor is.

Where the numbers come from: range and field of view are a common 2D laser's (Arena-Rosnav's 720-ray robots see 270
degrees to 30 m; robot_sf's lidar 360 degrees to 10 m; we take robot_sf's 10 m with the laser's 270 degrees). No
anchor calibrates its noise, misses or ghosts (robot_sf's pedestrian noise defaults to 0, and its docs say the
detections are not calibrated); ours are settings of the order of a leg detector on a 2D laser, stated here and
varied by anyone through ``SensingSpec``: 5 cm plus 1 % of the distance (one sigma), 10 % of visible people missed in
a step, 0.2 ghosts per step in the field of view, no latency (one step, 0.4 s, is longer than a detector's own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from st_sim.sim.checks import named


class SensingSpecError(ValueError):
    """A sensing level or setting that cannot be used; the message names the field."""


@dataclass(frozen=True)
class SensingSpec:
    """The sensor's settings (metres, degrees, steps of 0.4 s). ``oracle=True`` skips sensor and tracker: the robot
    sees every pedestrian's exact past under its true id."""

    oracle: bool = False
    """every pedestrian seen exactly, no tracker (the other fields are then unused)"""
    range_m: float = math.inf
    """people whose centre is farther from the robot's are not seen [m], (0, inf]"""
    fov_deg: float = 360.0
    """field of view, centred on the robot's heading [deg], (0, 360]"""
    occlusion: bool = False
    """people whose line of sight from the robot's centre passes through a wall or another person's body are not
    seen"""
    noise_m: float = 0.0
    """standard deviation of each detected coordinate at distance 0 [m], [0, 5]"""
    noise_per_m: float = 0.0
    """growth of that standard deviation per metre of distance [m/m], [0, 1]"""
    miss_rate: float = 0.0
    """chance that a visible person is not detected in a step, [0, 1]"""
    false_per_step: float = 0.0
    """mean number of false detections (ghosts) per step, spread over the field of view within range, [0, 100]"""
    latency_steps: int = 0
    """steps between what the sensor saw and when the tracker gets it, [0, 10]"""

    def __post_init__(self) -> None:
        if not isinstance(self.oracle, bool) or not isinstance(self.occlusion, bool):
            raise SensingSpecError(f"SensingSpec.oracle / occlusion = {self.oracle!r} / {self.occlusion!r}: "
                                   "expected True or False")
        ranges = {"range_m": (0.0, math.inf, True), "fov_deg": (0.0, 360.0, True), "noise_m": (0.0, 5.0, False),
                  "noise_per_m": (0.0, 1.0, False), "miss_rate": (0.0, 1.0, False),
                  "false_per_step": (0.0, 100.0, False)}
        for name, (low, high, open_low) in ranges.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating) or not (
                    low < value <= high if open_low else low <= value <= high) or math.isnan(value):
                side = "(" if open_low else "["
                raise SensingSpecError(f"SensingSpec.{name} = {value!r}: expected a number in {side}{low:g}, {high:g}]")
        latency = self.latency_steps
        if isinstance(latency, bool) or not isinstance(latency, int | np.integer) or not 0 <= latency <= 10:
            raise SensingSpecError(f"SensingSpec.latency_steps = {latency!r}: expected an int in [0, 10]")
        if self.false_per_step > 0 and not math.isfinite(self.range_m):
            raise SensingSpecError("SensingSpec.false_per_step > 0 needs a finite range_m (ghosts appear within it)")


SENSING_LEVELS: dict[str, SensingSpec] = {
    "oracle": SensingSpec(oracle=True),
    "range": SensingSpec(range_m=10.0, fov_deg=270.0),
    "occluded": SensingSpec(range_m=10.0, fov_deg=270.0, occlusion=True),
    "noisy": SensingSpec(range_m=10.0, fov_deg=270.0, occlusion=True, noise_m=0.05, noise_per_m=0.01),
    "realistic": SensingSpec(range_m=10.0, fov_deg=270.0, occlusion=True, noise_m=0.05, noise_per_m=0.01,
                             miss_rate=0.1, false_per_step=0.2),
}
"""the ladder, one effect added per level (module docstring)"""


def sensing_spec(sensing: str | SensingSpec | None) -> SensingSpec:
    """The spec ``sensing`` names: a ``SensingSpec`` as it is, a level's name (``SENSING_LEVELS``), None for
    ``oracle``; ``SensingSpecError`` naming the choices for anything else."""
    return named(sensing, SENSING_LEVELS, SensingSpec, "oracle", "sensing", SensingSpecError)
