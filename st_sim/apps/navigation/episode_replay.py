"""``python -m st_sim episode``: one episode of a finished benchmark run again, checked against its line, optionally
recorded for Rerun.

    python -m st_sim episode runs/bench/mine univ-reactive 17 --rerun univ-reactive-17.rrd
    python -m st_sim episode results/benchmark/mpc-singular univ-reactive 17 --spawn     # a committed result

Everything comes from the run's ``summary.json`` (or ``summary.json.gz``): the scenario's env and keywords
(``scenarios[].env``, ``env_kwargs``, the predictor among them), the episode's seed (``scenarios[].episodes[]``), the
policy spec and the predictor. The episode runs as the benchmark ran it (one thread, the policy built the same way),
its figures are printed, and each must equal the episode's line in the summary, as JSON writes it: a figure that
differs is an error naming it (the code, the policy or the data changed since the run), so a recording made here
shows exactly the episode the numbers came from. The recording is ``episode_recording.EpisodeTape``'s.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from replays import strict_json
from st_sim.apps.grid import one_thread
from st_sim.command_line import CliError

NO_FIGURE = object()  # a figure one side of the comparison does not have


def add_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``episode`` subcommand."""
    replay = subparsers.add_parser("episode", help="one episode of a finished benchmark run again, its figures checked "
                                                   "against the run's, optionally recorded for Rerun")
    replay.add_argument("folder", metavar="DIR", help="a benchmark output folder (its summary.json, or summary.json.gz "
                                                      "as the committed results in results/benchmark/ keep it)")
    replay.add_argument("scenario", metavar="SCENARIO", help="the scenario's name (the summary's per-scenario tables)")
    replay.add_argument("episode", metavar="EPISODE", type=int, help="the episode's index in its scenario (0, 1, ...)")
    replay.add_argument("--rerun", default=None, metavar="OUT.rrd", help="write a Rerun recording of the episode here")
    replay.add_argument("--spawn", action="store_true", help="show the episode in a Rerun viewer started now")
    replay.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    return replay


def find_episode(summary: dict[str, Any], folder: str | os.PathLike, scenario: str, episode: int
                 ) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the scenario's entry, the episode's line) of a benchmark summary; ``CliError`` naming what is missing."""
    by_name = {entry["name"]: entry for entry in summary["scenarios"]}
    if scenario not in by_name:
        raise CliError(f"{folder}: the run has no scenario {scenario!r}; it has {', '.join(by_name)}")
    entry = by_name[scenario]
    lines = {line["episode"]: line for line in entry["episodes"]}
    if episode not in lines:
        raise CliError(f"{folder}: scenario {scenario} has no episode {episode}; it has episodes "
                       f"{min(lines)} to {max(lines)}")
    return entry, {"scenario": scenario, **lines[episode]}


def differences(expected: dict[str, Any], measured: dict[str, Any]) -> list[str]:
    """The figures of two episode lines that differ as JSON writes them, one phrase each ("min_distance_m: 0.41 in
    the run, 0.43 now"); a figure present on one side only counts too."""
    found = []
    for key in sorted(set(expected) | set(measured)):
        was, now = expected.get(key, NO_FIGURE), measured.get(key, NO_FIGURE)
        if _shown(was) != _shown(now):
            found.append(f"{key}: {_shown(was)} in the run, {_shown(now)} now")
    return found


def _shown(value: Any) -> str:
    return "absent" if value is NO_FIGURE else strict_json.dumps(value)


def replay_episode(folder: str | os.PathLike, scenario: str, episode: int, rerun: str | None = None,
                   data_root: str | None = None) -> tuple[dict[str, Any], dict[str, Any], Path | None]:
    """Run episode ``episode`` of ``scenario`` of the benchmark run in ``folder`` again.

    Args:
        rerun: a .rrd path or "spawn" to record it (None: no recording).

    Returns:
        (the episode's line in the run, the line measured now, as ``episodes.jsonl`` writes them; the recording's
        file, None without one or for a viewer).

    Raises:
        CliError: the folder holds no benchmark result, or not that scenario or episode.
    """
    import gymnasium as gym

    from st_sim.apps.navigation.benchmark import episode_record
    from st_sim.apps.navigation.episode_recording import EpisodeTape
    from st_sim.apps.navigation.episodes import run_episode
    from st_sim.apps.navigation.leaderboard import LeaderboardError, label, load_result
    from st_sim.apps.navigation.metrics import episode_metrics
    from st_sim.apps.navigation.policies import load_policy
    from st_sim.apps.navigation.world import world_of

    try:
        summary = load_result(folder)
    except LeaderboardError as err:
        raise CliError(str(err)) from None
    entry, expected = find_episode(summary, folder, scenario, episode)
    kwargs = dict(entry["env_kwargs"]) | ({} if data_root is None else {"root": data_root})
    env = gym.make(entry["env"], **kwargs)
    try:
        world = world_of(env)
        policy = load_policy(summary["policy"], world, summary["predictor"])
        tape = None if rerun is None else EpisodeTape(env, forecasts=summary["predictor"] != "none")
        trace, _ = run_episode(tape or env, policy, world, expected["seed"])
        measured = episode_record(scenario, episode, expected["seed"], episode_metrics(trace))
        path = None if tape is None else tape.write(rerun, measured, label(summary))
    finally:
        env.close()
    return expected, measured, path


def run(args: argparse.Namespace) -> int:
    """Replay the episode (with one thread, as the benchmark's jobs run), print its figures, fail naming every figure
    that differs from the run's; exit code 0."""
    if args.rerun and args.spawn:
        raise CliError("give --rerun OUT.rrd or --spawn, not both")
    one_thread()
    target = "spawn" if args.spawn else args.rerun
    expected, measured, path = replay_episode(args.folder, args.scenario, args.episode, target, args.data_root)
    width = max(map(len, measured))
    print("\n".join(f"{key:<{width}}  {_shown(value)}" for key, value in measured.items()))
    if path is not None:
        print(f"wrote {path}")
    wrong = differences(expected, measured)
    if wrong:
        raise CliError(f"episode {args.episode} of {args.scenario} does not reproduce the run in {args.folder}: "
                       + "; ".join(wrong) + " (the code, the policy or the data changed since the run)")
    print(f"every figure equals the run's line for episode {args.episode} of {args.scenario}")
    return 0
