"""Ablations of SingularTrajectory on ZARA1 (stochastic): K, fixed vs adaptive anchors, DDIM steps M, objective.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/ablations.py --runs runs/ablations

Each variant is trained with the default configuration except the named change (checkpoints are reused
when present, so the script resumes), then scored on the ZARA1 test split. The objective comparison also
runs on ETH.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import torch

from predictor.checkpoint import load, read_checkpoint
from predictor.train import TrainConfig
from predictor.train import main as train
from st_sim.scoring import evaluate_offline

VARIANTS = {  # name -> (scene, overrides of TrainConfig)
    "K=1": ("zara1", {"k": 1}),
    "K=2": ("zara1", {"k": 2}),
    "K=4 (default)": ("zara1", {}),
    "K=6": ("zara1", {"k": 6}),
    "fixed anchors": ("zara1", {"adapt_anchors": False}),
    "M=1": ("zara1", {"steps": 1}),
    "M=5": ("zara1", {"steps": 5}),
    "objective eps (zara1)": ("zara1", {"objective": "eps"}),
    "objective eps (eth)": ("eth", {"objective": "eps"}),
    "objective e2e (eth, default)": ("eth", {}),
}


def finished(last: dict, epochs: int) -> bool:
    """Whether a run's last.pt has all its epochs (``epochs`` for runs saved before the planned total was kept)."""
    return last["epoch"] + 1 >= last.get("epochs", epochs)


def run_variant(runs: Path, name: str, scene: str, overrides: dict, task: str = "stochastic") -> dict:
    """Train (or reuse) one variant in ``runs/<name>`` and score it on ``scene``'s test split."""
    out = runs / name.replace(" ", "_").replace("(", "").replace(")", "").replace(",", "")
    cfg = replace(TrainConfig(task=task, scene=scene, out=str(out), progress=False), **overrides)
    if not (out / "best.pt").is_file() or not finished(read_checkpoint(out / "last.pt"), cfg.epochs):
        train(cfg)  # resumes an interrupted run
    r = evaluate_offline(load(out / "best.pt"), task, scene)
    last = read_checkpoint(out / "last.pt")
    return {"name": name, "scene": scene, "ade": r.ade, "fde": r.fde, "map": r.map_violation,
            "paths": r.path_map_violation, "wall": last["history"][-1]["wall_s"], "val_fde": last["best"]["fde"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs/ablations", help="checkpoint folder (default: runs/ablations)")
    parser.add_argument("--only", nargs="*", default=None, help="variant names to run (default: all)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = [run_variant(Path(args.runs), name, scene, overrides) for name, (scene, overrides) in VARIANTS.items()
            if args.only is None or name in args.only]
    print("| variant | scene | ADE / FDE | map-violation points (paths) | train wall |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['name']} | {r['scene']} | {r['ade']:.4f} / {r['fde']:.4f} | {100 * r['map']:.2f}% "
              f"({100 * r['paths']:.1f}%) | {r['wall']:.0f} s |")


if __name__ == "__main__":
    main()
