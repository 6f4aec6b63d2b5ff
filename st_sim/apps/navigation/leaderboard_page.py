"""The figures of the documentation's leaderboard page (``docs/leaderboard.md``) from benchmark results: success
against at-fault collisions per scenario as small multiples, and each policy's worst scenarios with the commands
that record and replay their failures.

    python -m st_sim.apps.navigation.leaderboard_page        # the committed results -> the page's chart and table
    python -m st_sim.apps.navigation.leaderboard_page runs/bench/mine results/benchmark/mpc-singular \\
        --chart scenarios.png --out worst.md

Each folder is a ``benchmark`` output (``summary.json``, or the committed ``summary.json.gz``, read and checked by
``result_folder.load_result``); the results must have been measured on the same episodes
(``leaderboard.check_comparable``). Their labels reach the table and the chart through ``result_folder.shown``, and
the commands' words are quoted for the shell too (``leaderboard.shell_words``).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from replays.atomic import write_text_atomic
from st_sim.apps.navigation.leaderboard import BASELINES_DIR, check_comparable, label
from st_sim.apps.navigation.metrics import RATES
from st_sim.apps.navigation.result_folder import load_result, shell_words, shown

WORST = 3  # scenarios listed per policy [-]
REPO = BASELINES_DIR.parents[1]
CHART = REPO / "docs" / "leaderboard_scenarios.png"
TABLE = BASELINES_DIR / "worst-scenarios.md"


def scenario_chart(results: list[dict[str, Any]], path: str | Path) -> Path:
    """Success against at-fault collisions, one panel per scenario, every result a point with its 95 % intervals;
    a PNG at ``path``."""
    from st_sim.charts import ScatterPoint, save_figure, small_multiples

    check_comparable(results)
    panels: dict[str, list] = {shown(scenario["name"]): [] for scenario in results[0]["scenarios"]}
    for result in results:
        for scenario in result["scenarios"]:
            x, y = scenario["summary"]["collision_at_fault"], scenario["summary"]["success"]
            panels[shown(scenario["name"])].append(ScatterPoint(label(result), x["value"], y["value"],
                                                                (x["low"], x["high"]), (y["low"], y["high"])))
    first = results[0]
    return save_figure(small_multiples(
        "collisions at fault", "success", panels,
        title=f"per scenario: {shown(first['suite'])} {shown(first['suite_version'])}, {shown(first['split'])} "
              f"seeds, {first['episodes_per_scenario']} episodes each; bars: 95 % intervals"), path)


def worst_scenarios(result: dict[str, Any], count: int = WORST) -> list[dict[str, Any]]:
    """The ``count`` scenarios of ``result`` with the lowest success (ties: more at-fault collisions first)."""
    return sorted(result["scenarios"], key=lambda s: (s["summary"]["success"]["value"],
                                                      -s["summary"]["collision_at_fault"]["value"], s["name"]))[:count]


def worst_table(folders: list[Path], results: list[dict[str, Any]], count: int = WORST) -> str:
    """Markdown: per result, its worst scenarios (success, at-fault collisions), the command that records their
    failures and the one that replays the first failure of the worst in a viewer."""
    lines = ["| policy | worst scenarios: success, at fault | record their failures | watch the first |",
             "|---|---|---|---|"]
    for folder, result in zip(folders, results, strict=True):
        worst = worst_scenarios(result, count)
        cells = ", ".join(f"{shown(s['name'])} {s['summary']['success']['value']:.2f}, "
                          f"{s['summary']['collision_at_fault']['value']:.2f}" for s in worst)
        track = [*(["--robot", result["robot"]] if result["robot"] != "holonomic" else []),
                 *(["--sensing", result["sensing"]] if result["sensing"] != "oracle" else [])]
        record = _command("benchmark", "--policy", result["policy"], "--predictor", result["predictor"], *track,
                          "--scenarios", *(s["name"] for s in worst), "--record", "failures", "--out",
                          f"runs/bench/{folder.name}-worst")
        failed = next((line for line in worst[0]["episodes"] if not RATES["success"](line)), None)
        watch = "-" if failed is None else _command("episode", _shown_folder(folder), worst[0]["name"],
                                                    str(failed["episode"]), "--spawn")
        lines.append(f"| {label(result)} | {cells} | {record} | {watch} |")
    return "\n".join(lines) + "\n"


def _command(*words: str) -> str:
    """``python -m st_sim WORDS`` as a markdown code span (``leaderboard.shell_words``)."""
    return f"`{shell_words('python', '-m', 'st_sim', *words)}`"


def _shown_folder(folder: Path) -> str:
    """``folder`` relative to the repository when inside it (as a clone names the committed results)."""
    try:
        return str(folder.resolve().relative_to(REPO))
    except ValueError:
        return str(folder)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="*", type=Path, metavar="DIR",
                        help="benchmark output folders (default: every committed result in results/benchmark/)")
    parser.add_argument("--chart", type=Path, default=CHART, help=f"the small multiples PNG (default: {CHART})")
    parser.add_argument("--out", type=Path, default=TABLE, help=f"the worst-scenarios table (default: {TABLE})")
    args = parser.parse_args(argv)
    folders = args.results or sorted(path for path in BASELINES_DIR.iterdir() if path.is_dir())
    results = [load_result(folder) for folder in folders]
    print(f"wrote {scenario_chart(results, args.chart)}")
    write_text_atomic(args.out, worst_table(folders, results))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
