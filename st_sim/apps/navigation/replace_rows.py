"""Replace some scenarios of a committed benchmark result with a run of exactly those scenarios, after a change that
changed their episodes on purpose (the crowd's arithmetic made the same on every CPU, say).

    python -m st_sim benchmark --policy orca --predictor none --scenarios sim-crossing group --out runs/regen/orca
    python -m st_sim.apps.navigation.replace_rows results/benchmark/orca-none runs/regen/orca

The new run must be of the same policy, predictor, suite (name, version and content), benchmark version, split and
size; each scenario it holds replaces the committed one, whose other scenarios stay as they are. The pooled figures
and timing are computed again over the scenarios (``wall_s``: the two runs' wall times summed). The result's code
identity (``CODE_IDENTITY``: what the policy, the predictor and STCrowd were) stays the one its other scenarios ran
on; ``scenario_identity`` maps each scenario re-run to the code identity and the machines (``ran_on``) of the run
that made its episodes, so the summary says which code every scenario ran on (``identity_of``). ``ran_on`` lists
the machines of both runs, and ``migrated`` says which scenarios were re-run when.

    identity_of(load_result("results/benchmark/orca-none"), "sim-crossing")["stcrowd"]   # the code it ran on
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from replays.bounded_json import read_json
from st_sim.apps.navigation.benchmark import RAN_ON, SCENARIO_IDENTITY, summary_of
from st_sim.apps.navigation.leaderboard import SAME_EPISODES
from st_sim.apps.navigation.migrate_results import MigrationError, summary_path, write_summary
from st_sim.apps.navigation.result_folder import CODE_IDENTITY, INPUTS, load_result

SAME_RUN = ("policy", "predictor", *SAME_EPISODES)
"""what the committed result and the new run must share"""
def replace_rows(folder: Path, new_folder: Path) -> str:
    """Replace the scenarios of the result in ``folder`` that ``new_folder``'s run holds; returns what was done
    (``MigrationError`` if the runs differ in ``SAME_RUN``, the new one holds a scenario the old one lacks or does not
    record its code identity)."""
    path = summary_path(folder)
    load_result(folder)  # the committed result is checked as any folder is
    old, new = read_json(path, "benchmark summary"), load_result(new_folder)
    differ = [f"{key} {old.get(key)!r} there, {new[key]!r} in {new_folder}" for key in SAME_RUN
              if old.get(key) != new[key]]
    if differ:
        raise MigrationError(f"{path}: another run than {new_folder}'s ({'; '.join(differ)})")
    unrecorded = [key for key in CODE_IDENTITY if key not in new] + ([] if new.get(RAN_ON) else [RAN_ON])
    if unrecorded:
        raise MigrationError(f"{new_folder}: its summary records no {', '.join(unrecorded)}: which code made its "
                             "episodes is unknown")
    by_name = {entry["name"]: entry for entry in new["scenarios"]}
    unknown = sorted(set(by_name) - set(old["scenario_set"]))
    if unknown:
        raise MigrationError(f"{path}: holds no scenario {unknown[0]!r} to replace")
    scenarios = [by_name.get(entry["name"], entry) for entry in old["scenarios"]]
    every = [episode for entry in scenarios for episode in entry["episodes"]]
    timing = {"wall_s": old["timing"]["wall_s"] + new["timing"]["wall_s"],  # both invocations that made it
              **{key: sum(entry["timing"][key] for entry in scenarios) for key in ("worker_s", "policy_s", "steps")}}
    own = {key: new[key] for key in (*CODE_IDENTITY, RAN_ON, INPUTS) if key in new}
    # a new run itself replaced in part keeps its parts'
    identities = {**old.get(SCENARIO_IDENTITY, {}), **{name: new.get(SCENARIO_IDENTITY, {}).get(name, own)
                                                       for name in by_name}}
    note = (f"scenarios {', '.join(by_name)} re-run by replace_rows on STCrowd {new['stcrowd']['source_sha256'][:12]} "
            f"(commit {new[RAN_ON][-1]['commit'][:12]})")
    merged: dict[str, Any] = {**old, "scenarios": scenarios, "summary": summary_of(every), "timing": timing,
                              RAN_ON: old.get(RAN_ON, []) + [r for r in new[RAN_ON] if r not in old.get(RAN_ON, [])],
                              SCENARIO_IDENTITY: {name: identities[name] for name in old["scenario_set"]
                                                  if name in identities},
                              "migrated": "; ".join(filter(None, [old.get("migrated"), note]))}
    write_summary(path, merged)
    return f"{path}: {len(by_name)} scenarios replaced from {new_folder}"


def main(argv: list[str] | None = None) -> int:
    """Replace the rows of one committed result; exit code 0, or 1 with one line saying why not."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder", type=Path, metavar="DIR", help="the committed benchmark result")
    parser.add_argument("new", type=Path, metavar="NEW", help="a run of some of its scenarios")
    args = parser.parse_args(argv)
    try:
        print(replace_rows(args.folder, args.new))
    except ValueError as err:  # MigrationError, LeaderboardError, the reader's errors
        print(f"error: {err}")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
