"""Physical soundness of a whole run: the deepest overlap of two pedestrians, the deepest intrusion into a wall and
the escapes over every step, with the step where each happened.

The contact bounds the simulator promises (``OVERLAP_BOUND_M``, ``WALL_BOUND_M``) follow from its contact rules:
two pedestrians press at most ``BODY_GIVE_M`` into each other, and a gap already overrun (by a pair beyond that
give, or a body into a wall) is never closed further than the solver's tolerance allows, which converges to
2 x ``FREEZE_TOLERANCE_MPS`` x substep. The bounds add a margin for pymunk's own contact resolution.
``benchmarks/contacts.py`` measures them over seeds, layouts and head counts; ``tests/test_sim_contacts.py``
checks them as properties.

Run variants (``VARIANTS``), so that a sweep over seeds covers every kind of crowd:
- ``own``: the layout's own population (fitted to the scene's recording in a real scene's geometry; Weidmann's
  walkers in a synthetic layout);
- ``mixed``: a third of the crowd standing a while and half walking in groups, the densest mix of bodies that
  barely move and bodies that walk abreast;
- ``ego``: the own population round an ego robot that stands at the layout's ego start, seen by the pedestrians
  (a heavy body that never gives way: the crowd is squeezed between it and the walls).

An ego that drives into pedestrians is outside these bounds: it never gives way, so it pushes whoever it hits
(a collision, which ends an env's episode on that step) into others and into walls.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, replace
from typing import Final

import numpy as np

from replays import strict_json
from replays.atomic import write_text_atomic
from st_sim.sim.config import CrowdConfig, EgoConfig, PopulationConfig
from st_sim.sim.crowd import CrowdSim
from st_sim.sim.diagnostics import escaped, max_overlap_m, wall_penetration_m
from st_sim.sim.layout import Layout
from st_sim.sim.layouts import make_layout
from st_sim.sim.population import PopulationError

OVERLAP_BOUND_M: Final[float] = 0.04  # two pedestrian discs (0.2 m) never overlap more than this [m]
WALL_BOUND_M: Final[float] = 0.01  # a pedestrian disc never reaches more than this into a wall [m]
VARIANTS: Final[tuple[str, ...]] = ("own", "mixed", "ego")
SPAWN_RATE_HZ: Final[float] = 10.0  # per entry: the crowd is refilled as fast as there is room, to keep it dense
MIXED = {"standing_share": 0.33, "dwell_mean_s": 20.0, "group_share": 0.5}  # the "mixed" population's changes


@dataclass(frozen=True)
class Soundness:
    """What one run measured (lengths in metres; steps count from 1, 0 = the initial crowd, -1 = never).

    Attributes:
        layout, variant: what ran.  asked: pedestrians asked for.  seed: the run's seed.
        placed: pedestrians in the initial crowd (fewer than asked where no more fit).
        steps: 0.4 s steps run.  mean_present: mean head count.  mean_speed_mps: mean walking speed [m/s].
        max_overlap_m, overlap_step: the deepest overlap of two pedestrians and when.
        max_wall_m, wall_step: the deepest intrusion of a pedestrian into a wall and when.
        escapes: pedestrians whose centre ever left the walkable map.
    """

    layout: str
    variant: str
    asked: int
    seed: int
    placed: int
    steps: int
    mean_present: float
    mean_speed_mps: float
    max_overlap_m: float
    overlap_step: int
    max_wall_m: float
    wall_step: int
    escapes: int


def crowd_of(layout: Layout, variant: str, n: int) -> CrowdConfig:
    """The crowd of a run variant in a layout: n pedestrians at most, refilled at SPAWN_RATE_HZ per entry."""
    if variant not in VARIANTS:
        raise ValueError(f"variant={variant!r}: expected one of {', '.join(VARIANTS)}")
    try:
        population = PopulationConfig.fitted(layout.name)
    except KeyError:
        population = PopulationConfig()
    if variant == "mixed":
        population = replace(population, **MIXED)
    return CrowdConfig(max_pedestrians=n, spawn_rate_hz=SPAWN_RATE_HZ, population=population)


def build_crowd(layout: Layout, variant: str, n: int, seed: int) -> tuple[CrowdSim, CrowdConfig]:
    """The simulator of a run: n pedestrians, or as many as fit in the layout (its densest crowd)."""
    cfg = crowd_of(layout, variant, n)
    ego = EgoConfig() if variant == "ego" else None
    try:
        return CrowdSim(layout, cfg, np.random.default_rng(seed), ego=ego), cfg
    except PopulationError as err:
        if err.fits is None:
            raise
        cfg = replace(cfg, max_pedestrians=err.fits)
        return CrowdSim(layout, cfg, np.random.default_rng(seed), ego=ego), cfg


def measure(layout: Layout, variant: str, n: int, seed: int, steps: int) -> Soundness:
    """Run ``steps`` steps of a crowd of n pedestrians (``variant``) and record its worst contacts."""
    sim, cfg = build_crowd(layout, variant, n, seed)
    placed = len(sim.ids)
    worst_overlap, worst_wall = (0.0, -1), (0.0, -1)
    present, speeds, escapes = [], [], set()
    for step in range(steps + 1):
        if step:
            sim.step()
        xy = sim.positions_m
        overlap = max_overlap_m(xy, cfg.radius_m, layout.period)
        wall = wall_penetration_m(layout, xy, cfg.radius_m)
        if overlap > worst_overlap[0]:
            worst_overlap = (overlap, step)
        if wall > worst_wall[0]:
            worst_wall = (wall, step)
        escapes |= set(sim.ids[escaped(layout, xy)].tolist())
        present.append(len(xy))
        speeds.append(float(np.linalg.norm(sim.velocities_mps, axis=1).mean()) if len(xy) else 0.0)
    return Soundness(layout.name, variant, n, seed, placed, steps, float(np.mean(present)), float(np.mean(speeds)),
                     worst_overlap[0], worst_overlap[1], worst_wall[0], worst_wall[1], len(escapes))


def soundness_job(layout: str, n: int, seeds: list[int], steps: int, output: str,
                  data_root: str | None = None) -> None:
    """Grid job: ``measure`` the layout (a synthetic one or an ETH/UCY scene's geometry) with n pedestrians for
    every seed (variant = ``VARIANTS[seed % 3]``) and write the runs as a JSON list to ``output``."""
    if data_root is not None:
        os.environ["STCROWD_DATA"] = data_root
    shape = make_layout(layout)
    runs = [asdict(measure(shape, VARIANTS[seed % len(VARIANTS)], n, seed, steps)) for seed in seeds]
    write_text_atomic(output, strict_json.dumps(runs, indent=1))
