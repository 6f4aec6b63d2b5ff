"""Verification and validation of the crowd simulator: the applicable RiMEA tests, the fundamental diagram against
Weidmann's, counter-flow lanes, bottleneck flow against the published range, the ego seen or not, and the steering
models side by side (the calibrated speed model, social force, and ORCA through pyrvo as an outside reference).

Scenarios come from ``st_sim.sim.validation`` (seed 0). RiMEA tests that apply to a flat, single-floor simulator:
1 (free walking speed: 40 m at 1.33 m/s within 26-34 s), 4 (fundamental diagram in a periodic corridor),
6 (20 people round a corner, nobody through a wall), 7 (speed distribution of a population: Kolmogorov-Smirnov
distance below 0.19 at n = 50), 12-like (flow through a bottleneck vs its width). Stairs (2, 3), reaction times (5),
buildings and exits (8-11, 13-15) do not apply. The fundamental-diagram plot (PNG, matplotlib) goes to --out;
``--replot OUT/sim_validation.json`` redraws it from the saved figures.

    OMP_NUM_THREADS=1 python benchmarks/sim_validation.py                         # all, both models and ORCA
    OMP_NUM_THREADS=1 python benchmarks/sim_validation.py --models speed_model --quick
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.constants import STEP_S
from st_sim.charts import band_chart, save_figure
from st_sim.sim import CrowdConfig, CrowdSim, EgoConfig, SocialForceConfig, SpeedModelConfig, make_layout
from st_sim.sim.config import WALL_RADIUS_M
from st_sim.sim.layouts import periodic_corridor
from st_sim.sim.measures import SPECIFIC_FLOW_RANGE, lane_index, weidmann_speed_mps
from st_sim.sim.validation import (
    FREE_WALK_RANGE_S,
    KS_PASS,
    LANE_BAND_M,
    LANE_WINDOW_M,
    bottleneck_flow,
    corner_walk,
    counterflow,
    free_walk_time_s,
    fundamental_diagram,
    speed_distribution_ks,
)

MODELS = {"speed_model": SpeedModelConfig(), "social_force": SocialForceConfig()}
DENSITIES = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)  # [1/m^2]
TWO_WAY_DENSITIES = (1.0, 1.5, 2.0)  # [1/m^2]
DOORS_M = (0.8, 1.0, 1.2, 1.6, 2.0, 2.5)
FD_BAND = 0.2  # target: within +-20 % of Weidmann from 0.5 to 3 /m^2
GRIDLOCK_MPS = 0.05  # slower than this counts as gridlock [m/s]


def rimea(cfg: CrowdConfig) -> dict[str, dict]:
    """RiMEA tests 1, 6 and 7: figures and pass/fail."""
    walk_s = free_walk_time_s(cfg)
    arrived, corner_s, intrusion, escapes = corner_walk(cfg)
    ks, _, _ = speed_distribution_ks(cfg)
    return {
        "1 free walk": {"figure": f"{walk_s:.1f} s for 40 m (allowed {FREE_WALK_RANGE_S[0]:g}-"
                                  f"{FREE_WALK_RANGE_S[1]:g} s)",
                        "pass": FREE_WALK_RANGE_S[0] <= walk_s <= FREE_WALK_RANGE_S[1]},
        "6 corner": {"figure": f"{arrived}/20 arrived in {corner_s:.1f} s, deepest wall intrusion "
                               f"{100 * intrusion:.1f} cm, {escapes} escapes",
                     "pass": arrived == 20 and escapes == 0 and intrusion < 0.02},
        "7 speed distribution": {"figure": f"Kolmogorov-Smirnov distance {ks:.3f} (n = 50, pass below {KS_PASS})",
                                 "pass": ks < KS_PASS},
    }


def fd_rows(cfg: CrowdConfig, quick: bool) -> list[dict]:
    steps = 40 if quick else 100
    rows = []
    for rho in DENSITIES:
        flow = fundamental_diagram(cfg, rho, warmup_steps=steps, steps=steps)
        ref = float(weidmann_speed_mps(rho))
        rows.append({"density": rho, "speed": flow.mean_speed_mps, "weidmann": ref, "ratio": flow.mean_speed_mps / ref,
                     "overlap_cm": 100 * flow.max_overlap_m, "escapes": flow.escapes})
    return rows


def lane_rows(cfg: CrowdConfig, quick: bool) -> list[dict]:
    steps = 40 if quick else 100
    rows = []
    for rho in TWO_WAY_DENSITIES:
        flow = fundamental_diagram(cfg, rho, width_m=8.0, two_way=True, warmup_steps=steps, steps=steps)
        rows.append({"setting": f"periodic 20 m x 8 m, two-way, {rho:g} /m^2", "speed": flow.mean_speed_mps,
                     "lanes": flow.lane_index, "overlap_cm": 100 * flow.max_overlap_m})
    flow = counterflow(cfg, steps=60 if quick else 150)
    rows.append({"setting": f"corridor 20 m x 8 m, gates, {flow.n_pedestrians:.0f} pedestrians (1.25 /m^2)",
                 "speed": flow.mean_speed_mps, "lanes": flow.lane_index, "overlap_cm": 100 * flow.max_overlap_m})
    return rows


def ego_contacts(cfg: CrowdConfig, see: bool, seeds: int) -> float:
    """Share of steps in which a standing ego in the middle of the two-way corridor (60 pedestrians) is touched."""
    touched = steps = 0
    for seed in range(seeds):
        sim = CrowdSim(make_layout("corridor"), replace(cfg, max_pedestrians=60, spawn_rate_hz=2.0),
                       np.random.default_rng(seed), ego=EgoConfig(start_m=(10.0, 4.0), pedestrians_see_ego=see))
        for _ in range(150):
            sim.step(np.zeros(2))
            touched += sim.ego_collided
            steps += 1
    return touched / steps


def orca_fd(density: float, two_way: bool, quick: bool, length_m: float = 20.0, width_m: float = 4.0) -> dict | None:
    """ORCA (pyrvo) in the periodic corridor: mean speed and lane index; None without pyrvo.

    pyrvo has no periodic boundary: agents are moved back across the seam each 0.1 s step and do not see each
    other across it, which lets them speed up a little there.
    """
    try:
        import pyrvo
    except ImportError:
        print("pyrvo unavailable; `pip install pyrvo` for the ORCA reference")
        return None
    cfg = CrowdConfig()
    n = round(density * length_m * (width_m - 2 * WALL_RADIUS_M))
    sim0 = CrowdSim(periodic_corridor(length_m, width_m, two_way), replace(cfg, max_pedestrians=n),
                    np.random.default_rng(0))
    xy, goal_x, v0 = sim0.positions_m, np.sign(sim0.goals_m[:, 0] - length_m / 2), sim0.preferred_speeds_mps
    dt, substeps = 0.1, round(STEP_S / 0.1)
    orca = pyrvo.RVOSimulator(dt, 2.0, 10, 2.0, 0.5, cfg.radius_m, float(v0.max()))
    for p, speed in zip(xy, v0, strict=True):
        agent = orca.add_agent((float(p[0]), float(p[1])))
        orca.set_agent_max_speed(agent, float(speed) * cfg.max_speed_factor)
    for y in (0.0, width_m):  # thin walls along the corridor, beyond both ends of the period
        orca.add_obstacle([(-5.0, y - WALL_RADIUS_M), (length_m + 5.0, y - WALL_RADIUS_M),
                           (length_m + 5.0, y + WALL_RADIUS_M), (-5.0, y + WALL_RADIUS_M)])
    orca.process_obstacles()
    speeds, lanes = [], []
    steps = 40 if quick else 100
    for step in range(2 * steps):
        before = np.array([orca.get_agent_position(k).to_tuple() for k in range(len(xy))])
        for _ in range(substeps):
            for k in range(len(xy)):
                orca.set_agent_pref_velocity(k, (float(goal_x[k] * v0[k]), 0.0))
            orca.do_step()
            for k in range(len(xy)):
                p = orca.get_agent_position(k)
                if not 0.0 <= p.x < length_m:
                    orca.set_agent_position(k, (p.x % length_m, p.y))
        after = np.array([orca.get_agent_position(k).to_tuple() for k in range(len(xy))])
        moved = after - before
        moved[:, 0] -= length_m * np.rint(moved[:, 0] / length_m)
        if step >= steps:
            speeds.append(np.linalg.norm(moved, axis=1).mean() / STEP_S)
            lanes.append(lane_index(after, goal_x, LANE_BAND_M, LANE_WINDOW_M))
    return {"density": density, "speed": float(np.mean(speeds)), "lanes": float(np.mean(lanes)) if two_way else None}


def plot_fd(results: dict[str, list[dict]], orca: list[dict], path: Path) -> Path:
    """Weidmann's curve with its +-20 % band and every model's measured points (matplotlib PNG)."""
    rho = np.linspace(0.3, 5.4, 200)
    weidmann = weidmann_speed_mps(rho)
    series = {**results, **({"ORCA (pyrvo)": orca} if orca else {})}
    figure = band_chart(
        "density [pedestrians/m²]", "mean speed [m/s]",
        ("Weidmann", rho, weidmann, np.stack([(1 - FD_BAND) * weidmann, (1 + FD_BAND) * weidmann])),
        {name.replace("_", " "): (np.array([r["density"] for r in rows]), np.array([r["speed"] for r in rows]))
         for name, rows in series.items()},
        band_label=f"Weidmann ±{FD_BAND:.0%}", title="Fundamental diagram, periodic 20 m × 4 m corridor, one-way")
    return save_figure(figure, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", choices=sorted(MODELS), default=sorted(MODELS),
                        help="steering models to validate (default: both)")
    parser.add_argument("--no-orca", action="store_true", help="skip the ORCA (pyrvo) reference")
    parser.add_argument("--quick", action="store_true", help="shorter runs (40 instead of 100 measured steps)")
    parser.add_argument("--out", type=Path, default=Path("results/sim_validation"),
                        help="folder for the plot and the JSON figures (default: results/sim_validation)")
    parser.add_argument("--replot", type=Path, default=None, metavar="JSON",
                        help="only redraw the plot from a saved sim_validation.json (written beside it)")
    args = parser.parse_args(argv)
    if args.replot is not None:
        print(f"plot: {replot(args.replot)}")
        return 0

    report: dict[str, dict] = {}
    fd: dict[str, list[dict]] = {}
    for name in args.models:
        cfg = CrowdConfig(steering=MODELS[name])
        print(f"\n## {name}\n\n### RiMEA\n| test | figure | pass |\n|---|---|---|")
        tests = rimea(cfg)
        for test, result in tests.items():
            print(f"| {test} | {result['figure']} | {'pass' if result['pass'] else 'FAIL'} |", flush=True)
        print("\n### Fundamental diagram (RiMEA 4), periodic 20 m x 4 m, one-way\n| density /m^2 | speed m/s "
              "| Weidmann m/s | ratio | within +-20 % | overlap cm |\n|---|---|---|---|---|---|")
        fd[name] = fd_rows(cfg, args.quick)
        for row in fd[name]:
            within = abs(row["ratio"] - 1) <= FD_BAND if row["density"] <= 3 else row["speed"] > GRIDLOCK_MPS
            print(f"| {row['density']:g} | {row['speed']:.2f} | {row['weidmann']:.2f} | {row['ratio']:.2f} "
                  f"| {'yes' if within else 'NO'}{' (no gridlock)' if row['density'] > 3 else ''} "
                  f"| {row['overlap_cm']:.1f} |", flush=True)
        print("\n### Counter-flow and lanes\n| setting | speed m/s | lane index | overlap cm |\n|---|---|---|---|")
        lanes = lane_rows(cfg, args.quick)
        for row in lanes:
            print(f"| {row['setting']} | {row['speed']:.2f} | {row['lanes']:.2f} | {row['overlap_cm']:.1f} |",
                  flush=True)
        print(f"\n### Bottleneck (west room 8.5 m x 8 m, 150 people, wall 0.4 m), published "
              f"{SPECIFIC_FLOW_RANGE[0]}-{SPECIFIC_FLOW_RANGE[1]} /(m s)\n| door m | specific flow /(m s) | last out s "
              "| in range |\n|---|---|---|---|")
        doors = []
        for door in DOORS_M:
            specific, last_s = bottleneck_flow(cfg, door)
            doors.append({"door": door, "specific_flow": specific, "last_out_s": last_s})
            ok = SPECIFIC_FLOW_RANGE[0] <= specific <= SPECIFIC_FLOW_RANGE[1]
            print(f"| {door:g} | {specific:.2f} | {last_s:.0f} | {'yes' if ok else 'no'} |", flush=True)
        seen, unseen = ego_contacts(cfg, True, 2), ego_contacts(cfg, False, 2)
        print(f"\n### Ego standing in the two-way corridor (60 pedestrians, 2 x 150 steps)\nsteps with contact: "
              f"{100 * seen:.1f} % with pedestrians_see_ego=True, {100 * unseen:.1f} % with False", flush=True)
        report[name] = {"rimea": tests, "fundamental_diagram": fd[name], "lanes": lanes, "bottleneck": doors,
                        "ego_contact_share": {"seen": seen, "unseen": unseen}, "steering": asdict(cfg.steering)}
    orca: list[dict] = []
    if not args.no_orca:
        print("\n## ORCA (pyrvo), periodic corridor\n| setting | speed m/s | Weidmann m/s | lane index |\n"
              "|---|---|---|---|")
        for rho in DENSITIES:
            row = orca_fd(rho, False, args.quick)
            if row is None:
                break
            orca.append(row)
            print(f"| one-way 20 m x 4 m, {rho:g} /m^2 | {row['speed']:.2f} | {float(weidmann_speed_mps(rho)):.2f} | |",
                  flush=True)
        for rho in TWO_WAY_DENSITIES if orca else ():
            row = orca_fd(rho, True, args.quick, width_m=8.0)
            print(f"| two-way 20 m x 8 m, {rho:g} /m^2 | {row['speed']:.2f} | | {row['lanes']:.2f} |", flush=True)
            report.setdefault("orca", {})[f"two_way_{rho:g}"] = row
        report.setdefault("orca", {})["fundamental_diagram"] = orca
    plot = plot_fd(fd, orca, args.out / "fundamental_diagram.png")
    write_text_atomic(args.out / "sim_validation.json", strict_json.dumps(report, indent=2, default=float) + "\n")
    print(f"\nplot: {plot}; figures: {args.out / 'sim_validation.json'}")
    return 0


def replot(figures: Path) -> Path:
    """Redraw the fundamental diagram from a saved ``sim_validation.json`` (beside it), without simulating."""
    report = json.loads(figures.read_text())
    fd = {name: part["fundamental_diagram"] for name, part in report.items() if name in MODELS}
    return plot_fd(fd, report.get("orca", {}).get("fundamental_diagram", []),
                   figures.with_name("fundamental_diagram.png"))


if __name__ == "__main__":
    raise SystemExit(main())
