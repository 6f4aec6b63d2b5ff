"""A benchmark results folder read as data from anyone: nothing in it is taken on trust.

    result = load_result("results/benchmark/mpc-singular")    # the checked summary, figures from its episodes

``load_result`` reads the folder's ``summary.json`` (or ``summary.json.gz``) within ``replays.bounded_json``'s caps,
checks every field a reader uses (``LeaderboardError`` naming the file and the field's path: ``summary.json.gz:
scenarios[3].episodes[17].success: expected true/false, got "yes"``), and computes every figure again from the
episodes, refusing a summary whose stored figures differ; the leaderboard, its page, ``--paired``, ``episode`` and
``verify`` read folders through it.

Labels: a summary's strings (policy, predictor, scenario names, suite, version, split) reach markdown, HTML and the
charts only through ``shown``: ASCII letters, digits, space and ``_ . : / + = @ -`` stay as they are, every other
character becomes its numeric character reference ``&#N;``. A browser shows the character; markdown, HTML and
matplotlib's mathtext never read it as syntax (no table pipe, code span, tag, entity, link, ``$`` math or line
break); a chart and a code span show the reference itself.
"""

from __future__ import annotations

import os
import re
import shlex
import string
from collections.abc import Callable
from pathlib import Path
from typing import Any

from replays import strict_json
from replays.bounded_json import MAX_FILE_BYTES, read_json
from replays.errors import DataFormatError
from st_sim.apps.navigation.benchmark import FINGERPRINTS, RESULT_FORMAT, SCENARIO_IDENTITY, summary_of
from st_sim.apps.navigation.metrics import FORMER_NAMES, METRICS, RATES, Outcome
from st_sim.apps.navigation.result_cache import cached, entry_key, store

CODE_IDENTITY = (*FINGERPRINTS, "trust_policy_file")
"""the code a run's episodes came from: the policy's, the predictor's and STCrowd's (a re-run scenario's own in
``scenario_identity``, with the ``inputs`` its episodes read where its run recorded them)"""
INPUTS = "inputs"
"""the key of what a run's episodes read (``fingerprint.ChunkInputs``; runs before 2026-12-02 lack it)"""
RECORDED_SINCE = ("suite_sha256", "benchmark_version")
"""the fields that summaries written before runs recorded them lack (``MIGRATE`` adds them)"""
MIGRATE = "python -m st_sim.apps.navigation.migrate_results"
SAFE_CHARACTERS = frozenset(string.ascii_letters + string.digits + " _.:/+=@-")
"""the characters ``shown`` keeps as they are"""
LONGEST_NAME = 300  # characters of a name in a summary (policy, predictor, suite, scenario, ...) [-]
LARGEST_FIGURE = 1e300  # largest magnitude of a figure in a summary: no sum over its episodes overflows [-]
QUOTED_CHARACTERS = 60  # characters of a refused value an error message quotes [-]
ABSENT = object()
"""the value of a field a summary does not have"""
Kind = tuple[str, Callable[[Any], bool]]
"""what a field holds: its description (for messages) and the test of a value"""


class LeaderboardError(ValueError):
    """A folder holds no benchmark result, a malformed or inconsistent one, or results measured on other episodes."""


def _short_text(value: Any) -> bool:
    return isinstance(value, str) and len(value) <= LONGEST_NAME


def _number(value: Any) -> bool:
    return type(value) in (int, float) and abs(value) <= LARGEST_FIGURE  # not a bool; NaN fails the comparison


NAME: Kind = (f"a string of 1 to {LONGEST_NAME} characters",
              lambda value: isinstance(value, str) and 0 < len(value) <= LONGEST_NAME)
COUNT: Kind = ("a whole number >= 1", lambda value: type(value) is int and value >= 1)
WHOLE: Kind = ("a whole number", lambda value: type(value) is int)
FLAG: Kind = ("true/false", lambda value: isinstance(value, bool))
FIGURE: Kind = ("a number or null", lambda value: value is None or _number(value))
OBJECT: Kind = ("an object", lambda value: isinstance(value, dict))
INPUT_PART: Kind = (f"a string of up to {LONGEST_NAME} characters", lambda value: _short_text(value))
RECORD_LIST: Kind = ("a list of machine records", lambda value: isinstance(value, list))
RECORD_VALUE: Kind = (f"a string of up to {LONGEST_NAME} characters, true/false/null, or an object of such strings",
                      lambda value: value is None or isinstance(value, bool) or _short_text(value) or
                      (isinstance(value, dict) and all(map(_short_text, value.values()))))
