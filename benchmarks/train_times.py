"""Training wall time of every checkpoint under a runs folder, per task (from each checkpoint's own history).

    python benchmarks/train_times.py --runs runs

Reads ``runs/<task>/<scene>/last.pt`` (the per-epoch ``wall_s`` covers data preparation onwards, and
continues across a resume) and prints min / median / max seconds per model and the total per task.
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from predictor.checkpoint import read_checkpoint
from replays.constants import TASKS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs", help="folder holding <task>/<scene>/last.pt (default: runs)")
    args = parser.parse_args()
    print("| task | models | train wall per model (s): min / median / max | total (min) |")
    print("|---|---|---|---|")
    grand_total_s = 0.0
    for task in TASKS:
        paths = sorted(Path(args.runs, task).glob("*/last.pt"))
        if not paths:
            continue
        walls = [read_checkpoint(p)["history"][-1]["wall_s"] for p in paths]
        grand_total_s += sum(walls)
        print(f"| {task} | {len(walls)} | {min(walls):.0f} / {statistics.median(walls):.0f} / {max(walls):.0f} | "
              f"{sum(walls) / 60:.1f} |")
    print(f"\ntotal: {grand_total_s / 60:.1f} min of training wall time")


if __name__ == "__main__":
    main()
