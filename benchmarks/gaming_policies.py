"""The policies written to game the at-fault rule (``tests/gaming_policies.py``), and the straight planner, on the
five logged replays: pedestrian collisions and how many the rule puts at the robot's fault, per replay and pooled.

    python benchmarks/gaming_policies.py --episodes 25                       # the rule of this tree
    PYTHONPATH=OLD_TREE python benchmarks/gaming_policies.py --episodes 25   # another tree's rule, same policies
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from st_sim.apps.navigation.straight import StraightPlanner

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from gaming_policies import LOGGED_REPLAYS, Creeper, SpeedMatchedRammer, Standing, judged_collisions

POLICIES = {"straight": StraightPlanner, "speed-matched rammer": SpeedMatchedRammer, "creeper": Creeper,
            "standing": Standing}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=25, help="episodes per replay, seeds 0..N-1 (default: 25)")
    args = parser.parse_args()
    counts = {name: {} for name in POLICIES}  # policy -> replay -> (pedestrian collisions, at fault)
    for env_id in LOGGED_REPLAYS:
        for name, cls in POLICIES.items():
            verdicts = judged_collisions(cls, env_id, args.episodes)
            counts[name][env_id] = (len(verdicts), sum(v is True for v in verdicts))
    print(f"| policy | {' | '.join(r.removeprefix('STCrowd-').removesuffix('-v0') for r in LOGGED_REPLAYS)} | pooled |")
    print("|---|" + "---|" * (len(LOGGED_REPLAYS) + 1))
    for name, by_replay in counts.items():
        hits, fault = (sum(v[k] for v in by_replay.values()) for k in (0, 1))
        cells = [f"{f} / {h}" for h, f in by_replay.values()]
        print(f"| {name} | {' | '.join(cells)} | {fault} / {hits} ({fault / max(hits, 1):.0%}) |")
    print(f"cells: collisions at the robot's fault / pedestrian collisions, {args.episodes} episodes per replay")


if __name__ == "__main__":
    main()
