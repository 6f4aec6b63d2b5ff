"""Speed and physical soundness of the pymunk crowd simulator, side by side with PySocialForce and navground.

Both engines run the bidirectional corridor (20 m x 8 m, closed walls, gates at both ends) from the same initial
crowd (positions, goals, preferred speeds from ``CrowdSim``), 0.4 s steps; CrowdSim keeps its head count by brisk
spawning. Only ``step`` is timed, by the process's CPU time (the machine is shared; wall-clock figures beside
it), in alternating repeats of both engines, and the speed lead is the ratio of the two engines' CPU steps per
second in the same run. A jammed crowd is cheap, so each row also gives the mean walking speed: the comparison
is between flowing crowds. After every step the script measures the deepest overlap of two pedestrian discs,
the deepest intrusion into a wall, the pedestrians whose centre left the walkable map ("escapes"), the number
present and their mean speed.

    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py                       # 50, 200, 500 pedestrians, 2 repeats
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --sizes 200 --steps 300 --no-psf
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --periodic            # STCrowd without spawning and exits
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --batched 1 16 64 256 --steps 2560   # the batched engine

With --periodic, STCrowd runs the same corridor with its ends joined (a two-way periodic corridor, the same
head count for ever: steering and contacts only, no spawning or leaving); PySocialForce, which has no periodic
boundary, still runs the gated corridor.

PySocialForce is a benchmark-only extra (``pip install -e ".[bench]"``); without it the script says so and runs
STCrowd alone. Its defaults are kept except: 0.4 s steps, no groups, walls sampled every 0.1 m.

With --batched, each repeat also runs navground (C++ with Python bindings, the same ``bench`` extra) on its ORCA
Cross scenario: 40 holonomic agents of 0.2 m radius at up to 1.4 m/s, seeing 5 m, crossing an 8 m square between
targets on its sides, updated every 0.1 s (navground's default) and every 0.2 s (STCrowd's substep); its figure is
0.4 s of simulated time per CPU second, one thread, the same unit as STCrowd's sub-env steps.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from st_sim.sim import CrowdConfig, CrowdSim, Layout, PopulationError, make_layout
from st_sim.sim.crowd import step_crowds
from st_sim.sim.diagnostics import escaped, max_overlap_m, wall_penetration_m
from st_sim.sim.layouts import periodic_corridor

NAVGROUND_TIME_STEPS_S = (0.1, 0.2)  # navground's own default control period, and STCrowd's substep [s]
SPAWN_RATE_HZ = 10.0  # per gate: refills the corridor as fast as there is room, to hold the population
PSF_CONFIG = """
[scene]
enable_group = false
step_width = 0.4
"""


@dataclass
class Figures:
    """What one run measured."""

    engine: str
    n_pedestrians: int
    steps: int
    steps_per_s: float
    cpu_steps_per_s: float
    mean_present: float
    max_overlap_m: float
    max_wall_intrusion_m: float
    escapes: int
    mean_speed_mps: float

    def row(self, lead: float | None = None) -> str:
        return (f"| {self.engine} | {self.n_pedestrians} | {self.mean_present:.0f} | {self.mean_speed_mps:.2f} "
                f"| {self.cpu_steps_per_s:.1f} | {self.steps_per_s:.1f} | {'' if lead is None else f'{lead:.1f}x'} "
                f"| {100 * self.max_overlap_m:.2f} | {100 * self.max_wall_intrusion_m:.2f} | {self.escapes} |")


HEADER = ("| engine | pedestrians | present | speed m/s | CPU steps/s | wall steps/s | lead (CPU) | overlap cm "
          "| wall intrusion cm | escapes |\n|---|---|---|---|---|---|---|---|---|---|")


class Meter:
    """Times the steps (process CPU and wall clock) and checks the crowd after each one."""

    def __init__(self, layout: Layout, radius_m: float):
        self.layout, self.radius_m = layout, radius_m
        self.wall_s = self.cpu_s = self.overlap_m = self.intrusion_m = 0.0
        self.present: list[int] = []
        self.speeds: list[float] = []
        self.escaped: set[int] = set()

    def timed(self, step: Callable[[], object]) -> None:
        wall, cpu = time.perf_counter(), time.process_time()
        step()
        self.wall_s += time.perf_counter() - wall
        self.cpu_s += time.process_time() - cpu

    def check(self, ids: np.ndarray, xy_m: np.ndarray, v_mps: np.ndarray) -> None:
        self.overlap_m = max(self.overlap_m, max_overlap_m(xy_m, self.radius_m))
        self.intrusion_m = max(self.intrusion_m, wall_penetration_m(self.layout, xy_m, self.radius_m))
        self.escaped |= set(ids[escaped(self.layout, xy_m)].tolist())
        self.present.append(len(ids))
        self.speeds.append(float(np.linalg.norm(v_mps, axis=1).mean()) if len(ids) else 0.0)

    def figures(self, engine: str, n: int) -> Figures:
        steps = len(self.present)
        return Figures(engine, n, steps, steps / self.wall_s, steps / self.cpu_s, float(np.mean(self.present)),
                       self.overlap_m, self.intrusion_m, len(self.escaped), float(np.mean(self.speeds)))


def bench_stcrowd(n: int, steps: int, warmup: int, seed: int, periodic: bool) -> Figures:
    """Run CrowdSim with n pedestrians (kept near n by brisk spawning, or in a periodic corridor) and time
    ``step``."""
    layout = periodic_corridor(20.0, 8.0, two_way=True) if periodic else make_layout("corridor")
    cfg = CrowdConfig(max_pedestrians=n, spawn_rate_hz=SPAWN_RATE_HZ)
    sim = CrowdSim(layout, cfg, np.random.default_rng(seed), n_initial=n)
    for _ in range(warmup):
        sim.step()
    meter = Meter(layout, cfg.radius_m)
    for _ in range(steps):
        meter.timed(sim.step)
        meter.check(sim.ids, sim.positions_m, sim.velocities_mps)
    return meter.figures("stcrowd periodic" if periodic else "stcrowd", n)


def bench_pysocialforce(n: int, steps: int, seed: int) -> Figures | None:
    """Run PySocialForce from the same initial crowd as CrowdSim; None if it is not installed."""
    for noisy in ("numba", "matplotlib"):  # PySocialForce turns on DEBUG logging for everything it imports
        logging.getLogger(noisy).setLevel(logging.WARNING)
    try:
        import pysocialforce
    except ImportError as err:
        print(f"PySocialForce unavailable ({err}); `pip install -e \".[bench]\"` to compare")
        return None
    logging.getLogger().setLevel(logging.WARNING)
    layout = make_layout("corridor")
    cfg = CrowdConfig(max_pedestrians=n)
    sim = CrowdSim(layout, cfg, np.random.default_rng(seed), n_initial=n)
    state = np.concatenate([sim.positions_m, sim.velocities_mps, sim.goals_m], axis=1)
    walls = [(a[0], b[0], a[1], b[1]) for a, b in layout.walls_m]
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "psf.toml"
        config.write_text(PSF_CONFIG)
        psf = pysocialforce.Simulator(state, groups=None, obstacles=walls, config_file=str(config))
    psf.step(2)  # numba compiles on the first calls
    meter = Meter(layout, cfg.radius_m)
    ids = np.arange(n)
    for _ in range(steps):
        meter.timed(lambda: psf.step(1))
        meter.check(ids, psf.peds.pos(), psf.peds.vel())
    return meter.figures("pysocialforce", n)


def bench_batched(crowds: int, steps: int, warmup: int, seed: int) -> tuple[float, float]:
    """(sub-env steps per CPU second, per wall second) of ``crowds`` 40-pedestrian crossings stepped together
    (``step_crowds``, no ego), after ``warmup`` untimed steps."""
    layout = make_layout("crossing")
    sims = [CrowdSim(layout, CrowdConfig(), np.random.default_rng(seed + k)) for k in range(crowds)]
    for _ in range(warmup):
        step_crowds(sims, [None] * crowds)
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        step_crowds(sims, [None] * crowds)
    return crowds * steps / (time.process_time() - cpu), crowds * steps / (time.perf_counter() - wall)


NAVGROUND_CROSS = """
type: Cross
side: {side}
groups:
  - type: agent
    number: {agents}
    radius: {radius}
    control_period: {time_step}
    kinematics:
      type: Omni
      max_speed: {max_speed}
    behavior:
      type: ORCA
    state_estimation:
      type: Bounded
      range: {range}
