"""Training wall time of every finished run under a runs folder, per task (from each run's own summary).

    python benchmarks/train_times.py --runs runs

Reads ``runs/<task>/<scene>/seed<k>/train.json``, written when a run finishes (its ``wall_s`` covers data
preparation onwards, and continues across a resume), and prints min / median / max seconds per model and the
total per task.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path

from predictor.train import TRAIN_SUMMARY
from replays.constants import TASKS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", default="runs",
                        help=f"folder holding <task>/<scene>/seed<k>/{TRAIN_SUMMARY} (default: runs)")
    args = parser.parse_args()
    print("| task | models | train wall per model (s): min / median / max | total (min) |")
    print("|---|---|---|---|")
    grand_total_s = 0.0
    for task in TASKS:
        paths = sorted(Path(args.runs, task).glob(f"*/seed*/{TRAIN_SUMMARY}"))
        if not paths:
            continue
        walls = [json.loads(p.read_text())["wall_s"] for p in paths]
        grand_total_s += sum(walls)
        print(f"| {task} | {len(walls)} | {min(walls):.0f} / {statistics.median(walls):.0f} / {max(walls):.0f} | "
              f"{sum(walls) / 60:.1f} |")
    print(f"\ntotal: {grand_total_s / 60:.1f} min of training wall time")


if __name__ == "__main__":
    main()
