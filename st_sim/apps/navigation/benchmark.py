"""The navigation benchmark: one policy through a suite's scenarios on its published seeds, every metric per episode.

    python -m st_sim benchmark --policy mypkg.policy:MyPolicy --suite test --out runs/bench/mine
    python -m st_sim leaderboard runs/bench/mine

Episode i of every scenario resets with the split's i-th seed, so every policy meets the same episodes and results
compare pair by pair. The work is cut into chunks of ``CHUNK_EPISODES`` episodes of one scenario, run on a process
pool or a Ray cluster (``st_sim.apps.grid``). A chunk appends one JSON line per finished episode to its part file,
so a run that is killed keeps every finished episode, and the same command resumes it.

Layout of the output folder:
    run.json                            the run's identity (``RUN_IDENTITY``): what was asked, the suite's content
                                        hash, the benchmark version, STCrowd's version and source hash, whether the
                                        data's sums were waived (``STCROWD_ALLOW_MODIFIED_DATA``), and what the
                                        policy and the predictor are (``fingerprint``: their code, every file they
                                        read while loading and during the first episode); a resume whose identity
                                        differs in any part is refused, naming it. Beside it ``ran_on``, a record of
                                        each machine that ran part of the run (``provenance``), not compared
    parts/<scenario>/<first>.jsonl      one chunk's episodes, appended as they finish
    parts/<scenario>/<first>.inputs.json what the chunk's episodes read, in every process that ran them
                                        (``fingerprint.ChunkInputs``), grown before each episode's line is written;
                                        a resume is refused when any of it changed since, naming it
    parts/<scenario>/<first>.json       the chunk's timing, written when it is complete
    recordings/<scenario>/<episode>.rrd a Rerun recording of each episode ``--record`` chose (``episode_recording``)
    episodes.jsonl                      every episode, one JSON line each, in suite order
    summary.json                        the identity, the inputs of every episode (``inputs``), the scenario set; per
                                        scenario its env, keywords, episodes, summary and timing; the pooled summary
                                        and timing (``RESULT_FORMAT``); one line per top-level key

Timing, in ``summary.json``: ``wall_s`` is the run's wall-clock time (the invocation that finished it, resumed parts
not included), ``worker_s`` the chunks' wall times summed over the workers (with two workers about twice
``wall_s``), ``policy_s`` the time spent in the policy's ``act``, ``steps`` the env steps; a scenario's timing holds
the last three over its chunks.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from envs.suite import Scenario, Suite, env_kwargs_of, load_suite, make_scenario_env
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.bounded_json import read_json
from replays.data_root import ALLOW_MODIFIED_ENV_VAR
from replays.data_root import data_root as resolve_data_root
from replays.errors import DataFormatError
from st_sim.apps.grid import Job, run_jobs
from st_sim.apps.navigation.episode_recording import BenchmarkRecorder
from st_sim.apps.navigation.episodes import run_episode
from st_sim.apps.navigation.fingerprint import (
    ChunkInputs,
    ReadAudit,
    fingerprint_changes,
    inputs_changes,
    policy_fingerprint,
    predictor_fingerprint,
    read_inputs,
    stcrowd_identity,
)
from st_sim.apps.navigation.metrics import episode_metrics, summarize
from st_sim.apps.navigation.policies import FIXED_VIEW_HINT, SB3_PREFIX, PolicyError, load_policy, observation_fits
from st_sim.apps.navigation.provenance import machine_record
from st_sim.apps.navigation.world import world_of

CHUNK_EPISODES = 25  # episodes of one scenario per grid job [-]
SIGNIFICANT_DIGITS = 6  # figures are written with this many significant digits [-]
RESULT_FORMAT = "stcrowd-nav-benchmark/1"
BENCHMARK_VERSION = "4"
"""the version of what the metrics mean (docs: Benchmark your policy, "Versions"): 1, the suite as published on
2026-11-27; 2, from 2026-11-28, a pedestrian collision at the robot's fault when the robot closed the gap; 3, from
2026-11-29, when the robot was moving and not hit from behind (``envs.common.fault``), peers tuned on val; 4, from
2026-12-02, one robot model in every scenario (``st_sim.sim.robot``: the replays' robot gained the simulated crowds'
acceleration limit, a differential-drive track beside the holonomic one). Bumped
whenever a metric changes meaning; results of different versions are never tabled or paired together"""
RUN_IDENTITY = ("policy", "fingerprint", "predictor", "predictor_fingerprint", "trust_policy_file", "robot", "sensing",
                "modified_data_allowed", "suite",
                "suite_version", "suite_sha256", "benchmark_version", "stcrowd", "split", "scenarios", "episodes")
"""what must match for a rerun to resume the runs already in an output folder"""
RAN_ON = "ran_on"
"""the key of ``run.json`` and ``summary.json`` listing the machines that ran the run (``provenance``)"""
SCENARIO_IDENTITY = "scenario_identity"
"""the key of ``summary.json`` mapping each scenario re-run by ``replace_rows`` to the code identity and machines it
ran on (the others ran on the summary's own)"""
FINGERPRINTS = ("fingerprint", "predictor_fingerprint", "stcrowd")
"""identity parts that are dicts of named parts, compared part by part"""


class BenchmarkError(RuntimeError):
    """A benchmark run cannot go on (a failed chunk, a folder holding another run); the message says what to do."""


@dataclass(frozen=True)
class BenchmarkRun:
    """What to run: a policy with a predictor in the env, on a suite's split."""

    policy: str
    """a policy spec (``policies``): a shipped planner, package.module:name, or sb3:PATH.zip"""
    out: str
    """output folder"""
    predictor: str = "singular"
    """the envs' predictor (``none``: no forecasts, the fastest for a policy that does not read them)"""
    split: str = "test"
    """seed list: val (tuning) or test (reported figures)"""
    episodes: int | None = None
    """episodes per scenario (None: the suite's default)"""
    scenarios: tuple[str, ...] | None = None
    """scenario names to run (None: all)"""
    suite_file: str | None = None
    """a suite file (None: the shipped suite)"""
    data_root: str | None = None
    """ETH/UCY data root for the replays (default: $STCROWD_DATA or the cache); not part of the results"""
    record: str = "none"
    """Rerun recordings of the episodes run now: none, failures (not at the goal) or all; not part of the results"""
    trust_policy_file: bool = False
    """load an sb3: model with stable-baselines3's own loader, which runs code stored in the file (``policies``); not
    part of the results"""
    robot: str = "holonomic"
    """the robot of every scenario, by kind (``st_sim.sim.robot.ROBOTS``: its documented default limits)"""
    sensing: str = "oracle"
    """what the robot senses in every scenario, by level (``st_sim.perception.SENSING_LEVELS``)"""


@dataclass(frozen=True)
class RunPlan:
    """A run resolved once (``plan_run``): its suite, the scenarios it runs in suite order and the seeds of its
    split's first episodes, which every later step (the checks, the chunks, the summary) reads instead of the suite."""

    suite: Suite
    scenarios: tuple[Scenario, ...]
    seeds: tuple[int, ...]


def plan_run(run: BenchmarkRun) -> RunPlan:
    """Load ``run``'s suite and resolve its scenarios and seeds (``SuiteError`` naming an unknown scenario, split or
    episode count)."""
    suite = load_suite(run.suite_file)
    return RunPlan(suite, suite.select(run.scenarios), tuple(suite.seeds_of(run.split, run.episodes)))


def json_value(value: Any) -> Any:
    """``value`` as plain JSON: NumPy scalars as Python numbers, floats to ``SIGNIFICANT_DIGITS``, NaN and inf as
    null."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return float(f"{value:.{SIGNIFICANT_DIGITS}g}") if math.isfinite(value) else None
    return value


def episode_record(scenario: str, episode: int, seed: int, metrics: dict[str, Any]) -> dict[str, Any]:
    """One line of ``episodes.jsonl``: scenario, episode index, seed, then every metric of ``episode_metrics``."""
    return {"scenario": scenario, "episode": episode, "seed": seed,
            **{key: json_value(value) for key, value in metrics.items()}}


def run_chunk(scenario: Scenario, first: int, seeds: list[int], policy: str, predictor: str, part: str,
              data_root: str | None = None, record: str = "none", trust_policy_file: bool = False,
              robot: str = "holonomic", sensing: str = "oracle") -> None:
    """Grid job: episodes ``first .. first + len(seeds) - 1`` of ``scenario`` (the plan's, ``plan_run``), from
    ``seeds``, appended to ``part`` (.jsonl) one line each as they finish; then the chunk's timing into ``part`` with
    suffix .json. Episodes already in ``part`` are kept and skipped (a torn last line, from a killed run, is
    dropped). ``record`` chooses the episodes recorded into ``recordings/<scenario>/`` beside ``parts``
    (``episode_recording.BenchmarkRecorder``). The policy is built here, once per chunk, not once per process: what a
    policy carries from one episode to the next then depends on the chunk alone, not on which process ran which.

    Raises:
        PolicyError: the policy failed; the message names it, the scenario, the episode and the seed.
    """
    name = scenario.name
    lines_path = Path(part)
    lines_path.parent.mkdir(parents=True, exist_ok=True)
    done = _finished_lines(lines_path, {first + i: seed for i, seed in enumerate(seeds)})
    start, policy_s, steps = time.perf_counter(), 0.0, 0
    inputs = ChunkInputs(lines_path.with_suffix(".inputs.json"))
    with ReadAudit([lines_path.parents[2], resolve_data_root(data_root, check=False)]) as audit:
        env = make_scenario_env(scenario, predictor, data_root, robot=robot, sensing=sensing)
        try:
            world = world_of(env)
            checked = load_policy(policy, world, predictor, trust_file=trust_policy_file)
            checked.check_fits(env.observation_space, name)
            recorder = BenchmarkRecorder(env, record, lines_path.parents[2] / "recordings" / name, policy,
                                         predictor)
            with lines_path.open("a") as lines:
                for i, seed in enumerate(seeds, start=first):
                    if i in done:
                        continue
                    try:
                        trace, thinking_s = run_episode(recorder.env, checked, world, seed)
                    except PolicyError as err:
                        raise PolicyError(f"{err} (scenario {name!r}, episode {i}, seed {seed})") from err
                    policy_s += thinking_s
                    steps += len(trace.ego_xy_m) - 1
                    inputs.keep(audit)  # before the line: a line on disk never lacks the inputs it read
                    line = episode_record(name, i, seed, episode_metrics(trace))
                    recorder.keep(line)
                    lines.write(strict_json.dumps(line) + "\n")
                    lines.flush()
                    os.fsync(lines.fileno())
        finally:
            env.close()
    inputs.keep(audit)
    timing = {"episodes": len(seeds) - len(done), "steps": steps, "worker_s": time.perf_counter() - start,
              "policy_s": policy_s}
    write_text_atomic(lines_path.with_suffix(".json"), strict_json.dumps(timing))


def _finished_lines(path: Path, seeds: dict[int, int]) -> set[int]:
    """Episode indices already in ``path`` (only lines that parse and name an episode of ``seeds`` with its seed);
    the file is rewritten without any other line (a torn last line of a killed run)."""
    if not path.is_file():
        return set()
    kept, done = [], set()
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
            episode = record["episode"]
            if seeds.get(episode) != record["seed"] or episode in done:
                continue
        except (json.JSONDecodeError, KeyError, TypeError):
            continue
        kept.append(line)
        done.add(episode)
    write_text_atomic(path, "".join(f"{line}\n" for line in kept))
    return done


def plan(run: BenchmarkRun, planned: RunPlan) -> list[Job]:
    """The grid jobs of ``run``: one per chunk of ``CHUNK_EPISODES`` episodes of each planned scenario, each carrying
    its scenario and seeds (a worker loads no suite)."""
    out = Path(run.out).resolve()
    data_root = None if run.data_root is None else str(Path(run.data_root).resolve())
    jobs = []
    for scenario in planned.scenarios:
        for first in range(0, len(planned.seeds), CHUNK_EPISODES):
            part = out / "parts" / scenario.name / f"{first:05d}.jsonl"
            kwargs = {"scenario": scenario, "first": first,
                      "seeds": list(planned.seeds[first:first + CHUNK_EPISODES]), "policy": _portable(run.policy),
                      "predictor": run.predictor,
                      "part": str(part), "data_root": data_root, "record": run.record,
                      "trust_policy_file": run.trust_policy_file, "robot": run.robot, "sensing": run.sensing}
            jobs.append(Job(f"{scenario.name}/{first}", "st_sim.apps.navigation.benchmark:run_chunk", kwargs,
                            str(part.with_suffix(".json"))))
    return jobs


def _portable(policy: str) -> str:
    """``policy`` as a worker elsewhere reads it: an ``sb3:`` model's path made absolute (the results keep the spec as
    given)."""
    if policy.startswith(SB3_PREFIX):
        return SB3_PREFIX + str(Path(policy.removeprefix(SB3_PREFIX)).expanduser().resolve())
    return policy


def check_run(run: BenchmarkRun, planned: RunPlan) -> dict[str, Any]:
    """Every check that can fail before any episode: the split, episodes and scenarios exist, the policy builds, a
    policy that declares its observation space fits every scenario's env (else ``PolicyError`` naming the scenarios
    that fit, if any), and the output folder holds no other run (``BenchmarkError`` naming each part of the identity
    that differs). Returns the run's identity (``run.json``): the policy and the predictor are identified by what
    they read while the first scenario's env is made, the policy built and the first episode run (``ReadAudit``)."""
    suite, scenarios, seeds = planned.suite, planned.scenarios, planned.seeds
    outside = [run.out, resolve_data_root(run.data_root, check=False)]  # the envs' data: checked by its sums
    with ReadAudit(outside) as predictor_audit:
        env = make_scenario_env(scenarios[0], run.predictor, run.data_root, robot=run.robot, sensing=run.sensing)
    try:
        world = world_of(env)
        with ReadAudit(outside) as policy_audit:
            policy = load_policy(run.policy, world, run.predictor, trust_file=run.trust_policy_file)
            if policy.observation_space is None or observation_fits(policy.observation_space, env.observation_space):
                try:
                    run_episode(env, policy, world, seeds[0])
                except PolicyError as err:
                    raise PolicyError(f"{err} (scenario {scenarios[0].name!r}, episode 0, seed {seeds[0]})") from err
    finally:
        env.close()
    if policy.observation_space is not None:
        _check_fits(policy.spec, policy.observation_space, scenarios, suite, run.data_root, run.robot)
    identity = _identity(run, planned, policy_fingerprint(run.policy, policy.policy, policy_audit),
                         predictor_fingerprint(run.predictor, predictor_audit))
    marker = Path(run.out) / "run.json"
    if marker.is_file():
        held = {key: value for key, value in _held_run(marker).items() if key != RAN_ON}
        if held != identity:
            raise BenchmarkError(f"{run.out} holds another run ({'; '.join(_differences(held, identity))}): give "
                                 "another --out, or delete the folder to score this one there")
    return identity


