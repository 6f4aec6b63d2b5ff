"""Two navigation runs on the same episodes, pair by pair: successes and at-fault collisions (one-sided exact McNemar
tests both ways), and how the episodes that only the first completes ended for the second.

    python -m st_sim leaderboard --paired results/benchmark/ppo-reactive-singular results/benchmark/mpc-singular \\
        --scenarios '*-reactive'
    python -m st_sim leaderboard --paired CELL_A.json CELL_B.json         # two `navigate --json` results

A run is a ``python -m st_sim benchmark`` output folder (``summary.json``, or the committed ``summary.json.gz``),
whose episodes are pooled over its scenarios (``scenarios`` keeps those matching any of the glob patterns), or the
JSON of a ``navigate`` run (a cell of ``benchmarks/nav_table.py``). Both runs must hold the same episodes.
"""

from __future__ import annotations

import fnmatch
import json
import os
from collections import Counter
from pathlib import Path

from st_sim.apps.navigation.leaderboard import LeaderboardError, load_result
from st_sim.apps.navigation.metrics import RATES, paired_collision_test, paired_success_test


def paired_episodes(path: str | os.PathLike, patterns: tuple[str, ...] = ("*",)) -> list[dict]:
    """The episodes of a run, each keyed for pairing by its ``seed`` (with its scenario, in a benchmark run)."""
    path = Path(path)
    if path.is_file():
        try:
            return json.loads(path.read_text())["episodes"]
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as err:
            raise LeaderboardError(f"{path}: not the JSON of a navigate run (no episodes: {err})") from err
    episodes = [{**episode, "seed": (scenario["name"], episode["seed"])} for scenario in load_result(path)["scenarios"]
                if any(fnmatch.fnmatch(scenario["name"], pattern) for pattern in patterns)
                for episode in scenario["episodes"]]
    if not episodes:
        raise LeaderboardError(f"{path}: no scenario matches {' '.join(patterns)}")
    return episodes


def paired_text(first: str | os.PathLike, second: str | os.PathLike, patterns: tuple[str, ...] = ("*",)) -> str:
    """The paired comparison of two runs as lines of text (``LeaderboardError`` if they hold different episodes)."""
    a, b = paired_episodes(first, patterns), paired_episodes(second, patterns)
    if [e["seed"] for e in a] != [e["seed"] for e in b]:
        raise LeaderboardError(f"{first} and {second} hold different episodes (scenarios or seeds); pair runs of one "
                               "suite version, split and size, or cells of the same seeds")
    success = paired_success_test(a, b)
    fault = paired_collision_test(a, b, at_fault=True)
    at_fault = RATES["collision_at_fault"]
    ended = Counter(f"{e['outcome']}{', at fault' if at_fault(e) else ''}" for first_e, e in zip(a, b, strict=True)
                    if RATES["success"](first_e) and not RATES["success"](e))
    return "\n".join([
        f"{first} against {second}: {len(a)} paired episodes",
        f"successes: {success['a_successes']} vs {success['b_successes']} (only the first {success['only_a']}, only "
        f"the second {success['only_b']}); more for the first p = {success['p_value']:.2g}, for the second p = "
        f"{paired_success_test(b, a)['p_value']:.2g}",
        f"at-fault collisions: {fault['a_collisions']} vs {fault['b_collisions']} (only the first {fault['only_a']}, "
        f"only the second {fault['only_b']}); fewer for the first p = {fault['p_value']:.2g}, for the second p = "
        f"{paired_collision_test(b, a, at_fault=True)['p_value']:.2g}",
        f"the first completes, the second does not: {sum(ended.values())} ({dict(ended)})"])
