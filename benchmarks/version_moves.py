"""How each committed row moved between two benchmark versions: success and at-fault collisions pooled, and success
over the log replays, the reactive replays and the simulated scenarios, one markdown row per policy that both
folders hold.

    python benchmarks/version_moves.py results/benchmark-v3 results/benchmark
    python benchmarks/version_moves.py results/benchmark results/benchmark-tracks/diff-drive-oracle   # two tracks
"""

from __future__ import annotations

import argparse
from pathlib import Path

from st_sim.apps.navigation.leaderboard import label
from st_sim.apps.navigation.result_folder import load_result

GROUPS = (("log replays", "-log"), ("reactive replays", "-reactive"), ("simulated", ""))
"""the scenario groups a row reports, by the suffix of the scenario's name ("": neither suffix)"""


def rates(result: dict, suffix: str | None) -> tuple[float, float]:
    """(success, at-fault collision) over the episodes of ``result``'s scenarios in a group (``suffix``; None: all)."""
    def chosen(name: str) -> bool:
        if suffix is None:
            return True
        if suffix:
            return name.endswith(suffix)
        return not name.endswith(("-log", "-reactive"))

    episodes = [e for s in result["scenarios"] if chosen(s["name"]) for e in s["episodes"]]
    return (sum(e["success"] for e in episodes) / len(episodes),
            sum(e["collision_at_fault"] for e in episodes) / len(episodes))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("old", type=Path, help="a folder of result folders (one per row)")
    parser.add_argument("new", type=Path, help="another, whose rows of the same name are compared with the old")
    args = parser.parse_args()
    print("| policy | success | at fault | " + " | ".join(f"success, {name}" for name, _ in GROUPS) + " |")
    print("|---|---|---|" + "---|" * len(GROUPS))
    for new_folder in sorted(path for path in args.new.iterdir() if (path / "summary.json.gz").is_file()
                             or (path / "summary.json").is_file()):
        old_folder = args.old / new_folder.name
        if not old_folder.is_dir():
            continue
        old, new = load_result(old_folder), load_result(new_folder)
        (s0, f0), (s1, f1) = rates(old, None), rates(new, None)
        groups = " | ".join(f"{rates(old, suffix)[0]:.3f} → {rates(new, suffix)[0]:.3f}" for _, suffix in GROUPS)
        print(f"| {label(new)} | {s0:.3f} → {s1:.3f} | {f0:.3f} → {f1:.3f} | {groups} |")


if __name__ == "__main__":
    main()