def _check_fits(spec: str, own: spaces.Space, scenarios: tuple[Scenario, ...], suite: Suite,
                data_root: str | None, robot: str = "holonomic") -> None:
    """Refuse a policy whose observation space does not fit every asked scenario: ``PolicyError`` naming the first
    that does not and the suite's scenarios that fit (or saying none does, and why)."""
    env_spaces = {}
    for scenario in suite.scenarios:
        env = make_scenario_env(scenario, "none", data_root, robot=robot)
        env_spaces[scenario.name] = env.observation_space
        env.close()
    misfits = [scenario.name for scenario in scenarios if not observation_fits(own, env_spaces[scenario.name])]
    if not misfits:
        return
    fitting = [name for name, space in env_spaces.items() if observation_fits(own, space)]
    where = (f"It fits {', '.join(fitting)}: run it there with --scenarios {' '.join(fitting)}" if fitting else
             "It fits none of the suite's scenarios (their pedestrian slots or keys differ from its own)")
    more = f" (nor {len(misfits) - 1} more)" if len(misfits) > 1 else ""
    raise PolicyError(
        f"policy {spec!r} does not fit scenario {misfits[0]!r}{more}: it reads observations of {own}, the scenario's "
        f"env gives {env_spaces[misfits[0]]}. {where}; or {FIXED_VIEW_HINT}")


