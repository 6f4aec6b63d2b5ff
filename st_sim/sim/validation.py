"""Validation scenarios of the crowd simulator: the applicable RiMEA tests, the fundamental diagram in a periodic
corridor, counter-flow and lanes, and bottleneck flow.

Each function builds its layout, runs ``CrowdSim`` with the given ``CrowdConfig`` (the scenario sets the
population, start region and head count it needs) and returns its figures. ``benchmarks/sim_validation.py``
prints them against their references, ``benchmarks/fit_steering.py`` fits the steering parameters to them,
and the tests run the cheap ones. Speeds are walking speeds from 0.4 s displacements.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Final

import numpy as np
from scipy.stats import kstest, truncnorm

from replays.constants import STEP_S
from st_sim.sim.config import WALL_RADIUS_M, CrowdConfig, PopulationConfig
from st_sim.sim.crowd import CrowdSim
from st_sim.sim.diagnostics import escaped, max_overlap_m, wall_penetration_m
from st_sim.sim.layout import Region
from st_sim.sim.layouts import GATE_DEPTH_M, bottleneck, corner, corridor, periodic_corridor
from st_sim.sim.measures import lane_index, mean_speed_mps, steady_flow_per_s, step_displacements_m

FREE_WALK_M: Final[float] = 40.0  # RiMEA test 1: distance walked [m] ...
FREE_WALK_SPEED_MPS: Final[float] = 1.33  # ... at this speed [m/s] ...
FREE_WALK_RANGE_S: Final[tuple[float, float]] = (26.0, 34.0)  # ... in a time within this range [s]
LANE_BAND_M: Final[float] = 0.3  # half-width of a lane for the lane index [m]
LANE_WINDOW_M: Final[float] = 3.0  # half-length of a lane for the lane index [m]
BOTTLENECK_SKIP: Final[int] = 10  # passages left out at both ends of a bottleneck's steady flow [-]
STALL_STEPS: Final[int] = 100  # a bottleneck run ends when nobody passed the door for this many steps (40 s)
KS_PASS: Final[float] = 0.19  # RiMEA test 7 passes below this Kolmogorov-Smirnov distance (5 % level at n = 50)


@dataclass(frozen=True)
class Flow:
    """What a crowd did over the measured steps.

    Attributes:
        density_per_m2: pedestrians per walkable area [1/m^2] (NaN for open layouts).
        n_pedestrians: pedestrians present on average [-].  mean_speed_mps: mean walking speed [m/s].
        lane_index: lane order of a two-way flow in [0, 1] (``measures.lane_index``; NaN for one-way flows).
        max_overlap_m: deepest overlap of two bodies [m].  max_wall_intrusion_m: deepest intrusion into a wall [m].
        escapes: pedestrians whose centre left the walkable map [-].
    """

    density_per_m2: float
    n_pedestrians: float
    mean_speed_mps: float
    lane_index: float
    max_overlap_m: float
    max_wall_intrusion_m: float
    escapes: int


def _box(xmin: float, ymin: float, xmax: float, ymax: float) -> Region:
    return Region("start", np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=np.float64))


def _run(sim: CrowdSim, warmup_steps: int, steps: int, two_way: bool, density_per_m2: float) -> Flow:
    """Step sim warmup_steps, then measure it over steps."""
    layout, radius = sim.layout, sim.cfg.radius_m
    for _ in range(warmup_steps):
        sim.step()
    moved, present, lanes = [], [], []
    overlap = intrusion = 0.0
    gone: set[int] = set()
    for _ in range(steps):
        ids, before = sim.ids, sim.positions_m
        sim.step()
        stay = np.isin(ids, sim.ids)
        now = sim.positions_m[np.searchsorted(sim.ids, ids[stay])]
        moved.append(step_displacements_m(before[stay], now, layout.period))
        present.append(len(sim.ids))
        xy = sim.positions_m
        overlap = max(overlap, max_overlap_m(xy, radius, layout.period))
        intrusion = max(intrusion, wall_penetration_m(layout, xy, radius))
        gone |= set(sim.ids[escaped(layout, xy)].tolist())
        if two_way:
            lanes.append(lane_index(xy, np.sign(sim.goals_m[:, 0] - xy[:, 0]), LANE_BAND_M, LANE_WINDOW_M,
                                    layout.period))
    return Flow(density_per_m2, float(np.mean(present)), mean_speed_mps(np.concatenate(moved)),
                float(np.mean(lanes)) if lanes else float("nan"), overlap, intrusion, len(gone))


def fundamental_diagram(cfg: CrowdConfig, density_per_m2: float, length_m: float = 20.0, width_m: float = 4.0,
                        two_way: bool = False, warmup_steps: int = 50, steps: int = 50, seed: int = 0) -> Flow:
    """A periodic corridor (RiMEA test 4, wrap-around) held at density_per_m2 [1/m^2] of its walkable area
    (length x (width - wall thickness)); everybody walks east (two_way: east or west at random)."""
    n = round(density_per_m2 * length_m * (width_m - 2 * WALL_RADIUS_M))
    sim = CrowdSim(periodic_corridor(length_m, width_m, two_way), replace(cfg, max_pedestrians=n, density_per_m2=None),
                   np.random.default_rng(seed))
    return _run(sim, warmup_steps, steps, two_way, density_per_m2)


def counterflow(cfg: CrowdConfig, n: int = 200, warmup_steps: int = 30, steps: int = 100, seed: int = 0) -> Flow:
    """The bidirectional corridor (20 m x 8 m, gates at both ends) held near n pedestrians by brisk spawning."""
    sim = CrowdSim(corridor(), replace(cfg, max_pedestrians=n, density_per_m2=None, spawn_rate_hz=10.0),
                   np.random.default_rng(seed))
    return _run(sim, warmup_steps, steps, True, float("nan"))


def free_walk_time_s(cfg: CrowdConfig, seed: int = 0) -> float:
    """RiMEA test 1: seconds one pedestrian at 1.33 m/s takes to walk 40 m along a 2 m wide corridor."""
    population = PopulationConfig(speed_mean_mps=FREE_WALK_SPEED_MPS, speed_std_mps=0.0,
                                  speed_range_mps=(FREE_WALK_SPEED_MPS, FREE_WALK_SPEED_MPS))
    start_x = GATE_DEPTH_M + 0.5
    sim = CrowdSim(corridor(FREE_WALK_M + 2 * start_x, 2.0), replace(cfg, population=population, spawn_rate_hz=0.0,
                   max_pedestrians=1, density_per_m2=None), np.random.default_rng(seed), n_initial=1,
                   start_region=_box(start_x - 0.5, 0.5, start_x, 1.5))
    x0 = float(sim.positions_m[0, 0])
    for _ in range(round(2 * FREE_WALK_RANGE_S[1] / STEP_S)):
        before = float(sim.positions_m[0, 0])
        sim.step()
        if len(sim.ids) == 0 or sim.positions_m[0, 0] >= x0 + FREE_WALK_M:
            after = float(sim.positions_m[0, 0]) if len(sim.ids) else x0 + FREE_WALK_M
            share = (x0 + FREE_WALK_M - before) / max(after - before, 1e-9)
            return (sim.step_count - 1 + min(share, 1.0)) * STEP_S
    return float("inf")


def speed_distribution_ks(cfg: CrowdConfig, n: int = 50, seed: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
    """RiMEA test 7: n pedestrians walk a wide corridor; Kolmogorov-Smirnov distance between their walking speeds
    and the configured distribution (cfg.population's clipped normal).

    Returns:
        ks: the distance [-].  preferred: (n,) preferred speeds drawn [m/s].  walked: (n,) mean walking speeds [m/s].
    """
    pop = replace(cfg.population, standing_share=0.0, group_share=0.0)
    sim = CrowdSim(corridor(30.0, 20.0), replace(cfg, population=pop, spawn_rate_hz=0.0, max_pedestrians=n,
                   density_per_m2=None), np.random.default_rng(seed), start_region=_box(2.0, 1.0, 8.0, 19.0))
    preferred = sim.preferred_speeds_mps
    distance = np.zeros(n)
    walking = np.zeros(n)
    for _ in range(25):
        ids, before = sim.ids, sim.positions_m
        sim.step()
        stay = np.isin(ids, sim.ids)
        now = sim.positions_m[np.searchsorted(sim.ids, ids[stay])]
        distance[ids[stay]] += np.linalg.norm(now - before[stay], axis=1)
        walking[ids[stay]] += STEP_S
    walked = distance / np.maximum(walking, STEP_S)
    low, high = pop.speed_range_mps
    std = max(pop.speed_std_mps, 1e-9)
    dist = truncnorm((low - pop.speed_mean_mps) / std, (high - pop.speed_mean_mps) / std, pop.speed_mean_mps, std)
    return float(kstest(walked, dist.cdf).statistic), preferred, walked


def bottleneck_flow(cfg: CrowdConfig, door_m: float, n: int = 150, seed: int = 0,
                    max_steps: int = 1500) -> tuple[float, float]:
    """n pedestrians start in the 8.5 m x 8 m west room and leave through a door of door_m [m] in a 0.4 m wall.

    The run ends when all passed, after max_steps, or when nobody passed for STALL_STEPS (a clogged door).

    Returns:
        specific flow [1/(m s)] (steady flow through the door per metre of width, without the first and last
        BOTTLENECK_SKIP passages) and the time [s] until the last one passed (inf if not all did).
    """
    layout = bottleneck(room_m=8.5, wall_m=0.4, height_m=8.0, door_m=door_m)
    sim = CrowdSim(layout, replace(cfg, spawn_rate_hz=0.0, max_pedestrians=n, density_per_m2=None),
                   np.random.default_rng(seed), start_region=_box(0.3, 0.3, 8.2, 7.7))
    line_x = 8.5 + 0.4
    times: list[float] = []
    passed: set[int] = set()
    last_passage = 0
    while len(passed) < n and sim.step_count < max_steps and sim.step_count - last_passage < STALL_STEPS:
        sim.step()
        beyond = sim.ids[sim.positions_m[:, 0] >= line_x].tolist()
        gone = set(range(n)) - set(sim.ids.tolist())
        new = (set(beyond) | gone) - passed
        times += [sim.step_count * STEP_S] * len(new)
        passed |= new
        last_passage = sim.step_count if new else last_passage
    flow = steady_flow_per_s(np.array(times), BOTTLENECK_SKIP)
    return flow / door_m, (times[-1] if len(passed) == n else float("inf"))


def corner_walk(cfg: CrowdConfig, n: int = 20, seed: int = 0, max_steps: int = 300) -> tuple[int, float, float, int]:
    """RiMEA test 6: n pedestrians walk from the west arm around a left corner to the north exit of a 2 m
    corridor (arms of 12 m).

    Returns:
        arrived (pedestrians who reached the exit), time [s] until the last arrival (inf if some did not),
        deepest wall intrusion [m], escapes (centres off the walkable map).
    """
    layout = corner(12.0, 2.0)
    sim = CrowdSim(layout, replace(cfg, spawn_rate_hz=0.0, max_pedestrians=n, density_per_m2=None),
                   np.random.default_rng(seed), start_region=_box(0.2, 0.2, 6.0, 1.8))
    intrusion, gone = 0.0, set()
    while len(sim.ids) and sim.step_count < max_steps:
        sim.step()
        intrusion = max(intrusion, wall_penetration_m(layout, sim.positions_m, cfg.radius_m))
        gone |= set(sim.ids[escaped(layout, sim.positions_m)].tolist())
    arrived = n - len(sim.ids)
    return arrived, (sim.step_count * STEP_S if arrived == n else float("inf")), intrusion, len(gone)
