"""``python -m st_sim episode``: one episode of a finished benchmark run again, checked against its line, optionally
recorded for Rerun; ``python -m st_sim verify``: a sample of a run's episodes again, each checked the same way (is
this machine's STCrowd the one that made the figures?).

    python -m st_sim episode runs/bench/mine univ-reactive 17 --rerun univ-reactive-17.rrd
    python -m st_sim episode results/benchmark/mpc-singular univ-reactive 17 --spawn     # a committed result
    python -m st_sim verify results/benchmark/orca-none --per-scenario 2                  # the first 2 of each scenario

The episode comes from the run's ``summary.json`` (or ``summary.json.gz``): the scenario's env and keywords
(``scenarios[].env``, ``env_kwargs``), the episode's seed (``scenarios[].episodes[]``), the policy and the predictor.
A results folder is data from someone else, so nothing it names runs unless the user names it too: the env must be
one of STCrowd's registered ids and its keywords pass the suite's allow-list (``envs.suite.check_scenario``: no
path, no module), the policy is taken from the folder only if it is a shipped planner or a peer by name, and the
predictor only if it is a shipped one by name; any other (``package.module:name``, ``sb3:PATH``) must be given on the
command line (``--policy``, ``--predictor``), which is refused otherwise, saying how.

The episode runs as the benchmark ran it (one thread, the policy built the same way), its figures are printed, and
each must equal the episode's line in the summary, as JSON writes it: a figure that differs is an error naming it (the
code, the policy or the data changed since the run), so a recording made here shows exactly the episode the numbers
came from. The recording is ``episode_recording.EpisodeTape``'s.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from envs.suite import SuiteError, check_scenario
from replays import strict_json
from replays.data_root import data_root as resolve_data_root
from st_sim.apps.grid import one_thread
from st_sim.apps.navigation.policies import SB3_PREFIX, TRUST_HELP
from st_sim.apps.navigation.predictors import predictor_argument
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
    _add_specs(replay)
    replay.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    return replay


def add_verify_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register the ``verify`` subcommand."""
    verify = subparsers.add_parser("verify", help="re-run the first episodes of every scenario of finished benchmark "
                                                  "runs and compare each with its line (does this machine reproduce "
                                                  "them?)")
    verify.add_argument("folders", nargs="+", metavar="DIR", help="benchmark output folders (results/benchmark/...)")
    verify.add_argument("--per-scenario", type=int, default=1, metavar="K",
                        help="episodes re-run per scenario, the first K (default: 1)")
    verify.add_argument("--scenarios", nargs="+", default=["*"], metavar="PATTERN",
                        help="only the scenarios matching these glob patterns (default: all)")
    _add_specs(verify)
    verify.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    verify.add_argument("--quiet", action="store_true", help="no progress bar (for logs)")
    return verify


def _add_specs(parser: argparse.ArgumentParser) -> None:
    """The options naming the code a run used, which a results folder never names itself."""
    parser.add_argument("--policy", default=None, metavar="SPEC",
                        help="the policy to run, when the run's is not a shipped planner by name (a results folder "
                             "never names code to run: give package.module:name or sb3:PATH.zip yourself)")
    parser.add_argument("--predictor", type=predictor_argument, default=None, metavar="SPEC",
                        help="the predictor, when the run's is a plug-in package.module:name (given yourself)")
    parser.add_argument("--trust-policy-file", action="store_true", help=TRUST_HELP)


def chosen_specs(summary: dict[str, Any], folder: str | os.PathLike, policy: str | None,
                 predictor: str | None) -> tuple[str, str]:
    """(policy, predictor) to replay a run with: each the user's if given (the run's spec; an ``sb3:`` model's path
    may differ), else the run's if it is shipped by name (``planners.NAMED``, ``predictors.NAMES``); ``CliError``
    naming the run's spec and the flag to give otherwise."""
    from st_sim.apps.navigation.planners import NAMED
    from st_sim.apps.navigation.predictors import NAMES

    for flag, given, ran in (("--policy", policy, summary["policy"]), ("--predictor", predictor, summary["predictor"])):
        if given is not None and given != ran and not (given.startswith(SB3_PREFIX) and ran.startswith(SB3_PREFIX)):
            raise CliError(f"{folder}: {flag} {given}: the run's is {ran!r} (an sb3: model may lie elsewhere, its "
                           "bytes are checked)")
    if policy is None:
        policy = summary["policy"]
        if policy not in NAMED:
            raise CliError(f"{folder}: the run's policy {policy!r} is not a shipped planner, and a results folder "
                           "names no code to run: if you trust it, give it yourself with --policy SPEC")
    if predictor is None:
        predictor = summary["predictor"]
        if predictor not in NAMES:
            raise CliError(f"{folder}: the run's predictor {predictor!r} is not a shipped one, and a results folder "
                           "names no code to run: if you trust it, give it yourself with --predictor SPEC")
    return policy, predictor


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
    """The figures of two episode lines that differ as JSON writes them, one phrase each ("min_step_end_gap_m: 0.41 in
    the run, 0.43 now"); a figure present on one side only counts too."""
    found = []
    for key in sorted(set(expected) | set(measured)):
        was, now = expected.get(key, NO_FIGURE), measured.get(key, NO_FIGURE)
        if _shown(was) != _shown(now):
            found.append(f"{key}: {_shown(was)} in the run, {_shown(now)} now")
    return found


