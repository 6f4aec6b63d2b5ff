"""Benchmark results side by side: one markdown table per metric group, the success of every scenario, a chart.

    python -m st_sim leaderboard runs/bench/mine [runs/bench/other ...] [--out board.md] [--chart board.png]

Each folder is a ``benchmark`` output (its ``summary.json``). The shipped planners' results on the same episodes
(``results/benchmark/`` in the repository: the whole suite's test seeds, 100 episodes per scenario) join the table
unless ``--no-baselines``: a new run is compared with them at once; when they cannot join, the table says why and
how to get them. Results measured on other episodes (another suite, version, split or episode count) are refused,
since their figures do not compare; so are results over different scenario sets, unless ``--common-scenarios``
pools every result over the scenarios they share (and the header says so).
"""

from __future__ import annotations

import gzip
import json
import os
from pathlib import Path
from typing import Any

from st_sim.apps.navigation.benchmark import RESULT_FORMAT, json_value
from st_sim.apps.navigation.metrics import GROUPS, METRICS, Outcome, summarize
from st_sim.apps.navigation.report import metric_label

BASELINES_DIR = Path(__file__).resolve().parents[3] / "results" / "benchmark"
"""the shipped planners' committed results, one folder each holding ``summary.json.gz`` (a clone of the repository
has them)"""
SAME_EPISODES = ("suite", "suite_version", "split", "episodes_per_scenario")
GROUP_TITLES = {"safety": "Safety", "efficiency": "Efficiency", "comfort": "Comfort and social"}


class LeaderboardError(ValueError):
    """A folder holds no benchmark result, or results that were measured on other episodes."""


