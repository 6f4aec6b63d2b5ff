"""Tune the peers (``st_sim.apps.navigation.peers``) on the val split: a small grid of settings per peer, each cell
one benchmark run; the pick is the cell with the highest success, the lower at-fault collision rate breaking ties.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/tune_peers.py --out runs/peer_tune/grid --workers 1 > runs/peer_tune/grid.log 2>&1
    python benchmarks/tune_peers.py --out runs/peer_tune/grid --peers navground-hl   # one peer (or resume it)

The grids were run in two rounds: first one setting at a time from the untuned settings (and combinations with the
best so far), then a few cells round the first round's best (marked in ``GRIDS``). A cell is a peer's settings
dataclass with its defaults (the adapter's untuned settings: each library's defaults and the adapter's guidance) and
the cell's overrides, run as the policy ``tune_peers:GRID.<peer>.<cell>`` (hyphens of the peer's name as
underscores) through the benchmark (``st_sim.apps.navigation.benchmark``) with predictor none on the val split's
first ``EPISODES`` seeds of each of ``SCENARIOS``, into ``OUT/<peer>/<cell>/``. The same run by hand, from this
folder: ``python -m st_sim benchmark --policy tune_peers:GRID.navground_hl.eta1 --predictor none --suite val
--scenarios sim-crossing sim-bottleneck doorway eth-log univ-reactive --episodes 30 --out DIR``.

Resuming: a cell whose ``summary.json`` is there (the benchmark writes it atomically, last) is done and skipped; a
killed cell resumes from its finished episodes; a cell whose unfinished episodes ran on other code (the benchmark
refuses to mix them) is started afresh. ``REFERENCES`` (policies that are not the adapter, such as the docs-only HL
wrapper ``hl_from_docs``) run after their peer's cells on the same episodes, for the table only. Prints a markdown
table of every cell (success, at fault, collisions, timeouts over the 150 episodes; success per scenario) and each
peer's pick; the shipped adapters' ``tuned`` settings are the picks.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import time
from dataclasses import replace
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from envs.suite import load_suite
from st_sim.apps.navigation.benchmark import BenchmarkError, BenchmarkRun, check_run, run_benchmark
from st_sim.apps.navigation.peers import (
    NavgroundHL,
    NavgroundHrvo,
    NavgroundOrca,
    NavgroundSocialForce,
    PeerPlanner,
    PySocialForcePlanner,
)

SCENARIOS = ("sim-crossing", "sim-bottleneck", "doorway", "eth-log", "univ-reactive")
"""the val scenarios the peers are tuned on: simulated crowds, a scripted encounter and two replays"""
EPISODES = 30  # val episodes per scenario [-]
GRIDS: dict[str, tuple[type[PeerPlanner], dict[str, dict[str, Any]]]] = {
    # HL's eta: the robot's speed lets it stop eta before a collision; the envs' robot needs 0.75 s to stop from
    # 1.5 m/s (2 m/s^2), navground's eta is 0.5 s
    "navground-hl": (NavgroundHL, {
        "untuned": {},
        "eta1": {"eta_s": 1.0},
        "eta1p5": {"eta_s": 1.5},
        "eta2": {"eta_s": 2.0},
        "eta1p5_margin0p1": {"eta_s": 1.5, "safety_margin_m": 0.1},
        "eta1p5_tau0p25": {"eta_s": 1.5, "tau_s": 0.25},
        "eta1p5_goal": {"eta_s": 1.5, "waypoint_m": math.inf},
        "eta1p5_waypoint2": {"eta_s": 1.5, "waypoint_m": 2.0},
        "eta1p5_aperture_half": {"eta_s": 1.5, "aperture_rad": math.pi / 2},
        "eta1p5_sensing8": {"eta_s": 1.5, "sensing_m": 8.0, "horizon_m": 8.0},
        # round 2, round the first round's best (eta1p5_margin0p1)
        "eta1_margin0p1": {"eta_s": 1.0, "safety_margin_m": 0.1},
        "eta1p5_margin0p2": {"eta_s": 1.5, "safety_margin_m": 0.2},
        "eta1p5_margin0p3": {"eta_s": 1.5, "safety_margin_m": 0.3},
    }),
    # the slowest peer: fewer cells. Time horizons among people and against walls [s]
    "navground-orca": (NavgroundOrca, {
        "untuned": {},
        "horizon1": {"time_horizon_s": 1.0},
        "horizon3": {"time_horizon_s": 3.0},
        "walls0p4": {"static_time_horizon_s": 0.4},
        "margin0p1": {"safety_margin_m": 0.1},
        "goal": {"waypoint_m": math.inf},
        # round 2, round the first round's best (margin0p1)
        "margin0p2": {"safety_margin_m": 0.2},
        "margin0p3": {"safety_margin_m": 0.3},
    }),
    # navground's social force: its people's repulsion reaches 0.3 m (people_range_m), its walls' (10 m^2/s^2 within
    # 0.2 m) stop the robot in front of the doorway's 1.2 m door
    "navground-sf": (NavgroundSocialForce, {
        "untuned": {},
        "people0p6": {"people_range_m": 0.6},
        "people0p6_speed0p7": {"people_range_m": 0.6, "speed_share": 0.7},
        "people1_speed0p7": {"people_range_m": 1.0, "speed_share": 0.7},
        "people0p6_walls3": {"people_range_m": 0.6, "wall_strength_m2ps2": 3.0},
        "people0p6_walls3_speed0p7": {"people_range_m": 0.6, "wall_strength_m2ps2": 3.0, "speed_share": 0.7},
        "people0p6_speed0p7_wallsensing1p5": {"people_range_m": 0.6, "speed_share": 0.7, "wall_sensing_m": 1.5},
        "people0p6_speed0p7_goal": {"people_range_m": 0.6, "speed_share": 0.7, "waypoint_m": math.inf},
        # round 2, round the first round's best (people0p6_walls3_speed0p7)
        "people0p6_walls3_speed0p8": {"people_range_m": 0.6, "wall_strength_m2ps2": 3.0, "speed_share": 0.8},
        "people0p6_walls1_speed0p7": {"people_range_m": 0.6, "wall_strength_m2ps2": 1.0, "speed_share": 0.7},
        "people0p8_walls3_speed0p7": {"people_range_m": 0.8, "wall_strength_m2ps2": 3.0, "speed_share": 0.7},
    }),
    # HRVO's velocity obstacles have no time horizon: every wall within wall_sensing_m forbids the velocities toward it
    "navground-hrvo": (NavgroundHrvo, {
        "untuned": {},
        "wallsensing1": {"wall_sensing_m": 1.0},
        "wallsensing1p5": {"wall_sensing_m": 1.5},
        "wallsensing2": {"wall_sensing_m": 2.0},
        "wallsensing1p5_margin0p1": {"wall_sensing_m": 1.5, "safety_margin_m": 0.1},
        "wallsensing1p5_uncertainty0p2": {"wall_sensing_m": 1.5, "uncertainty_offset_mps": 0.2},
        "wallsensing1p5_speed0p8": {"wall_sensing_m": 1.5, "speed_share": 0.8},
        "wallsensing1p5_goal": {"wall_sensing_m": 1.5, "waypoint_m": math.inf},
        # round 2, round the first round's best (wallsensing1p5_speed0p8)
        "wallsensing2_speed0p8": {"wall_sensing_m": 2.0, "speed_share": 0.8},
        "wallsensing1p5_speed0p6": {"wall_sensing_m": 1.5, "speed_share": 0.6},
        "wallsensing2_speed0p8_uncertainty0p2": {"wall_sensing_m": 2.0, "speed_share": 0.8,
                                                 "uncertainty_offset_mps": 0.2},
    }),
    # PySocialForce's walls (factor 10, sigma 0.2 m, summed over wall points every 0.1 m) stop the robot in front of
    # the doorway's door; then the people's repulsion, the relaxation time, the speed, the target
    "pysocialforce": (PySocialForcePlanner, {
        "untuned": {},
        "walls3_sigma0p1": {"obstacle_factor": 3.0, "obstacle_sigma_m": 0.1},
        "walls1_sigma0p1": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1},
        "walls1_sigma0p1_social10": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "social_factor": 10.0},
        "walls1_sigma0p1_relax1": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "relaxation_time_s": 1.0},
        "walls1_sigma0p1_speed0p8": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "speed_share": 0.8},
        "walls1_sigma0p1_wallsensing1p5": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "wall_sensing_m": 1.5},
        "walls1_sigma0p1_goal": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "waypoint_m": math.inf},
        # round 2, round the first round's best (walls1_sigma0p1_social10)
        "walls1_sigma0p1_social20": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "social_factor": 20.0},
        "walls1_sigma0p1_social10_speed0p8": {"obstacle_factor": 1.0, "obstacle_sigma_m": 0.1, "social_factor": 10.0,
                                              "speed_share": 0.8},
        "walls0p5_sigma0p1_social10": {"obstacle_factor": 0.5, "obstacle_sigma_m": 0.1, "social_factor": 10.0},
    }),
}
"""peer -> (adapter class, cell name -> overrides of its settings dataclass's defaults); the first cell is untuned"""
REFERENCES: dict[str, tuple[str, ...]] = {"navground-hl": ("hl_from_docs:DocsHL",)}
"""peer -> policies run on the same episodes for comparison, never picked"""


def _attribute(peer: str) -> str:
    return peer.replace("-", "_")


GRID = SimpleNamespace(**{
    _attribute(peer): SimpleNamespace(**{cell: partial(cls, settings=replace(type(cls.tuned)(), **overrides))
                                         for cell, overrides in cells.items()})
    for peer, (cls, cells) in GRIDS.items()})
"""the cells as policies: ``GRID.<peer>.<cell>`` builds the adapter with the cell's settings"""


def run_cell(policy: str, out: Path, episodes: int, workers: int) -> dict[str, Any]:
    """The benchmark summary of ``policy`` on ``episodes`` val episodes of each of ``SCENARIOS``, from ``out`` if
    finished there, else run (resumed where it was killed, afresh where its unfinished episodes ran on other code)."""
    summary = out / "summary.json"
    if summary.is_file():
        return json.loads(summary.read_text())
    run = BenchmarkRun(policy, str(out), predictor="none", split="val", episodes=episodes, scenarios=SCENARIOS)
    if out.is_dir():
        try:
            check_run(run, load_suite(run.suite_file))
        except BenchmarkError as err:  # the folder's episodes are of another run
            print(f"  {err}: starting it afresh", flush=True)
            shutil.rmtree(out)
    return run_benchmark(run, workers=workers, progress=False)


def figures(summary: dict[str, Any]) -> dict[str, float]:
    """Pooled success, at-fault collision, collision and timeout rates [-] and the run's wall time [s]."""
    pooled = summary["summary"]
    return {"success": pooled["success"]["value"], "at_fault": pooled["collision_at_fault"]["value"],
            "collision": pooled["collision"]["value"], "timeout": pooled["timeout"]["value"],
            "wall_s": summary["timing"]["wall_s"]}


def pick(rows: list[tuple[str, dict[str, float]]]) -> str:
    """The cell with the highest success, the lower at-fault rate breaking ties, then the earlier cell."""
    return min(enumerate(rows), key=lambda item: (-item[1][1]["success"], item[1][1]["at_fault"], item[0]))[1][0]


def table_row(peer: str, cell: str, overrides: str, summary: dict[str, Any]) -> str:
    f = figures(summary)
    per_scenario = " / ".join(f"{s['summary']['success']['value']:.2f}" for s in summary["scenarios"])
    return (f"| {peer} | {cell} | {overrides} | {f['success']:.3f} | {f['at_fault']:.3f} | {f['collision']:.3f} | "
            f"{f['timeout']:.3f} | {per_scenario} | {f['wall_s']:.0f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--peers", nargs="+", default=list(GRIDS), choices=list(GRIDS),
                        help="peers to tune, in this order (default: all)")
    parser.add_argument("--out", default="runs/peer_tune/grid", help="cell folders (default: runs/peer_tune/grid)")
    parser.add_argument("--episodes", type=int, default=EPISODES,
                        help=f"val episodes per scenario (default: {EPISODES}; fewer: a smoke test, in another --out)")
    parser.add_argument("--workers", type=int, default=1,
                        help="parallel chunks per cell (default: 1, in this process; more: a process pool)")
    args = parser.parse_args()

    out = Path(args.out)
    runs = []
    for peer in args.peers:
        runs += [(peer, cell, f"tune_peers:GRID.{_attribute(peer)}.{cell}", out / peer / cell)
                 for cell in GRIDS[peer][1]]
        runs += [(peer, spec, spec, out / peer / spec.replace(":", "_")) for spec in REFERENCES.get(peer, ())]
    summaries: dict[tuple[str, str], dict[str, Any]] = {}
    for k, (peer, cell, policy, folder) in enumerate(runs, start=1):
        start = time.perf_counter()
        summaries[peer, cell] = summary = run_cell(policy, folder, args.episodes, args.workers)
        f = figures(summary)
        print(f"[{k}/{len(runs)}] {peer} {cell}: success {f['success']:.3f}, at fault {f['at_fault']:.3f} "
              f"({time.perf_counter() - start:.0f} s now)", flush=True)

    print(f"\nval split, {args.episodes} episodes of each of {', '.join(SCENARIOS)} (success per scenario in that "
          "order)\n"
          "| peer | cell | overrides | success | at fault | collision | timeout | success per scenario | wall [s] |\n"
          "|---|---|---|---|---|---|---|---|---|")
    for peer, cell, _, _ in runs:
        overrides = GRIDS[peer][1].get(cell)
        shown = "reference" if overrides is None else ", ".join(f"{k}={v:g}" for k, v in overrides.items()) or "-"
        print(table_row(peer, cell, shown, summaries[peer, cell]))
    print("\n| peer | pick | overrides | success | at fault | grid wall [s] |\n|---|---|---|---|---|---|")
    for peer in args.peers:
        cells = GRIDS[peer][1]
        rows = [(cell, figures(summaries[peer, cell])) for cell in cells]
        chosen = pick(rows)
        f = dict(rows)[chosen]
        shown = ", ".join(f"{k}={v:g}" for k, v in cells[chosen].items()) or "-"
        print(f"| {peer} | {chosen} | {shown} | {f['success']:.3f} | {f['at_fault']:.3f} | "
              f"{sum(r['wall_s'] for _, r in rows):.0f} |")


if __name__ == "__main__":
    main()