def _shown(value: Any) -> str:
    return "absent" if value is NO_FIGURE else strict_json.dumps(value)


def read_run(folder: str | os.PathLike) -> dict[str, Any]:
    """The checked summary of the benchmark run in ``folder`` (``result_folder.load_result``); ``CliError`` if it
    holds none or a malformed one."""
    from st_sim.apps.navigation.result_folder import LeaderboardError, load_result

    try:
        return load_result(folder)
    except LeaderboardError as err:
        raise CliError(str(err)) from None


def replay_episode(folder: str | os.PathLike, scenario: str, episode: int, rerun: str | None = None,
                   data_root: str | None = None, policy: str | None = None, predictor: str | None = None,
                   trust_policy_file: bool = False, summary: dict[str, Any] | None = None,
                   check_identity: bool = True, notes: set[str] | None = None
                   ) -> tuple[dict[str, Any], dict[str, Any], Path | None]:
    """Run episode ``episode`` of ``scenario`` of the benchmark run in ``folder`` again.

    Args:
        rerun: a .rrd path or "spawn" to record it (None: no recording).
        summary: the run's summary, already read (``read_run``; None: read it from ``folder``).
        policy, predictor: specs given by the user (None: the run's, if shipped by name; ``chosen_specs``).
        trust_policy_file: load an ``sb3:`` policy with stable-baselines3's own loader.
        check_identity: a policy or predictor given by the user must be what the run identified (``fingerprint``:
            its code, the files it read, what it declares), else ``CliError`` naming what changed; the shipped ones
            are STCrowd's code, which the figures themselves check. Other package versions than the run's are not
            refused (the figures say whether they matter, as for the run's read files): each is a phrase added to
            ``notes``, or printed to stderr when ``notes`` is None.

    Returns:
        (the episode's line in the run, the line measured now, as ``episodes.jsonl`` writes them; the recording's
        file, None without one or for a viewer).

    Raises:
        CliError: the folder holds no benchmark result, or not that scenario or episode, or names an env, keyword,
            policy or predictor that it may not (see the module docstring).
    """
    import gymnasium as gym

    from st_sim.apps.navigation.benchmark import episode_record
    from st_sim.apps.navigation.episode_recording import EpisodeTape
    from st_sim.apps.navigation.episodes import run_episode
    from st_sim.apps.navigation.fingerprint import (
        ReadAudit,
        fingerprint_changes,
        policy_fingerprint,
        predictor_fingerprint,
    )
    from st_sim.apps.navigation.leaderboard import label
    from st_sim.apps.navigation.metrics import episode_metrics
    from st_sim.apps.navigation.planners import NAMED
    from st_sim.apps.navigation.policies import load_policy
    from st_sim.apps.navigation.predictors import NAMES
    from st_sim.apps.navigation.result_folder import identity_of
    from st_sim.apps.navigation.world import world_of
    from st_sim.perception import SENSING_LEVELS
    from st_sim.sim.robot import ROBOTS

    summary = read_run(folder) if summary is None else summary
    entry, expected = find_episode(summary, folder, scenario, episode)
    policy, predictor = chosen_specs(summary, folder, policy, predictor)
    kwargs = dict(entry["env_kwargs"])
    if kwargs.pop("predictor", summary["predictor"]) != summary["predictor"]:
        raise CliError(f"{folder}: scenario {scenario}: its env_kwargs name another predictor than the run's "
                       f"{summary['predictor']!r}")
    try:
        check_scenario(entry["env"], kwargs, f"{folder}: scenario {scenario}")
    except SuiteError as err:
        raise CliError(str(err)) from None
    robot, sensing = summary.get("robot", "holonomic"), summary.get("sensing", "oracle")
    if robot not in ROBOTS or sensing not in SENSING_LEVELS:
        raise CliError(f"{folder}: robot {robot!r}, sensing {sensing!r}: expected one of {', '.join(ROBOTS)} and one "
                       f"of {', '.join(SENSING_LEVELS)}")
    kwargs |= ({"predictor": predictor, "robot": robot, "sensing": sensing}
               | ({} if data_root is None else {"root": data_root}))
    outside = [folder, resolve_data_root(data_root, check=False)]
    with ReadAudit(outside) as predictor_audit:
        env = gym.make(entry["env"], **kwargs)
    try:
        world = world_of(env)
        with ReadAudit(outside) as policy_audit:
            checked = load_policy(policy, world, predictor, trust_file=trust_policy_file)
            tape = None if rerun is None else EpisodeTape(env, forecasts=predictor != "none")
            trace, _ = run_episode(tape or env, checked, world, expected["seed"])
        measured = episode_record(scenario, episode, expected["seed"], episode_metrics(trace))
        path = None if tape is None else tape.write(rerun, measured, label(summary))
    finally:
        env.close()
    if check_identity:
        changed, identity = [], identity_of(summary, scenario)  # a scenario re-run by replace_rows: its run's
        if policy not in NAMED:
            changed += fingerprint_changes(identity["fingerprint"],
                                           policy_fingerprint(policy, checked.policy, policy_audit))
        if predictor not in NAMES:
            changed += fingerprint_changes(identity["predictor_fingerprint"],
                                           predictor_fingerprint(predictor, predictor_audit))
        refused = [change for change in changed if not change.startswith("version ")]
        if refused:
            raise CliError(f"{folder}: the policy or predictor given is not the one the run identified: "
                           f"{'; '.join(refused)}")
        versions = {f"{folder}: the policy's or predictor's {change}" for change in changed if change not in refused}
        if notes is not None:
            notes |= versions
        for note in sorted(versions) if notes is None else ():
            print(note, file=sys.stderr)
    return expected, measured, path


