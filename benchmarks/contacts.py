"""The simulator's contact bounds over many seeds: every layout x head count, each run checked at every step.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/contacts.py --seeds 200 --steps 200 --out runs/contacts          # the RESULTS figures
    python benchmarks/contacts.py --seeds 6 --steps 60 --layouts corridor bottleneck    # a quick look

Layouts: the synthetic ones (corridor, crossing, bottleneck, corner, periodic corridor) and the five ETH/UCY scenes'
geometries. Head counts: 10, 50, 200, 500, or as many as fit where the layout holds fewer (its densest crowd);
entries refill the crowd as fast as there is room. Seed k runs variant ``VARIANTS[k % 3]`` of
``st_sim.sim.soundness`` (the layout's own population, a mixed one with people standing and groups, or the own one
with an ego robot driving through). Runs go through the grid runner (``st_sim.apps.grid``): one job per layout,
head count and chunk of seeds writes ``OUT/<layout>/<n>/seeds<a>-<b>.json``, so an interrupted command resumes
and ``--executor ray`` spreads it over a cluster. The table gives, per layout and head count, the worst overlap of
two pedestrians and the deepest wall intrusion with the seed and step where each happened, against the bounds the
README states (``soundness.OVERLAP_BOUND_M``, ``WALL_BOUND_M``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.scenes import SCENE_NAMES
from st_sim.apps.grid import Job, raise_on_failure, run_jobs
from st_sim.command_line import add_grid_arguments
from st_sim.sim.layouts import SYNTHETIC
from st_sim.sim.soundness import OVERLAP_BOUND_M, WALL_BOUND_M

LAYOUTS = (*SYNTHETIC, *SCENE_NAMES)
SIZES = (10, 50, 200, 500)
CHUNK = 10  # seeds per job


def jobs_of(layouts: list[str], sizes: list[int], seeds: int, steps: int, out: Path,
            data_root: str | None) -> list[Job]:
    """One job per layout, head count and chunk of CHUNK seeds."""
    jobs = []
    for layout in layouts:
        for n in sizes:
            for first in range(0, seeds, CHUNK):
                chunk = list(range(first, min(first + CHUNK, seeds)))
                output = out / layout / str(n) / f"seeds{chunk[0]}-{chunk[-1]}_steps{steps}.json"
                jobs.append(Job(f"contacts/{layout}/{n}/seeds{chunk[0]}-{chunk[-1]}",
                                "st_sim.sim.soundness:soundness_job",
                                {"layout": layout, "n": n, "seeds": chunk, "steps": steps, "output": str(output),
                                 "data_root": data_root}, str(output)))
    return jobs


def table(runs: list[dict]) -> tuple[list[str], dict]:
    """Markdown rows per layout and head count, and the overall worst cases."""
    lines = ["| layout | asked | placed | runs | speed m/s | worst overlap cm (seed, variant, step) "
             "| worst wall intrusion cm (seed, variant, step) | escapes |", "|---|---|---|---|---|---|---|---|"]
    cells: dict[tuple[str, int], list[dict]] = {}
    for run in runs:
        cells.setdefault((run["layout"], run["asked"]), []).append(run)
    for (layout, asked), cell in cells.items():
        o = max(cell, key=lambda r: r["max_overlap_m"])
        w = max(cell, key=lambda r: r["max_wall_m"])
        placed = sorted({r["placed"] for r in cell})
        placed_txt = str(placed[0]) if len(placed) == 1 else f"{placed[0]}-{placed[-1]}"
        speed = sum(r["mean_speed_mps"] for r in cell) / len(cell)
        lines.append(f"| {layout} | {asked} | {placed_txt} | {len(cell)} | {speed:.2f} "
                     f"| {100 * o['max_overlap_m']:.2f} ({o['seed']}, {o['variant']}, {o['overlap_step']}) "
                     f"| {100 * w['max_wall_m']:.2f} ({w['seed']}, {w['variant']}, {w['wall_step']}) "
                     f"| {sum(r['escapes'] for r in cell)} |")
    o = max(runs, key=lambda r: r["max_overlap_m"])
    w = max(runs, key=lambda r: r["max_wall_m"])
    worst = {"runs": len(runs), "max_overlap_m": o["max_overlap_m"], "overlap_run": o,
             "max_wall_m": w["max_wall_m"], "wall_run": w, "escapes": sum(r["escapes"] for r in runs),
             "overlap_bound_m": OVERLAP_BOUND_M, "wall_bound_m": WALL_BOUND_M}
    return lines, worst


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--layouts", nargs="+", default=list(LAYOUTS), choices=LAYOUTS, help="default: all ten")
    parser.add_argument("--sizes", nargs="+", type=int, default=list(SIZES),
                        help="head counts (default: 10 50 200 500)")
    parser.add_argument("--seeds", type=int, default=200, help="seeds 0..N-1 per layout and head count (default: 200)")
    parser.add_argument("--steps", type=int, default=200, help="0.4 s steps per run (default: 200)")
    parser.add_argument("--out", default="runs/contacts", help="folder of the per-job JSON (default: runs/contacts)")
    parser.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    add_grid_arguments(parser)
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.steps < 1 or min(args.sizes) < 1:
        parser.error("--seeds, --steps and --sizes must be positive")
    out = Path(args.out).resolve()
    data_root = None if args.data_root is None else str(Path(args.data_root).resolve())
    jobs = jobs_of(args.layouts, args.sizes, args.seeds, args.steps, out, data_root)
    reports = run_jobs(jobs, executor=args.executor, workers=args.workers, address=args.ray_address, desc="contacts")
    raise_on_failure(reports)
    runs = [run for job in jobs for run in json.loads(Path(job.output).read_text())]
    lines, worst = table(runs)
    print("\n".join(lines))
    o, w = worst["overlap_run"], worst["wall_run"]
    print(f"\n{len(runs)} runs of {args.steps} steps. Worst overlap {100 * worst['max_overlap_m']:.2f} cm "
          f"(bound {100 * OVERLAP_BOUND_M:.0f} cm): {o['layout']}, {o['asked']} asked, seed {o['seed']} "
          f"({o['variant']}), step {o['overlap_step']}. Deepest wall intrusion {100 * worst['max_wall_m']:.2f} cm "
          f"(bound {100 * WALL_BOUND_M:.0f} cm): {w['layout']}, {w['asked']} asked, seed {w['seed']} ({w['variant']}), "
          f"step {w['wall_step']}. Escapes: {worst['escapes']}.")
    report = {"steps": args.steps, "seeds": args.seeds, **worst}
    write_text_atomic(out / "summary.json", strict_json.dumps(report, indent=1))
    held = worst["max_overlap_m"] <= OVERLAP_BOUND_M and worst["max_wall_m"] <= WALL_BOUND_M and not worst["escapes"]
    return 0 if held else 1


if __name__ == "__main__":
    raise SystemExit(main())
