"""Give a benchmark summary written before runs recorded them the two fields that decide whether results compare:
the suite's content hash and the benchmark version; or drop from its identity the files a run no longer counts as
inputs.

    python -m st_sim.apps.navigation.migrate_results results/benchmark/* --benchmark-version 2
    python -m st_sim.apps.navigation.migrate_results results/benchmark/* --drop-machine-reads

Nothing is taken on trust: the summary must state the suite's name and version, and each of its scenarios and every
episode's seed must be the suite's (``--suite-file``, default the shipped suite), or it is refused naming the first
that is not; only then is ``suite_sha256`` the suite's content hash. The benchmark version says what the metrics
meant when the run was made (the changelog: docs, "Benchmark your policy", "Versions"); it is the word of whoever
migrates, recorded as such in ``migrated``. ``--drop-machine-reads`` removes the ``read`` parts that name the C
library's files about the machine or this machine's cache of derived data (``fingerprint.not_an_input``), which runs
recorded before they were left out: another machine holds other ones, so a run naming them could not be verified
there. The summary is rewritten in place, atomically (gzipped if it was).
"""

from __future__ import annotations

import argparse
import gzip
from pathlib import Path
from typing import Any

from envs.suite import Suite, load_suite
from replays.atomic import atomic_path
from replays.bounded_json import read_json
from st_sim.apps.navigation.benchmark import BENCHMARK_VERSION, FINGERPRINTS, SCENARIO_IDENTITY, summary_text
from st_sim.apps.navigation.fingerprint import MACHINE_FILES, not_an_input
from st_sim.apps.navigation.result_folder import INPUTS

VERSIONS = tuple(str(version) for version in range(1, int(BENCHMARK_VERSION) + 1))
"""every benchmark version so far"""


class MigrationError(ValueError):
    """A summary that cannot be migrated: it does not match the suite it names; the message says where."""


def summary_path(folder: Path) -> Path:
    """The folder's ``summary.json``, or its ``summary.json.gz``."""
    plain = folder / "summary.json"
    return plain if plain.is_file() or not plain.with_suffix(".json.gz").is_file() else plain.with_suffix(".json.gz")


def write_summary(path: Path, summary: dict[str, Any]) -> None:
    """``summary`` into ``path`` as the benchmark writes it (``summary_text``), gzipped if ``path`` ends in ``.gz``,
    atomically."""
    text = summary_text(summary).encode()
    with atomic_path(path) as tmp:
        tmp.write_bytes(gzip.compress(text, mtime=0) if path.suffix == ".gz" else text)


def check_against_suite(summary: dict[str, Any], suite: Suite, where: str) -> None:
    """Refuse (``MigrationError``) a summary whose suite, scenarios, env settings or episode seeds are not
    ``suite``'s."""
    if (summary.get("suite"), summary.get("suite_version")) != (suite.name, suite.version):
        raise MigrationError(f"{where}: it was measured on suite {summary.get('suite')!r} "
                             f"{summary.get('suite_version')!r}, not {suite.name} {suite.version}")
    seeds = suite.seeds_of(summary["split"], summary["episodes_per_scenario"])
    by_name = {scenario.name: scenario for scenario in suite.scenarios}
    for entry in summary["scenarios"]:
        scenario = by_name.get(entry["name"])
        kwargs = {key: value for key, value in entry["env_kwargs"].items() if key != "predictor"}
        if scenario is None or scenario.env != entry["env"] or dict(scenario.env_kwargs) != kwargs:
            raise MigrationError(f"{where}: scenario {entry['name']!r} ({entry['env']}, {kwargs}) is not the suite's")
        for episode in entry["episodes"]:
            if seeds[episode["episode"]] != episode["seed"]:
                raise MigrationError(f"{where}: episode {episode['episode']} of {entry['name']} has seed "
                                     f"{episode['seed']}, the suite's {summary['split']} seed is "
                                     f"{seeds[episode['episode']]}")