def load_result(folder: str | os.PathLike) -> dict[str, Any]:
    """The ``summary.json`` (or gzipped ``summary.json.gz``, as the committed results are kept) of a benchmark output
    folder, checked to be one (``LeaderboardError`` otherwise). A summary written before runs recorded their scenario
    set gets ``scenario_set`` and ``suite_scenarios`` from its scenarios."""
    path = Path(folder) / "summary.json"
    if not path.is_file() and path.with_suffix(".json.gz").is_file():
        path = path.with_suffix(".json.gz")
    try:
        text = gzip.decompress(path.read_bytes()).decode() if path.suffix == ".gz" else path.read_text()
        result = json.loads(text)
    except FileNotFoundError:
        raise LeaderboardError(f"{folder}: no summary.json (run `python -m st_sim benchmark --out {folder}` "
                               "first; an interrupted run writes it when resumed to the end)") from None
    except (OSError, EOFError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise LeaderboardError(f"{path}: not a readable benchmark summary ({err})") from err
    if not isinstance(result, dict) or result.get("format") != RESULT_FORMAT:
        raise LeaderboardError(f"{path}: not a benchmark summary (expected format {RESULT_FORMAT})")
    result.setdefault("scenario_set", [scenario["name"] for scenario in result["scenarios"]])
    result.setdefault("suite_scenarios", len(result["scenario_set"]))
    return result


def baseline_results(like: dict[str, Any], folder: Path = BASELINES_DIR,
                     common_scenarios: bool = False) -> tuple[list[dict[str, Any]], str | None]:
    """The committed results in ``folder`` that can stand beside ``like``: measured on the same episodes, over the
    same scenarios (or any, with ``common_scenarios``). Returns them and, when none can, a sentence that says why
    and how to get them."""
    if not folder.is_dir():
        return [], f"the shipped planners' results are not here ({folder} is missing: a clone of the repository has it)"
    found = [load_result(path) for path in sorted(folder.iterdir()) if path.is_dir()]
    same = [result for result in found if all(result[key] == like[key] for key in SAME_EPISODES)]
    if not same:
        kept = found[0] if found else None
        measured = "" if kept is None else (f" (they were measured on the {kept['split']} seeds, "
                                            f"{kept['episodes_per_scenario']} episodes per scenario, suite "
                                            f"{kept['suite']} {kept['suite_version']})")
        return [], (f"the shipped planners are left out: no committed result was measured on the episodes of this "
                    f"run, {like['split']} seeds with {like['episodes_per_scenario']} per scenario{measured}. To see "
                    "them beside it, run the benchmark on those settings (`--suite test`, default episodes), or run a "
                    "shipped planner on this run's settings (`python -m st_sim benchmark --policy mpc --suite "
                    f"{like['split']} --episodes {like['episodes_per_scenario']} --out DIR`) and list its folder")
    if common_scenarios:
        return same, None
    fitting = [result for result in same if result["scenario_set"] == like["scenario_set"]]
    if fitting:
        return fitting, None
    return [], (f"the shipped planners are left out: they ran {len(same[0]['scenario_set'])} scenarios, this run "
                f"{len(like['scenario_set'])}; add --common-scenarios to pool them all over the scenarios they share")


def label(result: dict[str, Any]) -> str:
    """How a result is named in tables: its policy, and the predictor in the env unless none."""
    return result["policy"] if result["predictor"] == "none" else f"{result['policy']} + {result['predictor']}"


def check_comparable(results: list[dict[str, Any]], common_scenarios: bool = False) -> None:
    """Refuse results measured on different episodes, over different scenario sets (unless ``common_scenarios``),
    or two of the same name (``LeaderboardError``)."""
    first = results[0]
    for result in results[1:]:
        differ = [f"{key} {first[key]!r} vs {result[key]!r}" for key in SAME_EPISODES if result[key] != first[key]]
        if differ:
            raise LeaderboardError(f"{label(first)} and {label(result)} were measured on different episodes "
                                   f"({', '.join(differ)}); compare results of one suite version, split and size")
        if not common_scenarios and result["scenario_set"] != first["scenario_set"]:
            raise LeaderboardError(
                f"{label(first)} ran {len(first['scenario_set'])} scenarios, {label(result)} "
                f"{len(result['scenario_set'])}: their pooled figures do not compare. Pass --common-scenarios to pool "
                f"every result over the {len(shared_scenarios([first, result]))} scenarios they share")
    names = [label(result) for result in results]
    if len(set(names)) < len(names):
        raise LeaderboardError(f"two results are both {max(names, key=names.count)!r}; give each folder once")


def shared_scenarios(results: list[dict[str, Any]]) -> list[str]:
    """The scenarios every result ran, in the first result's order."""
    return [name for name in results[0]["scenario_set"] if all(name in result["scenario_set"] for result in results)]


def restricted(result: dict[str, Any], names: list[str]) -> dict[str, Any]:
    """``result`` kept to the scenarios ``names``, its pooled summary computed again over their episodes."""
    kept = [scenario for scenario in result["scenarios"] if scenario["name"] in names]
    episodes = [{k: float("nan") if v is None else v for k, v in e.items()} for s in kept for e in s["episodes"]]
    summary = {name: {k: json_value(v) for k, v in cell.items()} for name, cell in summarize(episodes).items()}
    return {**result, "scenarios": kept, "scenario_set": [s["name"] for s in kept], "summary": summary}


def comparable(results: list[dict[str, Any]], common_scenarios: bool = False) -> list[dict[str, Any]]:
    """``results`` checked to compare (``check_comparable``); with ``common_scenarios`` each kept to the scenarios
    they all share and pooled again over them (``LeaderboardError`` if they share none)."""
    check_comparable(results, common_scenarios)
    if not common_scenarios:
        return results
    names = shared_scenarios(results)
    if not names:
        raise LeaderboardError("the results share no scenario: nothing to compare")
    return [result if result["scenario_set"] == names else restricted(result, names) for result in results]


def markdown(results: list[dict[str, Any]], note: str | None = None) -> str:
    """One table per metric group (pooled over the episodes of each result's scenarios), then outcomes, success and
    at-fault collisions per scenario; ``results`` of one scenario set (``comparable``). ``note``: a sentence under
    the header (why the shipped planners are absent)."""
    check_comparable(results)
    first = results[0]
    count, total = len(first["scenario_set"]), first["suite_scenarios"]
    if count == total:
        pooled = f"pooled over every episode of the suite's {total} scenarios"
    else:
        pooled = (f"pooled over the episodes of the {count} scenarios every result holds, of the suite's {total} "
                  f"({', '.join(first['scenario_set'])})")
    lines = [f"Suite {first['suite']} {first['suite_version']}, {first['split']} seeds, "
             f"{first['episodes_per_scenario']} episodes per scenario; every cell: value [95 % interval], {pooled}.",
             ""]
    if note:
        lines += [f"Note: {note}.", ""]
    for group in GROUPS:
        names = [name for name, metric in METRICS.items() if metric.group == group
                 and any(result["summary"].get(name, {}).get("n") for result in results)]
        lines += [f"### {GROUP_TITLES[group]}", "", "| policy | " + " | ".join(map(metric_label, names)) + " |",
                  "|---|" + "---|" * len(names)]
        lines += ["| " + label(result) + " | " + " | ".join(_cell(result["summary"].get(name)) for name in names)
                  + " |" for result in results]
        lines.append("")
    lines += _per_scenario(results, "Outcomes per scenario (shares of goal / pedestrian collision / wall collision / "
                                    "timeout)", _outcomes)
    for metric, title in (("success", "Success per scenario"),
                          ("collision_at_fault", "Collisions at fault per scenario")):
        lines += _per_scenario(results, title, lambda scenario, metric=metric:
                               f"{scenario['summary'][metric]['value']:.2f}")
    return "\n".join(lines)


def _per_scenario(results: list[dict[str, Any]], title: str, cell: Any) -> list[str]:
    """A table of one row per result and one column per scenario, each cell ``cell(scenario entry)``."""
    scenarios = results[0]["scenario_set"]
    lines = [f"### {title}", "", "| policy | " + " | ".join(scenarios) + " |", "|---|" + "---|" * len(scenarios)]
    for result in results:
        by_name = {scenario["name"]: scenario for scenario in result["scenarios"]}
        lines.append("| " + label(result) + " | " + " | ".join(
            cell(by_name[name]) if name in by_name else "-" for name in scenarios) + " |")
    return [*lines, ""]


def _outcomes(scenario: dict[str, Any]) -> str:
    """``goal / pedestrian / wall / timeout`` shares of a scenario's episodes."""
    episodes = scenario["episodes"]
    shares = [sum(e["outcome"] == outcome.value for e in episodes) / max(len(episodes), 1) for outcome in Outcome]
    return " / ".join(f"{share:.2f}" for share in shares)


def _cell(cell: dict[str, Any] | None) -> str:
    if not cell or cell.get("value") is None:
        return "-"
    value, low, high = (cell.get(key) for key in ("value", "low", "high"))
    digits = 3 if abs(value) < 10 else 1
    if low is None or high is None:
        return f"{value:.{digits}f}"
    return f"{value:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def chart(results: list[dict[str, Any]], path: str | os.PathLike) -> Path:
    """Success against at-fault collisions, every result a labelled point with its 95 % intervals; a PNG."""
    from st_sim.charts import ScatterPoint, interval_scatter, save_figure

    points = []
    for result in results:
        x, y = result["summary"]["collision_at_fault"], result["summary"]["success"]
        points.append(ScatterPoint(label(result), x["value"], y["value"], (x["low"], x["high"]),
                                   (y["low"], y["high"])))
    first = results[0]
    figure = interval_scatter("collisions at fault (share of episodes)", "success (share of episodes)",
                              {f"{first['suite']} {first['suite_version']}, {first['split']} seeds, "
                               f"{first['episodes_per_scenario']} episodes per scenario": points})
    return save_figure(figure, path)
