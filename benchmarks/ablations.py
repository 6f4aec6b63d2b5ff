"""Ablations of SingularTrajectory on ZARA1 (stochastic): K, fixed vs adaptive anchors, DDIM steps M, objective.

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/ablations.py --runs runs/ablations [--workers N | --executor ray --ray-address HOST:PORT]

Each variant is trained with the default configuration except the named change, then scored on the test split
(offline windows). The objective comparison also runs on ETH. Training and scoring are two grids
(``st_sim.apps.grid``): every model trains in ``RUNS/<changed settings>/<task>/<scene>/seed<k>/`` (``default``
when nothing changes; ``train.json`` marks a finished run) and every score is kept in
``RUNS/evaluations/<task>/<scene>/<checkpoint label>-offline.json``, so a rerun skips what is done and an
interrupted one resumes.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from predictor.registry import run_dir
from predictor.train import TRAIN_SUMMARY, TrainConfig
from st_sim.apps.evaluate import source_label
from st_sim.apps.grid import Job, raise_on_failure, run_jobs, summary_lines
from st_sim.command_line import add_grid_arguments

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


@dataclass(frozen=True)
class Model:
    """One model of a benchmark table: the default ``TrainConfig`` but ``overrides``, on a task, scene and seed."""

    task: str
    scene: str
    overrides: dict[str, Any] = field(default_factory=dict)
    seed: int = 0

    def config(self, runs: Path, data_root: str | None) -> TrainConfig:
        """Its training configuration, with ``out`` in ``runs``: models with the same settings share a folder."""
        default = TrainConfig()
        changed = {k: v for k, v in sorted(self.overrides.items()) if getattr(default, k) != v}
        variant = "_".join(f"{k}={v}" for k, v in changed.items()) or "default"
        out = run_dir(runs / variant, self.task, self.scene, self.seed)
        return replace(TrainConfig(task=self.task, scene=self.scene, seed=self.seed, out=str(out),
                                   data_root=data_root, progress=False), **changed)


def evaluation_job(cfg: TrainConfig, runs: Path) -> Job:
    """Score a finished run's ``best.pt`` offline on its test split; the JSON is named after the checkpoint."""
    checkpoint = Path(cfg.out) / "best.pt"
    output = runs / "evaluations" / cfg.task / cfg.scene / f"{source_label(str(checkpoint))}-offline.json"
    return Job(f"evaluate/{Path(cfg.out).relative_to(runs)}", "st_sim.apps.evaluate:evaluate_job",
               {"source": str(checkpoint), "task": cfg.task, "scene": cfg.scene, "root": cfg.data_root,
                "stream": False, "momentary_from_8": False, "rerun_path": None, "output": str(output)}, str(output))


def train_and_score(models: list[Model], runs: Path, grid: dict[str, Any],
                    data_root: str | None = None) -> list[dict[str, float]]:
    """Train the models that have not finished, then score each one; one row per model, in order.

    Args:
        runs: the models' folder; made absolute, since a Ray cluster's workers run in their own folders.
        grid: ``run_jobs`` options: ``executor``, ``workers``, ``address``.
        data_root: ETH/UCY folder (made absolute; None: each worker's $STCROWD_DATA or the cache).

    Returns:
        Per model: test ``ade``, ``fde`` [m], ``map`` and ``paths`` (map-violation shares of points and paths),
        ``wall`` (training wall time [s]) and ``val_fde`` (validation FDE of the selected epoch [m]).
    """
    runs, data_root = runs.resolve(), None if data_root is None else str(Path(data_root).resolve())
    configs = [model.config(runs, data_root) for model in models]
    training = {cfg.out: Job(f"train/{Path(cfg.out).relative_to(runs)}", "predictor.train:train_job", asdict(cfg),
                             str(Path(cfg.out) / TRAIN_SUMMARY)) for cfg in configs}
    reports = run_jobs(list(training.values()), desc="train", **grid)
    raise_on_failure(reports)
    scoring = {cfg.out: evaluation_job(cfg, runs) for cfg in configs}
    reports += run_jobs(list(scoring.values()), desc="evaluate", **grid)
    raise_on_failure(reports)
    print("\n".join(summary_lines(reports)) + "\n")
    rows = []
    for cfg in configs:
        result = json.loads(Path(scoring[cfg.out].output).read_text())
        summary = json.loads((Path(cfg.out) / TRAIN_SUMMARY).read_text())
        rows.append({"ade": result["ade"], "fde": result["fde"], "map": result["map_violation"],
                     "paths": result["path_map_violation"], "wall": summary["wall_s"],
                     "val_fde": summary["best"]["fde"]})
    return rows


def grid_options(args: argparse.Namespace) -> dict[str, Any]:
    """``run_jobs`` options from the flags of ``add_grid_arguments``."""
    return {"executor": args.executor, "workers": args.workers, "address": args.ray_address}


def add_arguments(parser: argparse.ArgumentParser, runs: str) -> None:
    """The flags both benchmark scripts take: the runs folder, the data root and the grid's executor."""
    parser.add_argument("--runs", default=runs, help=f"checkpoint folder (default: {runs})")
    parser.add_argument("--data-root", default=None,
                        help="ETH/UCY folder, the same path on every machine (default: each worker's $STCROWD_DATA "
                             "or the cache)")
    add_grid_arguments(parser)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser, "runs/ablations")
    parser.add_argument("--only", nargs="*", default=None, help="variant names to run (default: all)")
    args = parser.parse_args()
    names = [name for name in VARIANTS if args.only is None or name in args.only]
    models = [Model("stochastic", VARIANTS[name][0], VARIANTS[name][1]) for name in names]
    rows = train_and_score(models, Path(args.runs), grid_options(args), args.data_root)
    print("| variant | scene | ADE / FDE | map-violation points (paths) | train wall |")
    print("|---|---|---|---|---|")
    for name, model, r in zip(names, models, rows, strict=True):
        print(f"| {name} | {model.scene} | {r['ade']:.4f} / {r['fde']:.4f} | {100 * r['map']:.2f}% "
              f"({100 * r['paths']:.1f}%) | {r['wall']:.0f} s |")


if __name__ == "__main__":
    main()