NAME_LIST: Kind = ("a list of strings",
                   lambda value: isinstance(value, list) and all(isinstance(item, str) for item in value))
SCENARIOS: Kind = ("a list of at least one scenario", lambda value: isinstance(value, list) and len(value) > 0)
EPISODES: Kind = ("a list of episodes", lambda value: isinstance(value, list))
SHA256: Kind = ("64 lowercase hex digits",
                lambda value: isinstance(value, str) and re.fullmatch(r"[0-9a-f]{64}", value) is not None)
ENV_ID: Kind = ("an env id (Name-vN)", lambda value: isinstance(value, str) and len(value) <= LONGEST_NAME
                and re.fullmatch(r"[A-Za-z][A-Za-z0-9_-]*-v[0-9]+", value) is not None)
OUTCOME: Kind = ("one of " + ", ".join(strict_json.dumps(outcome.value) for outcome in Outcome),
                 lambda value: isinstance(value, str) and value in {outcome.value for outcome in Outcome})
EPISODE_FIGURES: dict[str, Kind] = {**{name: FLAG if metric.kind == "rate" else FIGURE
                                       for name, metric in METRICS.items()},
                                    **{former: FIGURE for formers in FORMER_NAMES.values() for former in formers}}
"""what each figure of an episode holds where present (``metrics.summarize`` reads older files that lack some)"""


def shown(text: str) -> str:
    """``text`` for markdown, HTML or a chart: ``SAFE_CHARACTERS`` as they are, any other character as its numeric
    character reference ``&#N;`` (``"a|b<c>"`` -> ``"a&#124;b&#60;c&#62;"``)."""
    return "".join(char if char in SAFE_CHARACTERS else f"&#{ord(char)};" for char in text)


def shell_words(*words: str) -> str:
    """A shell command for markdown or a terminal: each word ``shown``, then quoted for the shell (``shlex.quote``)."""
    return " ".join(shlex.quote(shown(word)) for word in words)


