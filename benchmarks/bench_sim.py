"""Speed and physical soundness of the pymunk crowd simulator, side by side with PySocialForce.

Both engines run the bidirectional corridor (20 m x 8 m, closed walls, gates at both ends) with the same
initial crowd (positions, goals, preferred speeds from ``CrowdSim``), 0.4 s steps. Only ``step`` is
timed; after every step the script measures the deepest overlap of two 0.25 m discs, the deepest intrusion
into a wall and the pedestrians whose centre left the walkable map ("escapes").

    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py            # 50, 200, 500 pedestrians
    OMP_NUM_THREADS=1 python benchmarks/bench_sim.py --sizes 200 --steps 300 --no-psf

PySocialForce is a benchmark-only extra (``pip install pysocialforce``); without it the script says so and
runs STCrowd alone. Its defaults are kept except: 0.4 s steps, no groups, walls sampled every 0.1 m.
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from st_sim.sim import CrowdConfig, CrowdSim, make_layout
from st_sim.sim.diagnostics import escaped, max_overlap_m, wall_penetration_m

RADIUS_M = 0.25  # disc radius of every overlap figure [m]
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
    max_overlap_m: float
    max_wall_intrusion_m: float
    escapes: int
    mean_speed_mps: float

    def row(self) -> str:
        return (f"{self.engine:<14}{self.n_pedestrians:>6}{self.steps:>7}{self.steps_per_s:>10.1f}"
                f"{100 * self.max_overlap_m:>13.2f}{100 * self.max_wall_intrusion_m:>14.2f}{self.escapes:>9}"
                f"{self.mean_speed_mps:>11.2f}")


HEADER = (f"{'engine':<14}{'peds':>6}{'steps':>7}{'steps/s':>10}{'overlap cm':>13}{'wall int. cm':>14}"
          f"{'escapes':>9}{'speed m/s':>11}")


def bench_stcrowd(n: int, steps: int, warmup: int, seed: int) -> Figures:
    """Run CrowdSim with n pedestrians (kept at n by spawning) and time ``step``."""
    layout = make_layout("corridor")
    cfg = CrowdConfig(max_pedestrians=n, spawn_rate_hz=2.0)
    sim = CrowdSim(layout, cfg, np.random.default_rng(seed), n_initial=n)
    for _ in range(warmup):
        sim.step()
    elapsed, overlap, intrusion, speeds, gone = 0.0, 0.0, 0.0, [], set()
    for _ in range(steps):
        start = time.perf_counter()
        sim.step()
        elapsed += time.perf_counter() - start
        xy = sim.positions_m
        overlap = max(overlap, max_overlap_m(xy, RADIUS_M))
        intrusion = max(intrusion, wall_penetration_m(layout, xy, RADIUS_M))
        gone |= set(sim.ids[escaped(layout, xy)].tolist())
        speeds.append(np.linalg.norm(sim.velocities_mps, axis=1).mean())
    return Figures("stcrowd", n, steps, steps / elapsed, overlap, intrusion, len(gone), float(np.mean(speeds)))


def bench_pysocialforce(n: int, steps: int, seed: int) -> Figures | None:
    """Run PySocialForce from the same initial crowd as CrowdSim; None if it is not installed."""
    logging.getLogger("numba").setLevel(logging.WARNING)  # PySocialForce turns on DEBUG logging for everything
    try:
        import pysocialforce
    except ImportError as err:
        print(f"PySocialForce unavailable ({err}); `pip install pysocialforce` to compare")
        return None
    layout = make_layout("corridor")
    sim = CrowdSim(layout, CrowdConfig(max_pedestrians=n), np.random.default_rng(seed), n_initial=n)
    state = np.concatenate([sim.positions_m, sim.velocities_mps, sim.goals_m], axis=1)
    walls = [(a[0], b[0], a[1], b[1]) for a, b in layout.walls_m]
    with tempfile.TemporaryDirectory() as tmp:
        config = Path(tmp) / "psf.toml"
        config.write_text(PSF_CONFIG)
        psf = pysocialforce.Simulator(state, groups=None, obstacles=walls, config_file=str(config))
    psf.step(2)  # numba compiles on the first calls
    elapsed, overlap, intrusion, speeds, gone = 0.0, 0.0, 0.0, [], set()
    for _ in range(steps):
        start = time.perf_counter()
        psf.step(1)
        elapsed += time.perf_counter() - start
        xy = psf.peds.pos()
        overlap = max(overlap, max_overlap_m(xy, RADIUS_M))
        intrusion = max(intrusion, wall_penetration_m(layout, xy, RADIUS_M))
        gone |= set(np.flatnonzero(escaped(layout, xy)).tolist())
        speeds.append(np.linalg.norm(psf.peds.vel(), axis=1).mean())
    return Figures("pysocialforce", n, steps, steps / elapsed, overlap, intrusion, len(gone), float(np.mean(speeds)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 200, 500],
                        help="pedestrian counts (default: 50 200 500)")
    parser.add_argument("--steps", type=int, default=200, help="timed 0.4 s steps of STCrowd (default: 200)")
    parser.add_argument("--warmup", type=int, default=10, help="untimed steps before timing (default: 10)")
    parser.add_argument("--psf-steps", type=int, default=30, help="timed steps of PySocialForce (default: 30)")
    parser.add_argument("--no-psf", action="store_true", help="skip PySocialForce")
    parser.add_argument("--seed", type=int, default=0, help="crowd seed (default: 0)")
    args = parser.parse_args(argv)

    print("corridor 20 m x 8 m, bidirectional; 0.4 s steps; overlap/intrusion of 0.25 m discs")
    print(HEADER)
    for n in args.sizes:
        print(bench_stcrowd(n, args.steps, args.warmup, args.seed).row(), flush=True)
        if not args.no_psf:
            psf = bench_pysocialforce(n, args.psf_steps, args.seed)
            if psf is not None:
                print(psf.row(), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