"""
"""navground's Cross scenario (agents cross a square between targets on its sides) with ORCA, holonomic pedestrians"""


def bench_navground(time_step_s: float, steps: int, warmup: int, seed: int, agents: int = 40) -> float | None:
    """Sub-env steps of 0.4 s per CPU second of navground's ORCA Cross (``agents`` discs of 0.2 m at up to 1.4 m/s
    seeing 5 m, updated every ``time_step_s``), after ``warmup`` untimed steps; None without navground."""
    try:
        from navground import sim
    except ImportError:
        return None
    scenario = sim.load_scenario(NAVGROUND_CROSS.format(side=8.0, agents=agents, radius=0.2, time_step=time_step_s,
                                                        max_speed=1.4, range=5.0))
    world = sim.World()
    scenario.init_world(world, seed=seed)
    ticks = round(0.4 / time_step_s)
    world.run(steps=warmup * ticks, time_step=time_step_s)
    cpu = time.process_time()
    world.run(steps=steps * ticks, time_step=time_step_s)
    return steps / (time.process_time() - cpu)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 200, 500],
                        help="pedestrian counts (default: 50 200 500)")
    parser.add_argument("--steps", type=int, default=200, help="timed 0.4 s steps of STCrowd (default: 200)")
    parser.add_argument("--warmup", type=int, default=20, help="untimed steps before timing (default: 20)")
    parser.add_argument("--psf-steps", type=int, default=30, help="timed steps of PySocialForce (default: 30)")
    parser.add_argument("--repeats", type=int, default=2, help="alternating runs of both engines (default: 2)")
    parser.add_argument("--no-psf", action="store_true", help="skip PySocialForce")
    parser.add_argument("--periodic", action="store_true",
                        help="STCrowd in the corridor with its ends joined (no spawning or exits)")
    parser.add_argument("--seed", type=int, default=0, help="crowd seed (default: 0)")
    parser.add_argument("--batched", type=int, nargs="+", default=[], metavar="K",
                        help="instead: K crossings of 40 pedestrians stepped together by the batched engine, for each "
                        "K (sub-env steps per second)")
    args = parser.parse_args(argv)
    if args.batched:
        print("| engine | crowds stepped together | 40-pedestrian sub-env steps of 0.4 s / CPU s | / wall s |\n"
              "|---|---|---|---|")
        for _ in range(args.repeats):  # navground's ORCA Cross beside ours, alternating, in every repeat
            for crowds in args.batched:
                cpu_rate, wall_rate = bench_batched(crowds, max(1, args.steps // crowds), args.warmup, args.seed)
                print(f"| STCrowd crossing, step_crowds | {crowds} | {cpu_rate:.0f} | {wall_rate:.0f} |", flush=True)
            for time_step_s in NAVGROUND_TIME_STEPS_S:
                rate = bench_navground(time_step_s, args.steps, args.warmup, args.seed)
                if rate is None:
                    print("| navground | – | not installed (pip install -e '.[bench]') | – |")
                    break
                print(f"| navground Cross, ORCA, {time_step_s} s updates | 1 | {rate:.0f} | – |", flush=True)
        return 0

    print("corridor 20 m x 8 m, bidirectional; 0.4 s steps; CPU = process time; lead = STCrowd's CPU steps/s over "
          "PySocialForce's in the same repeat")
    print(HEADER)
    for n in args.sizes:
        for _ in range(args.repeats):
            try:
                ours = bench_stcrowd(n, args.steps, args.warmup, args.seed, args.periodic)
            except PopulationError as err:
                print(f"| stcrowd | {n} | refused: {err} |")
                break
            psf = None if args.no_psf else bench_pysocialforce(n, args.psf_steps, args.seed)
            print(ours.row(None if psf is None else ours.cpu_steps_per_s / psf.cpu_steps_per_s), flush=True)
            if psf is not None:
                print(psf.row(), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