def load_result(folder: str | os.PathLike, only: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The summary of a benchmark output folder, checked: its ``summary.json`` (or gzipped ``summary.json.gz``, as
    the committed results are kept) read within ``replays.bounded_json``'s caps, every field a reader uses checked
    (``check_summary``), its figures computed again from its episodes (``check_figures``). ``LeaderboardError``
    names the file and what is wrong. With ``only`` (field -> value), a summary whose fields differ is not checked
    further: None. What was checked is cached (``result_cache``: keyed by the file's bytes and STCrowd's code), so
    a file is checked once on a machine."""
    path = Path(folder) / "summary.json"
    if not path.exists() and path.with_suffix(".json.gz").exists():
        path = path.with_suffix(".json.gz")
    if not path.exists():
        raise LeaderboardError(f"{folder}: no summary.json (run `python -m st_sim benchmark --out {folder}` "
                               "first; an interrupted run writes it when resumed to the end)")
    name = entry_key(path.read_bytes()) if path.is_file() and path.stat().st_size <= MAX_FILE_BYTES else None
    entry = None if name is None else cached(name)
    if entry is None:
        try:
            result = read_json(path, "benchmark summary")
        except DataFormatError as err:
            raise LeaderboardError(str(err)) from err
        check_summary(result, path)
        result.setdefault("robot", "holonomic")  # written before the robot was recorded (benchmark version 3 and older)
        result.setdefault("sensing", "oracle")  # written before sensing existed
        entry = {"figures_checked": False, "result": result}
    result = entry["result"]
    if only is not None and any(result.get(key) != value for key, value in only.items()):
        if name is not None:
            store(name, result, figures_checked=entry["figures_checked"])
        return None
    if not entry["figures_checked"]:
        check_figures(result, path)
        if name is not None:
            store(name, result, figures_checked=True)
    return result


def identity_of(summary: dict[str, Any], scenario: str) -> dict[str, Any]:
    """The code identity (``CODE_IDENTITY``) that the episodes of ``scenario`` in ``summary`` ran on, and what they
    read (``inputs``): its entry in ``scenario_identity`` if ``replace_rows`` re-ran it, else the summary's own
    (fields it does not record left out)."""
    record = summary.get(SCENARIO_IDENTITY, {}).get(scenario, summary)
    return {key: record[key] for key in (*CODE_IDENTITY, INPUTS) if key in record}


def check_summary(result: Any, path: Path) -> None:
    """Refuse (``LeaderboardError`` naming ``path`` and the field's path) a benchmark summary whose fields are not of
    the types its readers take: the names, the suite's identity, the scenario set, per scenario its name, env,
    keywords and exactly ``episodes_per_scenario`` episodes, in order (``check_episode``), the machine records
    (``ran_on``: objects of short strings, flags and objects of short strings), and ``scenario_identity`` if present
    (per scenario of the summary, its ``FINGERPRINTS`` objects and ``trust_policy_file``)."""
    if not isinstance(result, dict) or result.get("format") != RESULT_FORMAT:
        raise LeaderboardError(f"{path}: not a benchmark summary (expected format {RESULT_FORMAT})")
    missing = [key for key in RECORDED_SINCE if key not in result]
    if missing:
        raise LeaderboardError(f"{path}: written before runs recorded {' and '.join(missing)} (the suite's content, "
                               "the version of the metrics' definitions); add them with "
                               f"`{MIGRATE} {shell_words(str(path.parent))} --benchmark-version N` (N: what the "
                               "metrics meant when it ran, see the changelog in docs/benchmark-your-policy.md)")
    for key in ("policy", "predictor", "suite", "suite_version", "benchmark_version", "split"):
        field(path, result, key, NAME)
    for key in ("robot", "sensing"):
        if key in result:
            field(path, result, key, NAME)
    field(path, result, "suite_sha256", SHA256)
    count = field(path, result, "episodes_per_scenario", COUNT)
    names = [_check_scenario(path, scenario, f"scenarios[{i}]", count)
             for i, scenario in enumerate(field(path, result, "scenarios", SCENARIOS))]
    if len(set(names)) < len(names):
        twice = max(names, key=names.count)
        raise LeaderboardError(f"{path}: scenarios: {_quoted(twice)} is there {names.count(twice)} times")
    if field(path, result, "scenario_set", NAME_LIST) != names:
        raise LeaderboardError(f"{path}: scenario_set: not the names of the scenarios the summary holds, in order")
    if field(path, result, "suite_scenarios", COUNT) < len(names):
        raise LeaderboardError(f"{path}: suite_scenarios: {result['suite_scenarios']}, fewer than the "
                               f"{len(names)} scenarios the summary holds")
    identities = field(path, result, SCENARIO_IDENTITY, OBJECT) if SCENARIO_IDENTITY in result else {}
    for name, identity in identities.items():
        if name not in names:
            raise LeaderboardError(f"{path}: {SCENARIO_IDENTITY}: {_quoted(name)} is not a scenario the summary holds")
        where = f"{SCENARIO_IDENTITY}[{_quoted(name)}]"
        check(path, where, identity, OBJECT)
        for key in FINGERPRINTS:
            field(path, identity, key, OBJECT, where)
        field(path, identity, "trust_policy_file", FLAG, where)
        _check_inputs(path, identity, where)
    _check_inputs(path, result)
    if "modified_data_allowed" in result:
        field(path, result, "modified_data_allowed", FLAG)
    if "ran_on" in result:
        for i, record in enumerate(field(path, result, "ran_on", RECORD_LIST)):
            for key, value in check(path, f"ran_on[{i}]", record, OBJECT).items():
                check(path, f"ran_on[{i}][{_quoted(key)}]", value, RECORD_VALUE)


def _check_inputs(path: Path, owner: dict[str, Any], where: str = "") -> None:
    """``owner["inputs"]``, if there (what a run's episodes read: part -> SHA-256 or version), checked to be an
    object of short strings."""
    if "inputs" in owner:
        for part, value in field(path, owner, "inputs", OBJECT, where).items():
            check(path, f"{where}.inputs[{_quoted(part)}]" if where else f"inputs[{_quoted(part)}]", value,
                  INPUT_PART)


def _check_scenario(path: Path, scenario: Any, where: str, count: int) -> str:
    """Check one entry of ``scenarios`` (``where``: its field path); returns its name."""
    check(path, where, scenario, OBJECT)
    name = field(path, scenario, "name", NAME, where)
    field(path, scenario, "env", ENV_ID, where)
    field(path, scenario, "env_kwargs", OBJECT, where)
    episodes = field(path, scenario, "episodes", EPISODES, where)
    if len(episodes) != count:
        raise LeaderboardError(f"{path}: {where}.episodes: {len(episodes)} episodes, not the {count} of "
                               "episodes_per_scenario")
    for index, episode in enumerate(episodes):
        check_episode(path, episode, f"{where}.episodes[{index}]")
        in_order: Kind = (f"{index} (the episodes in order)",
                          lambda value, index=index: type(value) is int and value == index)
        field(path, episode, "episode", in_order, f"{where}.episodes[{index}]")
    return name


def check_episode(path: Path, episode: Any, where: str) -> None:
    """Refuse an episode (``where``: its field path) whose ``seed`` is not a whole number, whose ``outcome`` is not an
    ``Outcome``, whose figures are not of ``EPISODE_FIGURES``' kinds, or whose rates contradict its outcome (a
    ``success`` of a timeout)."""
    check(path, where, episode, OBJECT)
    field(path, episode, "seed", WHOLE, where)
    outcome = field(path, episode, "outcome", OUTCOME, where)
    for name, kind in EPISODE_FIGURES.items():
        if name not in episode:
            continue
        value = field(path, episode, name, kind, where)
        counts = RATES.get(name)
        if counts is not None and counts(episode) != value:
            raise LeaderboardError(f"{path}: {where}.{name}: {_quoted(value)} stored, but its outcome "
                                   f"{_quoted(outcome)} gives {_quoted(not value)}")


def check_figures(result: dict[str, Any], path: Path) -> None:
    """Compute the figures of every scenario and the pooled ones again from the episodes (``metrics.summarize``, as
    the benchmark writes them), refuse a summary whose stored ones differ (``LeaderboardError`` naming the figure;
    a figure that none of the episodes holds may be absent: the file is older than it), and keep the computed ones in
    ``result``."""
    every = []
    for index, scenario in enumerate(result["scenarios"]):
        _check_figures(path, scenario, f"scenarios[{index}].summary", scenario["episodes"])
        every += scenario["episodes"]
    _check_figures(path, result, "summary", every)


def _check_figures(path: Path, owner: dict[str, Any], where: str, episodes: list[dict[str, Any]]) -> None:
    """``owner["summary"]`` (field path ``where``) checked to equal the figures of ``episodes``, then replaced by
    them."""
    computed = summary_of(episodes)
    stored = dict(check(path, where, owner.get("summary", ABSENT), OBJECT))
    for name, formers in FORMER_NAMES.items():  # an older file's summary holds the figure under a former name
        former = next((f for f in formers if f in stored), None)
        if name not in stored and former is not None:
            stored[name] = stored.pop(former)
    unknown = next((name for name in stored if name not in computed), None)
    if unknown is not None:
        raise LeaderboardError(f"{path}: {where}: {_quoted(unknown)} is not a figure of the benchmark's metrics")
    for name, cell in computed.items():
        if name not in stored and cell["n"] == 0:  # a figure added after the file was written: none of its episodes
            continue                               # holds it, so there is nothing to check
        held = field(path, stored, name, OBJECT, where)
        if set(held) != set(cell):
            raise LeaderboardError(f"{path}: {where}.{name}: holds {', '.join(map(_quoted, held))}; expected "
                                   f"{', '.join(cell)}")
        for key, value in cell.items():
            if field(path, held, key, FIGURE, f"{where}.{name}") != value:
                raise LeaderboardError(f"{path}: {where}.{name}.{key}: {_quoted(held[key])} stored, "
                                       f"{_quoted(value)} from the episodes")
    owner["summary"] = computed


def field(path: Path, owner: dict[str, Any], key: str, kind: Kind, where: str = "") -> Any:
    """``owner[key]``, checked to be of ``kind`` (``check``; ``where``: the owner's field path, "" at the top)."""
    return check(path, f"{where}.{key}" if where else key, owner.get(key, ABSENT), kind)


def check(path: Path, where: str, value: Any, kind: Kind) -> Any:
    """``value``, or ``LeaderboardError`` naming ``path`` and the field's path ``where`` if it is not of ``kind``
    (``summary.json.gz: scenarios[3].episodes[17].success: expected true/false, got "yes"``)."""
    what, fits = kind
    if value is ABSENT or not fits(value):
        raise LeaderboardError(f"{path}: {where}: expected {what}, got {_quoted(value)}")
    return value


def _quoted(value: Any) -> str:
    """A value of a summary for a message: JSON (control characters escaped), cut at ``QUOTED_CHARACTERS``."""
    if value is ABSENT:
        return "nothing (the field is missing)"
    if isinstance(value, dict | list):
        return "an object" if isinstance(value, dict) else f"a list of {len(value)}"
    text = strict_json.dumps(value)
    return text if len(text) <= QUOTED_CHARACTERS else f"{text[:QUOTED_CHARACTERS]}... ({len(text):,} characters)"
