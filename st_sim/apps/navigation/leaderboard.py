"""Benchmark results side by side: one markdown table per metric group, the success of every scenario, a chart.

    python -m st_sim leaderboard runs/bench/mine [runs/bench/other ...] [--out board.md] [--chart board.png]

Each folder is a ``benchmark`` output (its ``summary.json``). The shipped planners' results on the same suite
version and split (``results/benchmark/`` in the repository) join the table unless ``--no-baselines``: a new run
is compared with them at once. Results measured on other episodes (another suite, version, split or episode count)
are refused, since their figures do not compare.
"""

from __future__ import annotations

import gzip
import json
import os
from pathlib import Path
from typing import Any

from st_sim.apps.navigation.benchmark import RESULT_FORMAT
from st_sim.apps.navigation.metrics import GROUPS, METRICS
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
    folder, checked to be one (``LeaderboardError`` otherwise)."""
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
    return result


def baseline_results(like: dict[str, Any], folder: Path = BASELINES_DIR) -> list[dict[str, Any]]:
    """The committed results in ``folder`` measured on the same episodes as ``like`` (none without the folder)."""
    if not folder.is_dir():
        return []
    found = [load_result(path) for path in sorted(folder.iterdir()) if path.is_dir()]
    return [result for result in found if all(result[key] == like[key] for key in SAME_EPISODES)]


def label(result: dict[str, Any]) -> str:
    """How a result is named in tables: its policy, and the predictor in the env unless none."""
    return result["policy"] if result["predictor"] == "none" else f"{result['policy']} + {result['predictor']}"


def check_comparable(results: list[dict[str, Any]]) -> None:
    """Refuse results measured on different episodes, or two of the same name (``LeaderboardError``)."""
    first = results[0]
    for result in results[1:]:
        differ = [f"{key} {first[key]!r} vs {result[key]!r}" for key in SAME_EPISODES if result[key] != first[key]]
        if differ:
            raise LeaderboardError(f"{label(first)} and {label(result)} were measured on different episodes "
                                   f"({', '.join(differ)}); compare results of one suite version, split and size")
    names = [label(result) for result in results]
    if len(set(names)) < len(names):
        raise LeaderboardError(f"two results are both {max(names, key=names.count)!r}; give each folder once")


def markdown(results: list[dict[str, Any]]) -> str:
    """One table per metric group (pooled over every episode of each result), then success and at-fault collisions
    per scenario."""
    check_comparable(results)
    first = results[0]
    lines = [f"Suite {first['suite']} {first['suite_version']}, {first['split']} seeds, "
             f"{first['episodes_per_scenario']} episodes per scenario; every cell: value [95 % interval], pooled "
             "over every episode of the suite.", ""]
    for group in GROUPS:
        names = [name for name, metric in METRICS.items() if metric.group == group
                 and any(result["summary"].get(name, {}).get("n") for result in results)]
        lines += [f"### {GROUP_TITLES[group]}", "", "| policy | " + " | ".join(map(metric_label, names)) + " |",
                  "|---|" + "---|" * len(names)]
        lines += ["| " + label(result) + " | " + " | ".join(_cell(result["summary"].get(name)) for name in names)
                  + " |" for result in results]
        lines.append("")
    scenarios = [scenario["name"] for scenario in first["scenarios"]]
    for metric, title in (("success", "Success per scenario"),
                          ("collision_at_fault", "Collisions at fault per scenario")):
        lines += [f"### {title}", "", "| policy | " + " | ".join(scenarios) + " |", "|---|" + "---|" * len(scenarios)]
        for result in results:
            by_name = {scenario["name"]: scenario["summary"] for scenario in result["scenarios"]}
            lines.append("| " + label(result) + " | " + " | ".join(
                f"{by_name[name][metric]['value']:.2f}" if name in by_name else "-" for name in scenarios) + " |")
        lines.append("")
    return "\n".join(lines)


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