def _held_run(marker: Path) -> dict[str, Any]:
    """An output folder's ``run.json``: its identity and ``ran_on`` records (``BenchmarkError`` naming the file if it
    is not what a run writes)."""
    try:
        held = read_json(marker, "run identity")
    except DataFormatError as err:
        raise BenchmarkError(f"{err}: delete the folder, or give another --out") from None
    if not isinstance(held, dict) or not isinstance(held.get(RAN_ON, []), list) or \
            not all(isinstance(record, dict) for record in held.get(RAN_ON, [])):
        raise BenchmarkError(f"{marker}: not a run's identity with a list of machine records ({RAN_ON}): delete the "
                             "folder, or give another --out")
    return held


def _differences(held: dict[str, Any], identity: dict[str, Any]) -> list[str]:
    """What differs between a folder's ``run.json`` and this run's identity, in words."""
    missing = [key for key in RUN_IDENTITY if key not in held]
    if missing:
        return [f"it was written before runs recorded {', '.join(missing)}"]
    differ = [f"{key} {held[key]!r} there, {identity[key]!r} now" for key in RUN_IDENTITY
              if key not in FINGERPRINTS and held[key] != identity[key]]
    whose = {"fingerprint": f"policy {identity['policy']!r}", "predictor_fingerprint":
             f"predictor {identity['predictor']!r}", "stcrowd": "STCrowd's version, code or data"}
    for key in FINGERPRINTS:
        changes = fingerprint_changes(held[key], identity[key])
        if changes:
            differ.append(f"{whose[key]} changed: {', '.join(changes)}")
    return differ


