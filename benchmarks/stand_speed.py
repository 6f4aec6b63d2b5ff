"""Choose single-sample models' standing threshold on the validation splits (never the test splits).

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/stand_speed.py --runs runs

For every ``runs/<task>/<scene>/seed0/best.pt`` of the deterministic task and the 20 domain pairs, predicts
the validation windows once per ``stand_speed_m`` (agents whose last step is shorter keep constant velocity),
each window on its own scene's map, and prints the validation FDE per model and its mean per task [m].
"""

from __future__ import annotations

import argparse
import statistics
from dataclasses import replace
from pathlib import Path

import numpy as np

from predictor.checkpoint import load
from replays import load_scene, load_windows, scene_of_recording
from st_sim.apps.evaluate import task_scenes
from st_sim.metrics import ade_fde

THRESHOLDS_M = (0.0, 0.02, 0.05, 0.1)  # metres per 0.4 s step; 0 = every agent through the refiner


def validation_fde(path: Path, task: str, scene: str) -> list[float]:
    """Mean validation FDE [m] of one checkpoint for each threshold of ``THRESHOLDS_M``."""
    model = load(path)
    val = load_windows(task, scene, "val")
    names = np.array([scene_of_recording(r).name for r in val.recording])
    fdes = []
    for threshold_m in THRESHOLDS_M:
        model.cfg = replace(model.cfg, stand_speed_m=threshold_m)
        pred = np.empty((len(val), 1, *val.fut.shape[1:]), np.float32)
        for name in np.unique(names):
            own = names == name
            pred[own] = model.predict(val.obs[own], val.group[own], load_scene(name), 1)
        fdes.append(float(ade_fde(pred, val.fut)[1].mean()))
    return fdes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs", help="training folder <task>/<scene>/seed0/ (default: runs)")
    args = parser.parse_args()
    header = " | ".join(f"{t:g}" for t in THRESHOLDS_M)
    print(f"| task | model | val FDE at stand_speed_m = {header} (m/step) |")
    print("|---|---|" + "---|" * len(THRESHOLDS_M))
    for task in ("deterministic", "domain"):
        rows = {scene: validation_fde(path, task, scene) for scene in task_scenes(task)
                if (path := Path(args.runs, task, scene, "seed0", "best.pt")).exists()}
        for scene, fdes in rows.items():
            print(f"| {task} | {scene} | " + " | ".join(f"{f:.4f}" for f in fdes) + " |")
        if rows:
            means = [statistics.fmean(column) for column in zip(*rows.values(), strict=True)]
            print(f"| {task} | **mean of {len(rows)}** | " + " | ".join(f"{m:.4f}" for m in means) + " |")


if __name__ == "__main__":
    main()
