"""How far two benchmark results of one policy differ, episode line by episode line, over the scenarios they share:
lines that differ in any figure, outcomes that differ, successes each way (after a change that moves episodes on
purpose, to say how many moved).

    python benchmarks/compare_rows.py results/benchmark runs/regen          # each folder of the second beside its
                                                                            # namesake in the first
"""

from __future__ import annotations

import argparse
from pathlib import Path

from st_sim.apps.navigation.result_folder import load_result


def compare(old_folder: Path, new_folder: Path) -> tuple[int, int, int, int, int]:
    """(episodes compared, lines that differ, outcomes that differ, successes in old, in new) over the scenarios of
    ``new_folder``'s result."""
    old = {scenario["name"]: scenario for scenario in load_result(old_folder)["scenarios"]}
    counts = [0, 0, 0, 0, 0]
    for scenario in load_result(new_folder)["scenarios"]:
        for was, now in zip(old[scenario["name"]]["episodes"], scenario["episodes"], strict=True):
            for k, value in enumerate((1, was != now, was["outcome"] != now["outcome"], was["success"],
                                       now["success"])):
                counts[k] += int(value)
    return tuple(counts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old", type=Path, help="a folder of benchmark results (results/benchmark)")
    parser.add_argument("new", type=Path, help="a folder of runs named as the old ones, of some of their scenarios")
    args = parser.parse_args()
    print("| result | episodes | lines that differ | outcomes that differ | successes before | after |")
    print("|---|---|---|---|---|---|")
    total = [0, 0, 0, 0, 0]
    for new in sorted(path for path in args.new.iterdir() if (path / "summary.json").is_file()):
        counts = compare(args.old / new.name, new)
        total = [a + b for a, b in zip(total, counts, strict=True)]
        print(f"| {new.name} | " + " | ".join(map(str, counts)) + " |")
    print("| all | " + " | ".join(map(str, total)) + " |")


if __name__ == "__main__":
    main()
