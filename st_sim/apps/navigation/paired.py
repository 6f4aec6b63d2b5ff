"""Two navigation runs on the same episodes, pair by pair: successes and at-fault collisions (one-sided exact McNemar
tests both ways), and how the episodes that only the first completes ended for the second.

    python -m st_sim leaderboard --paired results/benchmark/ppo-reactive-singular results/benchmark/mpc-singular \\
        --scenarios '*-reactive'
    python -m st_sim leaderboard --paired CELL_A.json CELL_B.json         # two `navigate --json` results

A run is a ``python -m st_sim benchmark`` output folder (``summary.json``, or the committed ``summary.json.gz``,
read and checked by ``result_folder.load_result``), whose episodes are pooled over its scenarios (``scenarios`` keeps
those matching any of the glob patterns), or the JSON of a ``navigate`` run (a cell of ``benchmarks/nav_table.py``;
read within ``replays.bounded_json``'s caps, its episodes checked as a benchmark's). Both runs must hold the same
episodes; two benchmark runs also the same version of the metrics and suite content (``PAIRED_SAME``).
"""

from __future__ import annotations

import fnmatch
import os
from collections import Counter
from pathlib import Path
from typing import Any

from replays.bounded_json import read_json
from replays.errors import DataFormatError
from st_sim.apps.navigation.metrics import RATES, paired_collision_test, paired_success_test
from st_sim.apps.navigation.result_folder import (
    EPISODES,
    OBJECT,
    LeaderboardError,
    check,
    check_episode,
    field,
    load_result,
    shell_words,
    shown,
)

PAIRED_SAME = ("benchmark_version", "suite_sha256")
"""what two benchmark runs paired must share besides their scenarios and seeds"""


def navigate_episodes(path: Path) -> list[dict[str, Any]]:
    """The episodes of a ``navigate --json`` file, each keyed for pairing by its ``seed`` (``LeaderboardError`` naming
    the file and the field if it is not such a file)."""
    try:
        run = read_json(path, "navigate --json result")
    except DataFormatError as err:
        raise LeaderboardError(str(err)) from err
    episodes = field(path, check(path, "the file's value", run, OBJECT), "episodes", EPISODES)
    for index, episode in enumerate(episodes):
        check_episode(path, episode, f"episodes[{index}]")
    return episodes


def benchmark_episodes(result: dict[str, Any], patterns: tuple[str, ...], path: Path) -> dict[str, list[dict]]:
    """The episodes of a benchmark result (``load_result``) by scenario, of the scenarios matching ``patterns``, each
    keyed for pairing by its scenario and ``seed``."""
    chosen = {scenario["name"]: [{**episode, "seed": (scenario["name"], episode["seed"])}
                                 for episode in scenario["episodes"]]
              for scenario in result["scenarios"] if any(fnmatch.fnmatch(scenario["name"], p) for p in patterns)}
    if not chosen:
        raise LeaderboardError(f"{path}: no scenario matches {shell_words(*patterns)}")
    return chosen


def paired_runs(first: Path, second: Path, patterns: tuple[str, ...]) -> tuple[list[dict], list[dict]]:
    """The episodes of two runs of one kind, checked to be the same episodes (``LeaderboardError`` naming what
    differs: the metrics' version or suite content, the scenarios, or the seeds)."""
    if first.is_file() != second.is_file():
        raise LeaderboardError(f"{first} and {second}: a benchmark folder and a navigate --json file hold different "
                               "episodes; pair two runs of one kind")
    if first.is_file():
        a, b = navigate_episodes(first), navigate_episodes(second)
        if [e["seed"] for e in a] != [e["seed"] for e in b]:
            raise LeaderboardError(f"{first} and {second} hold different seeds; pair cells run on the same seeds")
        return a, b
    one, two = load_result(first), load_result(second)
    differ = [f"{key} {one[key]!r} vs {two[key]!r}" for key in PAIRED_SAME if one[key] != two[key]]
    if differ:
        raise LeaderboardError(f"{first} and {second} were not measured alike ({'; '.join(differ)}): pair runs of one "
                               "version of the metrics and one suite content")
    a, b = benchmark_episodes(one, patterns, first), benchmark_episodes(two, patterns, second)
    if set(a) != set(b):
        shared = [name for name in a if name in b]
        suggest = (f"pair them over the {len(shared)} they share: --scenarios {shell_words(*shared)}" if shared else
                   "they share none")
        raise LeaderboardError(
            f"{first} and {second} ran different scenarios (only the first: "
            f"{', '.join(shown(n) for n in a if n not in b) or 'none'}; only the second: "
            f"{', '.join(shown(n) for n in b if n not in a) or 'none'}); {suggest}")
    other = next((name for name in a if [e["seed"] for e in a[name]] != [e["seed"] for e in b[name]]), None)
    if other is not None:
        raise LeaderboardError(f"{first} and {second} hold different seeds in scenario {shown(other)} "
                               f"({shown(one['split'])} split, {one['episodes_per_scenario']} episodes vs "
                               f"{shown(two['split'])}, {two['episodes_per_scenario']}); pair runs of one split and "
                               "size")
    return [e for name in a for e in a[name]], [e for name in a for e in b[name]]  # in the first run's order


def paired_text(first: str | os.PathLike, second: str | os.PathLike, patterns: tuple[str, ...] = ("*",)) -> str:
    """The paired comparison of two runs as lines of text (``LeaderboardError`` if they hold different episodes)."""
    a, b = paired_runs(Path(first), Path(second), patterns)
    success = paired_success_test(a, b)
    fault = paired_collision_test(a, b, at_fault=True)
    at_fault = RATES["collision_at_fault"]
    ended = Counter(f"{e['outcome']}{' at fault' if at_fault(e) else ''}" for first_e, e in zip(a, b, strict=True)
                    if RATES["success"](first_e) and not RATES["success"](e))
    return "\n".join([
        f"{first} against {second}: {len(a)} paired episodes",
        f"successes: {success['a_successes']} vs {success['b_successes']} (only the first {success['only_a']}, only "
        f"the second {success['only_b']}); the first's rate minus the second's {_difference(success)}; more for the "
        f"first p = {success['p_value']:.2g}, for the second p = {paired_success_test(b, a)['p_value']:.2g}",
        f"at-fault collisions: {fault['a_collisions']} vs {fault['b_collisions']} (only the first {fault['only_a']}, "
        f"only the second {fault['only_b']}); the first's rate minus the second's {_difference(fault)}; fewer for the "
        f"first p = {fault['p_value']:.2g}, for the second p = "
        f"{paired_collision_test(b, a, at_fault=True)['p_value']:.2g}",
        f"the first completes, the second does not: {sum(ended.values())} "
        f"({', '.join(f'{outcome} {count}' for outcome, count in ended.most_common()) or 'none'})"])


def _difference(test: dict[str, float | int]) -> str:
    """A paired test's difference of rates with its 95 % interval, in words."""
    return f"{test['difference']:+.3f} [95 % interval {test['low']:+.3f}, {test['high']:+.3f}]"