def _identity(run: BenchmarkRun, planned: RunPlan, fingerprint: dict[str, str],
              predictor_parts: dict[str, str]) -> dict[str, Any]:
    suite = planned.suite
    return {"policy": run.policy, "fingerprint": fingerprint, "predictor": run.predictor,
            "predictor_fingerprint": predictor_parts, "trust_policy_file": run.trust_policy_file, "robot": run.robot,
            "sensing": run.sensing, "modified_data_allowed": os.environ.get(ALLOW_MODIFIED_ENV_VAR) == "1",
            "suite": suite.name, "suite_version": suite.version, "suite_sha256": suite.content_sha256,
            "benchmark_version": BENCHMARK_VERSION, "stcrowd": stcrowd_identity(), "split": run.split,
            "scenarios": [scenario.name for scenario in planned.scenarios], "episodes": len(planned.seeds)}


def run_benchmark(run: BenchmarkRun, executor: str = "local", workers: int | None = None,
                  address: str | None = None, progress: bool = True) -> dict[str, Any]:
    """Run what is missing of ``run`` and write ``episodes.jsonl`` and ``summary.json``; returns the summary.

    ``workers=1`` with the local executor runs the chunks in this process (a policy's error then surfaces as
    itself); otherwise on a process pool of ``workers`` (default: one per core) or on Ray.
    """
    start = time.perf_counter()
    planned = plan_run(run)
    identity = check_run(run, planned)
    out = Path(run.out)
    for record in sorted(out.glob("parts/*/*.inputs.json")):
        changes = inputs_changes(read_inputs(record))
        if changes:
            raise BenchmarkError(f"{out} holds episodes whose inputs changed since they ran "
                                 f"({record.relative_to(out)}: {'; '.join(changes)}): give another --out, or delete "
                                 "the folder to score this run there")
    marker = out / "run.json"
    ran_on = _held_run(marker).get(RAN_ON, []) if marker.is_file() else []
    ran_on += [machine_record()] if machine_record() not in ran_on else []
    write_text_atomic(marker, strict_json.dumps({**identity, RAN_ON: ran_on}, indent=1))
    jobs = plan(run, planned)
    if executor == "local" and workers == 1:
        from tqdm import tqdm

        for job in tqdm([job for job in jobs if not job.done()], desc="benchmark", unit="chunk", disable=not progress):
            run_chunk(**job.kwargs)
    else:
        reports = run_jobs(jobs, executor=executor, workers=workers, address=address, progress=progress,
                           desc="benchmark chunks")
        failed = [report for report in reports if report.status == "failed"]
        if failed:
            raise BenchmarkError(f"{len(failed)} of {len(jobs)} chunks failed; the first, {failed[0].name}: "
                                 f"{failed[0].error}. Finished episodes are kept in {out}/parts: fix the cause and "
                                 "run the same command again to resume")
    return collect(run, planned, jobs, {**identity, RAN_ON: ran_on}, time.perf_counter() - start)