def migrate(folder: Path, version: str, suite: Suite) -> str:
    """Add ``suite_sha256`` and ``benchmark_version`` to the summary in ``folder`` (and ``scenario_set`` and
    ``suite_scenarios`` to one written before runs recorded them); returns what was done."""
    path = summary_path(folder)
    summary = read_json(path, "benchmark summary")
    if "suite_sha256" in summary and "benchmark_version" in summary:
        return f"{path}: already records its suite's content and benchmark version"
    check_against_suite(summary, suite, str(path))
    summary.setdefault("scenario_set", [entry["name"] for entry in summary["scenarios"]])
    summary.setdefault("suite_scenarios", len(suite.scenarios))
    migrated: dict[str, Any] = {}
    for key, value in summary.items():
        migrated[key] = value
        if key == "suite_version":
            migrated |= {"suite_sha256": suite.content_sha256, "benchmark_version": version}
    migrated["migrated"] = (f"suite_sha256 and benchmark_version added by migrate_results: episodes checked against "
                            f"suite {suite.name} {suite.version}; benchmark version {version} as stated by the "
                            "migrating user")
    write_summary(path, migrated)
    return f"{path}: migrated (suite {suite.content_sha256[:12]}..., benchmark version {version})"


def drop_machine_reads(folder: Path) -> str:
    """Remove from the identity of the summary in ``folder`` (its fingerprints and inputs, and those of the
    scenarios ``replace_rows`` re-ran) every part that ``not_an_input``; returns what was done."""
    path = summary_path(folder)
    summary = read_json(path, "benchmark summary")
    identities = summary.get(SCENARIO_IDENTITY, {}) if isinstance(summary, dict) else None
    if not isinstance(identities, dict) or not all(isinstance(record, dict) for record in identities.values()):
        raise MigrationError(f"{path}: not a benchmark summary (an object whose {SCENARIO_IDENTITY}, if any, maps "
                             "scenarios to objects)")
    if not isinstance(summary.get("migrated", ""), str):
        raise MigrationError(f"{path}: 'migrated' is not a string")
    records = [summary, *identities.values()]
    dropped = sorted({part for record in records for key in (*FINGERPRINTS, INPUTS)
                      if isinstance(record.get(key), dict) for part in record[key] if not_an_input(part)})
    if not dropped:
        return f"{path}: names no file a run no longer counts as an input"
    for record in records:
        for key in (*FINGERPRINTS, INPUTS):
            if isinstance(record.get(key), dict):
                record[key] = {part: value for part, value in record[key].items() if not not_an_input(part)}
    machine = [part for part in dropped if part.removeprefix("read ") in MACHINE_FILES]
    cached = len(dropped) - len(machine)  # named by count: their paths are this machine's
    what = ", ".join([*machine, *([f"{cached} file(s) of the derived-data cache"] if cached else [])])
    summary["migrated"] = "; ".join(filter(None, [summary.get("migrated"), f"{what} dropped by migrate_results "
                                                  "--drop-machine-reads (not inputs of a run)"]))
    write_summary(path, summary)
    return f"{path}: dropped {what}"


def main(argv: list[str] | None = None) -> int:
    """Migrate every folder given; exit code 0, or 1 naming the first folder that cannot be."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folders", nargs="+", type=Path, metavar="DIR", help="benchmark output folders")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--benchmark-version", choices=VERSIONS,
                      help="what the metrics meant when the runs were made (the docs' changelog)")
    what.add_argument("--drop-machine-reads", action="store_true",
                      help="drop the files a run no longer counts as inputs (the machine's, the derived-data cache)")
    parser.add_argument("--suite-file", default=None, help="the suite the runs name (default: the shipped one)")
    args = parser.parse_args(argv)
    suite = load_suite(args.suite_file)
    for folder in args.folders:
        try:
            print(drop_machine_reads(folder) if args.drop_machine_reads else
                  migrate(folder, args.benchmark_version, suite))
        except (ValueError, OSError) as err:  # MigrationError, the suite's and the reader's errors
            print(f"error: {folder}: {err}")
            return 1
        except (KeyError, TypeError) as err:
            print(f"error: {folder}: not a benchmark summary (no field {err})")
            return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
