"""How far a retrained model lands from the original when only floating-point order changes (as on another CPU).

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/retrain_spread.py --runs runs/spread

Each model is trained twice with the same seed and data: with one torch thread and with two (a different
summation order in the matrix products, the kind of difference another machine makes). Both are scored on
the test split; the table prints the epoch each run selected on validation FDE and the test ADE / FDE gap.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
from pathlib import Path

from predictor.checkpoint import load
from predictor.train import TRAIN_SUMMARY, TrainConfig, read_summary
from st_sim.apps.grid import Job, raise_on_failure, run_jobs
from st_sim.scoring import evaluate_offline

MODELS = (("stochastic", "zara1"), ("stochastic", "eth"), ("deterministic", "hotel"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs/spread", help="training folder (default: runs/spread)")
    parser.add_argument("--workers", type=int, default=2, help="parallel trainings (default: 2)")
    args = parser.parse_args()
    jobs = []
    for task, scene in MODELS:
        for threads in (1, 2):
            out = Path(args.runs) / task / scene / f"threads{threads}"
            cfg = TrainConfig(task=task, scene=scene, out=str(out), threads=threads, progress=False)
            jobs.append(Job(f"{task}/{scene}/threads{threads}", "predictor.train:train_job", asdict(cfg),
                            str(out / TRAIN_SUMMARY)))
    raise_on_failure(run_jobs(jobs, workers=args.workers, desc="train"))
    print("| model | threads | selected epoch | val FDE | test ADE / FDE | test gap ADE / FDE |")
    print("|---|---|---|---|---|---|")
    for task, scene in MODELS:
        rows = []
        for threads in (1, 2):
            out = Path(args.runs) / task / scene / f"threads{threads}"
            result = evaluate_offline(load(out / "best.pt"), task, scene)
            rows.append((threads, read_summary(out)["best"], result))
        gap = (abs(rows[0][2].ade - rows[1][2].ade), abs(rows[0][2].fde - rows[1][2].fde))
        for threads, best, result in rows:
            print(f"| {task}/{scene} | {threads} | {best['epoch']} | {best['fde']:.4f} | "
                  f"{result.ade:.4f} / {result.fde:.4f} | {gap[0]:.4f} / {gap[1]:.4f} |")


if __name__ == "__main__":
    main()