def run_verify(args: argparse.Namespace) -> int:
    """Replay the first ``--per-scenario`` episodes of every matching scenario of each folder (one thread), print one
    line per scenario; exit code 0 if every figure of every episode equals the run's, else 1 (the lines name them).
    A run of the user's own policy or predictor (``--policy``, ``--predictor``) must be what the run identified: the
    first replay of each scenario is audited as the benchmark audits its run (``fingerprint``; a scenario re-run by
    ``replace_rows`` has its own), and any part that differs is an error naming it; so is a file or module that the
    run's episodes read (its ``inputs``) and that is not the same here (other package versions, in either, are named
    once each, not refused: the figures say whether they matter).
    Patterns that match no scenario of a folder are an error, not a pass."""
    import fnmatch

    from tqdm import tqdm

    from st_sim.apps.navigation.fingerprint import inputs_changes
    from st_sim.apps.navigation.result_folder import identity_of

    if args.per_scenario < 1:
        raise CliError(f"--per-scenario {args.per_scenario}: give 1 or more")
    one_thread()
    differing = replayed = 0
    notes: set[str] = set()
    for folder in args.folders:
        summary = read_run(folder)  # read and checked once, not once per episode
        names = [entry["name"] for entry in summary["scenarios"]
                 if any(fnmatch.fnmatch(entry["name"], pattern) for pattern in args.scenarios)]
        if not names:
            raise CliError(f"{folder}: --scenarios {' '.join(args.scenarios)} matches none of the run's scenarios "
                           f"({', '.join(entry['name'] for entry in summary['scenarios'])})")
        read = {part: value for name in names for part, value in identity_of(summary, name).get("inputs", {}).items()}
        changed = inputs_changes(read)
        files = [change for change in changed if not change.startswith("version ")]
        if files:
            raise CliError(f"{folder}: files the run's episodes read are not the same here: {'; '.join(files)}")
        if changed:
            tqdm.write(f"{folder}: other versions here than where it ran ({'; '.join(changed)}); the episodes tell "
                       "whether they matter")
        for name in tqdm(names, desc=str(folder), unit="scenario", leave=False, disable=args.quiet):
            episodes = [line["episode"] for line in find_episode(summary, folder, name, 0)[0]["episodes"]]
            wrong = {}
            for episode in episodes[:args.per_scenario]:
                before = set(notes)
                expected, measured, _ = replay_episode(
                    folder, name, episode, data_root=args.data_root, policy=args.policy, predictor=args.predictor,
                    trust_policy_file=args.trust_policy_file, summary=summary, check_identity=episode == episodes[0],
                    notes=notes)
                for note in sorted(notes - before):
                    tqdm.write(f"{note}; the episodes tell whether it matters")
                replayed += 1
                found = differences(expected, measured)
                if found:
                    wrong[episode] = found
            differing += len(wrong)
            shown = "; ".join(f"episode {episode}: {', '.join(found)}" for episode, found in wrong.items())
            tqdm.write(f"{folder} {name}: {min(args.per_scenario, len(episodes)) - len(wrong)} of "
                       f"{min(args.per_scenario, len(episodes))} episodes reproduce" + (f" ({shown})" if wrong else ""))
    if differing:
        raise CliError(f"{differing} of {replayed} episodes do not reproduce: this machine's STCrowd, its packages or "
                       "the data differ from the run's (compare its ran_on records: docs, Reproducing a result)")
    print(f"every episode re-run equals its line ({replayed} episodes)")
    return 0


def run(args: argparse.Namespace) -> int:
    """Replay the episode (with one thread, as the benchmark's jobs run), print its figures, fail naming every figure
    that differs from the run's; exit code 0."""
    if args.rerun and args.spawn:
        raise CliError("give --rerun OUT.rrd or --spawn, not both")
    one_thread()
    target = "spawn" if args.spawn else args.rerun
    expected, measured, path = replay_episode(args.folder, args.scenario, args.episode, target, args.data_root,
                                              args.policy, args.predictor, args.trust_policy_file)
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