def collect(run: BenchmarkRun, planned: RunPlan, jobs: list[Job], identity: dict[str, Any],
            wall_s: float) -> dict[str, Any]:
    """Gather the chunks of a finished run into ``episodes.jsonl`` and ``summary.json``; returns the summary.
    ``identity`` is the run's (``check_run``) with its ``ran_on`` records, ``wall_s`` the run's wall-clock time [s]."""
    by_scenario: dict[str, list[dict]] = {}
    timing: dict[str, dict[str, float]] = {}
    inputs: dict[str, str] = {}
    for job in jobs:
        name = job.kwargs["scenario"].name
        part = Path(job.kwargs["part"])
        read = read_inputs(part.with_suffix(".inputs.json"))
        differ = sorted(key for key, value in read.items() if inputs.setdefault(key, value) != value)
        if differ:
            raise BenchmarkError(f"{', '.join(differ)}: one value in some chunks, another in {part}: an input changed "
                                 "during the run; delete the folder and run again")
        by_scenario.setdefault(name, []).extend(json.loads(line) for line in part.read_text().splitlines())
        spent = json.loads(part.with_suffix(".json").read_text())
        cell = timing.setdefault(name, {"worker_s": 0.0, "policy_s": 0.0, "steps": 0})
        for key in cell:
            cell[key] += spent[key]
    scenarios, every = [], []
    for scenario in planned.scenarios:
        episodes = sorted(by_scenario[scenario.name], key=lambda e: e["episode"])
        every += episodes
        scenarios.append({"name": scenario.name, "env": scenario.env,
                          "env_kwargs": env_kwargs_of(scenario, run.predictor), "description": scenario.description,
                          "episodes": [{k: v for k, v in e.items() if k != "scenario"} for e in episodes],
                          "summary": summary_of(episodes), "timing": timing[scenario.name]})
    summary = {"format": RESULT_FORMAT, **{k: v for k, v in identity.items() if k not in ("episodes", "scenarios")},
               "inputs": dict(sorted(inputs.items())),
               "episodes_per_scenario": identity["episodes"], "scenario_set": identity["scenarios"],
               "suite_scenarios": len(planned.suite.scenarios),
               "scenarios": scenarios, "summary": summary_of(every),
               "timing": {"wall_s": wall_s, **{key: sum(cell[key] for cell in timing.values())
                                               for key in ("worker_s", "policy_s", "steps")}}}
    out = Path(run.out)
    write_text_atomic(out / "episodes.jsonl", "".join(strict_json.dumps(e) + "\n" for e in every))
    write_text_atomic(out / "summary.json", summary_text(summary))
    return summary


def summary_text(summary: dict[str, Any]) -> str:
    """``summary.json``'s text: strict JSON, one line per top-level key."""
    return "{\n" + ",\n".join(f"{strict_json.dumps(key)}: {strict_json.dumps(value, separators=(',', ':'))}"
                               for key, value in summary.items()) + "\n}\n"


def summary_of(episodes: list[dict]) -> dict[str, dict[str, Any]]:
    """``summarize`` of JSON episode records (null read back as NaN), with NaN written as null: the figures a summary
    holds, as the leaderboard computes them again from the episodes."""
    restored = [{k: float("nan") if v is None else v for k, v in e.items()} for e in episodes]
    return {name: {k: json_value(v) for k, v in cell.items()} for name, cell in summarize(restored).items()}

