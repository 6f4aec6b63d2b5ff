"""Benchmark results side by side: one markdown table per metric group, the success of every scenario, a chart.

    python -m st_sim leaderboard runs/bench/mine [runs/bench/other ...] [--out board.md] [--chart board.png]

Each folder is a ``benchmark`` output (its ``summary.json``). The shipped planners' results on the same episodes
(``results/benchmark/`` in the repository: the whole suite's test seeds, 100 episodes per scenario) join the table
unless ``--no-baselines``: a new run is compared with them at once; when they cannot join, the table says why and
how to get them. Results measured on other episodes (another suite, suite content, version of the metrics, split or
episode count: ``SAME_EPISODES``; or other seeds in a scenario they share) are refused, since their figures do not
compare; so are results over different scenario sets, unless ``--common-scenarios`` pools every result over the
scenarios they share (and the header says so).

Folders are read as data (``result_folder.load_result``): within caps, every field checked, every figure computed
again from the episodes, every label escaped (``result_folder.shown``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from envs.suite import load_suite
from st_sim.apps.navigation.benchmark import summary_of
from st_sim.apps.navigation.metrics import GROUPS, METRICS, Outcome
from st_sim.apps.navigation.report import metric_label
from st_sim.apps.navigation.result_folder import LeaderboardError, load_result, shell_words, shown

BASELINES_DIR = Path(__file__).resolve().parents[3] / "results" / "benchmark"
"""the shipped planners' committed results on the main track (the holonomic robot, the oracle's eyes), one folder each
holding ``summary.json.gz`` (a clone of the repository has them)"""
TRACKS_DIR = BASELINES_DIR.parent / "benchmark-tracks"
"""the other tracks' committed results: one folder per robot and sensing level (``diff-drive-oracle``,
``holonomic-realistic``, ...), one folder per result in it"""


def committed_folders(folder: Path = BASELINES_DIR) -> list[Path]:
    """The committed result folders of every track: ``folder``'s, then each track's in ``TRACKS_DIR`` beside it."""
    tracks = folder.parent / TRACKS_DIR.name
    folders = sorted(path for path in folder.iterdir() if path.is_dir())
    if tracks.is_dir():
        folders += sorted(path for track in sorted(tracks.iterdir()) if track.is_dir()
                          for path in track.iterdir() if path.is_dir())
    return folders
SAME_EPISODES = ("suite", "suite_version", "suite_sha256", "benchmark_version", "robot", "sensing", "split",
                 "episodes_per_scenario")
"""what results tabled side by side share: the suite's name, version and content (its SHA-256: seeds, scenarios, env
settings), the version of the metrics' definitions, the robot and what it senses (their track), the seed list and the
episodes per scenario"""
GROUP_TITLES = {"safety": "Safety", "efficiency": "Efficiency", "comfort": "Comfort and social",
                "perception": "Perception and forecasts"}


def baseline_results(like: dict[str, Any], folder: Path = BASELINES_DIR,
                     common_scenarios: bool = False) -> tuple[list[dict[str, Any]], str | None]:
    """The committed results in ``folder`` that can stand beside ``like``: measured on the same episodes
    (``SAME_EPISODES``), over the same scenarios (or any, with ``common_scenarios``). Returns them and, when none
    can, a sentence that says why and how to get them."""
    if not folder.is_dir():
        return [], f"the shipped planners' results are not here ({folder} is missing: a clone of the repository has it)"
    same = [result for path in committed_folders(folder)
            if (result := load_result(path, only={key: like[key] for key in SAME_EPISODES})) is not None]
    if not same:
        found = [load_result(path) for path in committed_folders(folder)[:1]]
        measured = "" if not found else " (" + "; ".join(
            f"{key} {shown(str(found[0][key]))} there, {shown(str(like[key]))} here" for key in SAME_EPISODES
            if found[0][key] != like[key]) + ")"
        return [], (f"the shipped planners are left out: no committed result was measured on the episodes of this "
                    f"run{measured}. To see them beside it, run the benchmark on their settings (`--suite test`, "
                    "default episodes, the shipped suite), or run a shipped planner on this run's settings "
                    f"(`{same_settings_command(like)}`) and list its folder")
    if common_scenarios:
        return same, None
    fitting = [result for result in same if result["scenario_set"] == like["scenario_set"]]
    if fitting:
        return fitting, None
    return [], (f"the shipped planners are left out: they ran {len(same[0]['scenario_set'])} scenarios, this run "
                f"{len(like['scenario_set'])}; add --common-scenarios to pool them all over the scenarios they share")


def same_settings_command(like: dict[str, Any], policy: str = "mpc") -> str:
    """The benchmark command that runs ``policy`` on the episodes of the result ``like``: its split, episodes per
    scenario, robot, sensing and (when it ran fewer than the suite's) scenarios; its own suite file, if it had one,
    is the user's to give."""
    words = ["python", "-m", "st_sim", "benchmark", "--policy", policy, "--suite", like["split"], "--episodes",
             str(like["episodes_per_scenario"]), "--robot", like["robot"], "--sensing", like["sensing"]]
    if len(like["scenario_set"]) < like["suite_scenarios"]:
        words += ["--scenarios", *like["scenario_set"]]
    suite_file = "" if like["suite_sha256"] == load_suite(None).content_sha256 else " --suite-file YOUR_SUITE_FILE"
    return shell_words(*words) + suite_file + " --out DIR"


def label(result: dict[str, Any]) -> str:
    """How a result is named in tables and charts (``shown``): its policy and the predictor in the env ("+ none":
    no forecasts)."""
    return f"{shown(result['policy'])} + {shown(result['predictor'])}"


def episodes_line(result: dict[str, Any]) -> str:
    """The episodes a result was measured on, in words (``shown``): suite, version, split, episodes per scenario."""
    return (f"{shown(result['suite'])} {shown(result['suite_version'])}, {shown(result['split'])} seeds, "
            f"{result['episodes_per_scenario']} episodes per scenario, {shown(result['robot'])} robot, "
            f"{shown(result['sensing'])} sensing")


def pooled_line(result: dict[str, Any]) -> str:
    """Which scenarios a result's pooled figures cover, in words: all of the suite's, or how many of them."""
    count, total = len(result["scenario_set"]), result["suite_scenarios"]
    if count == total:
        return f"pooled over every episode of the suite's {total} scenarios"
    return f"pooled over the episodes of the {count} scenarios every result holds, of the suite's {total}"


def check_comparable(results: list[dict[str, Any]], common_scenarios: bool = False) -> None:
    """Refuse results measured on different episodes (``SAME_EPISODES``, or other seeds in a scenario they share),
    over different scenario sets (unless ``common_scenarios``), or two of the same name (``LeaderboardError``)."""
    first = results[0]
    for result in results[1:]:
        differ = [f"{key} {first[key]!r} vs {result[key]!r}" for key in SAME_EPISODES if result[key] != first[key]]
        if differ:
            raise LeaderboardError(f"{label(first)} and {label(result)} were measured on different episodes "
                                   f"({', '.join(differ)}); compare results of one suite (name, version and content), "
                                   "one version of the metrics, split and size")
        if not common_scenarios and result["scenario_set"] != first["scenario_set"]:
            raise LeaderboardError(
                f"{label(first)} ran {len(first['scenario_set'])} scenarios, {label(result)} "
                f"{len(result['scenario_set'])}: their pooled figures do not compare. Pass --common-scenarios to pool "
                f"every result over the {len(shared_scenarios([first, result]))} scenarios they share")
        seeds = {scenario["name"]: [e["seed"] for e in scenario["episodes"]] for scenario in first["scenarios"]}
        other = next((s["name"] for s in result["scenarios"]
                      if s["name"] in seeds and [e["seed"] for e in s["episodes"]] != seeds[s["name"]]), None)
        if other is not None:
            raise LeaderboardError(f"{label(first)} and {label(result)} ran scenario {shown(other)} on different "
                                   "seeds, though their suites' content is the same (suite_sha256): one of them is "
                                   "not what it claims")
    names = [label(result) for result in results]
    if len(set(names)) < len(names):
        raise LeaderboardError(f"two results are both {max(names, key=names.count)!r}; give each folder once")


def shared_scenarios(results: list[dict[str, Any]]) -> list[str]:
    """The scenarios every result ran, in the first result's order."""
    return [name for name in results[0]["scenario_set"] if all(name in result["scenario_set"] for result in results)]


def restricted(result: dict[str, Any], names: list[str]) -> dict[str, Any]:
    """``result`` kept to the scenarios ``names``, its pooled summary computed again over their episodes."""
    kept = [scenario for scenario in result["scenarios"] if scenario["name"] in names]
    return {**result, "scenarios": kept, "scenario_set": [s["name"] for s in kept],
            "summary": summary_of([e for s in kept for e in s["episodes"]])}


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
    pooled = pooled_line(first)
    if len(first["scenario_set"]) < first["suite_scenarios"]:
        pooled += f" ({', '.join(map(shown, first['scenario_set']))})"
    lines = [f"Suite {episodes_line(first)}; every cell: value [95 % interval], {pooled}.", ""]
    if note:
        lines += [f"Note: {note}.", ""]
    for group in GROUPS:
        names = [name for name, metric in METRICS.items() if metric.group == group
                 and any(result["summary"].get(name, {}).get("n") for result in results)]
        if not names:  # no figure of the group exists in any result's episodes
            continue
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


def ran_on_table(results: list[dict[str, Any]]) -> str:
    """A markdown table of where each result ran (``provenance``: its ``ran_on`` records, one row each; a result
    written before runs recorded them gets one row saying so); every value ``shown``."""
    lines = ["### Where they ran", "", "| policy | commit | tree clean | numpy | torch | numba | CPU | SIMD "
             "(numpy / torch / numba) |", "|---|---|---|---|---|---|---|---|"]
    for result in results:
        records = result.get("ran_on")
        if not isinstance(records, list) or not records:
            lines.append(f"| {label(result)} | not recorded (written before runs recorded it) |" + " |" * 6)
            continue
        for record in records:
            versions, simd = (value if isinstance(value := record.get(key), dict) else {}
                              for key in ("versions", "simd"))
            cells = [str(record.get("commit", "?"))[:12], str(record.get("tree_clean", "?")),
                     *(str(versions.get(name, "?")) for name in ("numpy", "torch", "numba")),
                     str(record.get("cpu", "?")), " / ".join(str(simd.get(name, "?"))
                                                             for name in ("numpy", "torch", "numba"))]
            lines.append(f"| {label(result)} | " + " | ".join(shown(cell) for cell in cells) + " |")
    return "\n".join([*lines, ""])


def _per_scenario(results: list[dict[str, Any]], title: str, cell: Any) -> list[str]:
    """A table of one row per result and one column per scenario, each cell ``cell(scenario entry)``."""
    scenarios = results[0]["scenario_set"]
    lines = [f"### {title}", "", "| policy | " + " | ".join(map(shown, scenarios)) + " |",
             "|---|" + "---|" * len(scenarios)]
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
    figure = interval_scatter("collisions at fault (share of episodes)", "success (share of episodes)",
                              {f"{episodes_line(results[0])};\n{pooled_line(results[0])}": points})
    return save_figure(figure, path)
