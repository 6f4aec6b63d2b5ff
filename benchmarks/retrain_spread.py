"""How far a retrained model lands from the original when only floating-point order changes (as on another CPU).

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/retrain_spread.py --runs runs/spread                        # default training
    python benchmarks/retrain_spread.py --runs runs/spread --ema-decay 0 0.999    # and with averaged weights

Each model is trained twice with the same seed and data: with one torch thread and with two (a different
summation order in the matrix products, the kind of difference another machine makes), for every --ema-decay
(``TrainConfig.ema_decay``: 0 keeps the trained weights, > 0 their moving average). Both are scored on the test
split; the table prints the epoch each run selected on validation FDE and the test ADE / FDE gap between the two.
Trainings run through the grid runner (resumable).
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


def run_dir(runs: Path, task: str, scene: str, decay: float, threads: int) -> Path:
    return runs / task / scene / ("" if decay == 0 else f"ema{decay:g}") / f"threads{threads}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs/spread", help="training folder (default: runs/spread)")
    parser.add_argument("--workers", type=int, default=2, help="parallel trainings (default: 2)")
    parser.add_argument("--ema-decay", type=float, nargs="+", default=[0.0],
                        help="TrainConfig.ema_decay values to compare (default: 0)")
    parser.add_argument("--models", nargs="+", default=[f"{t}/{s}" for t, s in MODELS],
                        help="task/scene pairs (default: stochastic/zara1 stochastic/eth deterministic/hotel)")
    args = parser.parse_args()
    models = [tuple(m.split("/")) for m in args.models]
    runs = Path(args.runs).resolve()
    jobs = []
    for task, scene in models:
        for decay in args.ema_decay:
            for threads in (1, 2):
                out = run_dir(runs, task, scene, decay, threads)
                cfg = TrainConfig(task=task, scene=scene, out=str(out), threads=threads, ema_decay=decay,
                                  progress=False)
                jobs.append(Job(f"{task}/{scene}/ema{decay:g}/threads{threads}", "predictor.train:train_job",
                                asdict(cfg), str(out / TRAIN_SUMMARY)))
    raise_on_failure(run_jobs(jobs, workers=args.workers, desc="train"))
    print("| model | ema decay | threads | selected epoch | val FDE | test ADE / FDE | test gap ADE / FDE |")
    print("|---|---|---|---|---|---|---|")
    for task, scene in models:
        for decay in args.ema_decay:
            rows = []
            for threads in (1, 2):
                out = run_dir(runs, task, scene, decay, threads)
                result = evaluate_offline(load(out / "best.pt"), task, scene)
                rows.append((threads, read_summary(out)["best"], result))
            gap = (abs(rows[0][2].ade - rows[1][2].ade), abs(rows[0][2].fde - rows[1][2].fde))
            for threads, best, result in rows:
                print(f"| {task}/{scene} | {decay:g} | {threads} | {best['epoch']} | {best['fde']:.4f} | "
                      f"{result.ade:.4f} / {result.fde:.4f} | {gap[0]:.4f} / {gap[1]:.4f} |")


if __name__ == "__main__":
    main()
