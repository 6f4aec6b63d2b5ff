"""Two navigation runs on the same episodes, pair by pair: successes and at-fault collisions (one-sided McNemar both
ways), and how the episodes that only the first completes ended for the second.

    python benchmarks/paired.py runs/nav/table500-r46/STCrowd-Univ-v0__reactive__straight__none__500ep_seed0.json \
        runs/nav/table500-r46/STCrowd-Univ-v0__reactive__mpc__singular__500ep_seed0.json
    python benchmarks/paired.py results/benchmark/ppo-reactive-singular results/benchmark/mpc-singular \
        --scenarios '*-reactive'

A run is a cell of ``nav_table.py`` / ``navigate`` (its JSON) or a ``python -m st_sim benchmark`` output folder
(``summary.json``, or the committed ``summary.json.gz``), whose episodes are pooled over its scenarios (``--scenarios``
keeps those matching any of the patterns). Both runs must hold the same episodes.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
from collections import Counter
from pathlib import Path

from st_sim.apps.navigation.leaderboard import load_result
from st_sim.apps.navigation.metrics import paired_collision_test, paired_success_test


def episodes_of(path: Path, patterns: list[str]) -> list[dict]:
    """The episodes of a run, each keyed for pairing by its seed (with its scenario, in a benchmark run)."""
    if path.is_file():
        return json.loads(path.read_text())["episodes"]
    return [{**episode, "seed": (scenario["name"], episode["seed"])} for scenario in load_result(path)["scenarios"]
            if any(fnmatch.fnmatch(scenario["name"], pattern) for pattern in patterns)
            for episode in scenario["episodes"]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("first", type=Path, help="a cell JSON or a benchmark output folder")
    parser.add_argument("second", type=Path, help="the same, on the same episodes")
    parser.add_argument("--scenarios", nargs="+", default=["*"], help="benchmark runs: scenario name patterns")
    args = parser.parse_args()
    a, b = episodes_of(args.first, args.scenarios), episodes_of(args.second, args.scenarios)
    success = paired_success_test(a, b)
    print(f"{len(a)} paired episodes")
    print(f"successes: {success['a_successes']} vs {success['b_successes']} (only the first {success['only_a']}, "
          f"only the second {success['only_b']}); more for the first p = {success['p_value']:.2g}, for the second "
          f"p = {paired_success_test(b, a)['p_value']:.2g}")
    fault = paired_collision_test(a, b, at_fault=True)
    print(f"at-fault collisions: {fault['a_collisions']} vs {fault['b_collisions']} (only the first "
          f"{fault['only_a']}, only the second {fault['only_b']}); fewer for the first p = {fault['p_value']:.2g}, "
          f"for the second p = {paired_collision_test(b, a, at_fault=True)['p_value']:.2g}")
    ended = Counter(f"{second['outcome']}{', at fault' if second['at_fault'] else ''}"
                    for first, second in zip(a, b, strict=True) if first["success"] and not second["success"])
    print(f"the first completes, the second does not: {sum(ended.values())} ({dict(ended)})")


if __name__ == "__main__":
    main()
