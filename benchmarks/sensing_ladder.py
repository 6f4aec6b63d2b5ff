"""The sensing ladder: each planner's success and at-fault collisions at every sensing level, the paired tests of
SingularTrajectory against CVM in the MPC at each level, and a chart of both figures against the level.

    python benchmarks/sensing_ladder.py results/benchmark/*/ --chart docs/sensing_ladder.png

Each folder is a ``benchmark`` output (``summary.json`` or the committed ``summary.json.gz``); the results of one
track (robot) and episode set are grouped by planner (policy + predictor) and sensing level. The paired tests are
McNemar's exact tests on the same episodes (``leaderboard --paired``): does the MPC with SingularTrajectory collide at
fault less often than with CVM, and does it reach the goal as often, at each level; and how far each planner falls
from its own oracle row.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from st_sim.apps.navigation.leaderboard import label
from st_sim.apps.navigation.metrics import paired_collision_test, paired_success_test
from st_sim.apps.navigation.result_folder import load_result
from st_sim.perception import SENSING_LEVELS

FIRST, SECOND = "mpc + singular", "mpc + cvm"  # the pair the ladder tests at each level


def episodes(result: dict) -> list[dict]:
    """Every episode of a result, keyed for pairing by scenario and seed."""
    return [{**e, "seed": (s["name"], e["seed"])} for s in result["scenarios"] for e in s["episodes"]]


def cell(result: dict, name: str) -> str:
    figure = result["summary"][name]
    return f"{figure['value']:.3f} [{figure['low']:.3f}, {figure['high']:.3f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path)
    parser.add_argument("--chart", type=Path, default=None, help="also draw success and at fault against the level")
    args = parser.parse_args()
    results = [load_result(folder) for folder in args.results]
    levels = [level for level in SENSING_LEVELS if any(r["sensing"] == level for r in results)]
    planners = sorted({label(r) for r in results}, key=lambda name: (name != FIRST, name != SECOND, name))
    at = {(label(r), r["sensing"]): r for r in results}
    print("| sensing | " + " | ".join(f"{p}: success | {p}: at fault" for p in planners) + " |")
    print("|---|" + "---|---|" * len(planners))
    for level in levels:
        cells = [f"{cell(at[p, level], 'success')} | {cell(at[p, level], 'collision_at_fault')}" if (p, level) in at
                 else "- | -" for p in planners]
        print(f"| {level} | " + " | ".join(cells) + " |")
    print(f"\nPaired tests, {FIRST} against {SECOND} at each level (McNemar, one-sided):\n")
    print("| sensing | at fault: first, second, difference [95 %], p (first fewer) | success: first, second, "
          "difference [95 %], p (first more), p (second more) |")
    print("|---|---|---|")
    for level in levels:
        if (FIRST, level) not in at or (SECOND, level) not in at:
            continue
        a, b = episodes(at[FIRST, level]), episodes(at[SECOND, level])
        fault, success = paired_collision_test(a, b, at_fault=True), paired_success_test(a, b)
        reverse = paired_success_test(b, a)
        print(f"| {level} | {fault['a_collisions']}, {fault['b_collisions']}, {fault['difference']:+.3f} "
              f"[{fault['low']:+.3f}, {fault['high']:+.3f}], p = {fault['p_value']:.2g} | {success['a_successes']}, "
              f"{success['b_successes']}, {success['difference']:+.3f} [{success['low']:+.3f}, {success['high']:+.3f}]"
              f", p = {success['p_value']:.2g}, p = {reverse['p_value']:.2g} |")
    print("\nEach planner against its own oracle row (success: the level minus the oracle [95 %], p (fewer at the "
          "level)):\n")
    for planner in planners:
        if (planner, "oracle") not in at:
            continue
        for level in levels[1:]:
            if (planner, level) in at:
                test = paired_success_test(episodes(at[planner, level]), episodes(at[planner, "oracle"]))
                fewer = paired_success_test(episodes(at[planner, "oracle"]), episodes(at[planner, level]))
                print(f"- {planner}, {level}: {test['difference']:+.3f} [{test['low']:+.3f}, {test['high']:+.3f}], "
                      f"p = {fewer['p_value']:.2g}")
    if args.chart is not None:
        from st_sim.charts import new_figure, save_figure

        figure = new_figure(figsize=(10, 4))
        axes = figure.subplots(1, 2)
        for planner in planners:
            shown = [level for level in levels if (planner, level) in at]
            for ax, name in zip(axes, ("success", "collision_at_fault"), strict=True):
                values = [at[planner, level]["summary"][name] for level in shown]
                x = [levels.index(level) for level in shown]
                ax.errorbar(x, [v["value"] for v in values], yerr=[[v["value"] - v["low"] for v in values],
                                                                   [v["high"] - v["value"] for v in values]],
                            marker="o", capsize=3, label=planner)
        for ax, title in zip(axes, ("success", "collisions at fault"), strict=True):
            ax.set_xticks(range(len(levels)), levels)
            ax.set_xlabel("sensing level")
            ax.set_title(title)
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize="small")
        first = results[0]
        figure.suptitle(f"{first['suite']} {first['suite_version']}, {first['split']} seeds, "
                        f"{first['episodes_per_scenario']} episodes per scenario, {first['robot']} robot; bars: 95 %")
        print(f"\nwrote {save_figure(figure, args.chart)}")


if __name__ == "__main__":
    main()
