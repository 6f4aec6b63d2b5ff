"""The AVG rows of every table written by ``python -m st_sim evaluate --out DIR``, beside the paper's.

    python benchmarks/summary_table.py --results results [--baselines results/baselines]

Prints one markdown row per task: the three-seed mean ± sd of the AVG ADE / FDE, the paper's AVG, the delta,
whether the target (the paper's AVG) is met, and the constant-velocity baseline where its JSON is present
(``evaluate --predictor cvm --json DIR/baseline_<task>_cvm.json``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from replays.constants import TASKS


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results", default="results", help="folder of <task>.json (default: results)")
    parser.add_argument("--baselines", default="results/baselines",
                        help="folder of baseline_<task>_<predictor>.json (default: results/baselines)")
    args = parser.parse_args()
    print("| task | seeds | STCrowd AVG ADE / FDE | paper | delta | at or below the paper | CVM | CVM-S |")
    print("|---|---|---|---|---|---|---|---|")
    for task in TASKS:
        path = Path(args.results) / f"{task}.json"
        if not path.is_file():
            continue
        result = json.loads(path.read_text())
        avg = result["avg"]
        ours = f"{avg['ade']:.3f} ± {avg['ade_sd']:.3f} / {avg['fde']:.3f} ± {avg['fde_sd']:.3f}"
        if "paper_ade" in avg:
            paper = f"{avg['paper_ade']:.2f} / {avg['paper_fde']:.2f}"
            delta = f"{avg['ade'] - avg['paper_ade']:+.3f} / {avg['fde'] - avg['paper_fde']:+.3f}"
            met = " / ".join("yes" if avg[m] < avg[f"paper_{m}"] + 0.005 else "no" for m in ("ade", "fde"))
        else:
            paper = delta = met = "–"
        baselines = []
        for name in ("cvm", "cvm-s"):
            base = Path(args.baselines) / f"baseline_{task}_{name}.json"
            if base.is_file():
                b = json.loads(base.read_text())["avg"]
                baselines.append(f"{b['ade']:.3f} / {b['fde']:.3f}")
            else:
                baselines.append("–")
        seeds = ", ".join(str(s) for s in result.get("seeds", [0]))
        print(f"| {task} | {seeds} | {ours} | {paper} | {delta} | {met} | {baselines[0]} | {baselines[1]} |")
    print("\n'at or below the paper': the mean rounds to the paper's two-decimal figure or lower (within 0.005 m).")


if __name__ == "__main__":
    main()
