"""Results folders come from anyone: a crafted summary is refused naming the file and the field (a wrong type, a spec,
a path or markup where it does not belong; figures that are not its episodes'; bombs past the caps of
``replays.bounded_json``), an honest one is read with the figures its episodes give, markup in its labels never
reaches markdown or a chart raw, and ``--paired`` says which scenarios or versions differ."""

from __future__ import annotations

import argparse
import copy
import gzip
import os
import re
import shlex
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from envs.suite import load_suite
from replays.bounded_json import BLOCK_BYTES, MAX_DEPTH, MAX_JSON_BYTES, MAX_TOKENS
from st_sim.apps.cli import main
from st_sim.apps.navigation import benchmark_cli
from st_sim.apps.navigation.benchmark import BENCHMARK_VERSION, RESULT_FORMAT, json_value, summary_of, summary_text
from st_sim.apps.navigation.leaderboard import (
    LeaderboardError,
    baseline_results,
    chart,
    check_comparable,
    episodes_line,
    label,
    load_result,
    markdown,
    ran_on_table,
    same_settings_command,
)
from st_sim.apps.navigation.leaderboard_page import scenario_chart, worst_table
from st_sim.apps.navigation.metrics import MEANS, METRICS, Outcome
from st_sim.apps.navigation.paired import paired_text
from st_sim.apps.navigation.result_cache import cached, entry_key
from st_sim.perception import SENSING_LEVELS
from st_sim.sim.robot import ROBOTS

HOSTILE = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SPECS = ["pkg.module:Policy", "sb3:/srv/model.zip", "os:system", "payload:X-v0"]
PATHS = ["/etc/passwd", "../../secret", "~/model.zip", "C:\\x", "/dev/zero"]
MARKUP = ["<img src=x onerror=alert(1)>", "a | b", "`rm -rf ~`", "[x](javascript:alert(1))", "$\\frac{a$", "x\ny",
          "&lt;", "**bold**", "<!--", "a\\|b", "\x1b[31mred", "<script>", "line\r\nbreak"]
hostile_text = st.sampled_from(SPECS + PATHS + MARKUP) | st.text(min_size=1, max_size=20)
SAFE_SHOWN = re.compile(r"(?:[A-Za-z0-9 _.:/+=@-]|&#[0-9]+;)*")
"""what ``shown`` may give: the safe characters and numeric character references"""
OUTCOMES = [outcome.value for outcome in Outcome]
SUITE_NAMES = [scenario.name for scenario in load_suite().scenarios]
SHIPPED_SHA256 = load_suite().content_sha256


def episode_line(index: int, seed: int, outcome: Outcome, robot: bool, means: dict[str, Any]) -> dict[str, Any]:
    """An episode line as the benchmark writes it: rates that agree with ``outcome`` (a pedestrian collision the
    robot's if ``robot``), then ``means``."""
    pedestrian, wall = outcome is Outcome.PEDESTRIAN, outcome is Outcome.WALL
    return {"episode": index, "seed": seed, "outcome": outcome.value, "collision": pedestrian or wall,
            "collision_at_fault": wall or (pedestrian and robot), "collision_robot_on_person": pedestrian and robot,
            "collision_person_on_robot": pedestrian and not robot, "pedestrian_collision": pedestrian,
            "wall_collision": wall, "success": outcome is Outcome.GOAL, "timeout": outcome is Outcome.TIMEOUT, **means}


def plain_lines(*outcomes: Outcome) -> list[dict[str, Any]]:
    """Episode lines of these outcomes, seeds 100, 101, ..., every mean 1.0."""
    return [episode_line(index, 100 + index, outcome, True, dict.fromkeys(MEANS, 1.0))
            for index, outcome in enumerate(outcomes)]


@st.composite
def episode_lines(draw: st.DrawFn, count: int) -> list[dict[str, Any]]:
    """``count`` episode lines of random outcomes, seeds and means (or null), every float rounded as the writer
    rounds it."""
    means = st.none() | st.integers(0, 500) | st.floats(-1e3, 1e3, allow_nan=False).map(json_value)
    return [episode_line(index, draw(st.integers(0, 2**32 - 1)), draw(st.sampled_from(Outcome)), draw(st.booleans()),
                         {name: draw(means) for name in MEANS}) for index in range(count)]


def honest(scenarios: list[list[dict[str, Any]]], **fields: Any) -> dict[str, Any]:
    """A benchmark summary of these episodes (one list per scenario), its figures from the writer's own code."""
    built = [{"name": f"scenario-{k}", "env": "STCrowd-SimCrossing-v1", "env_kwargs": {"predictor": "none"},
              "description": "", "episodes": episodes, "summary": summary_of(episodes),
              "timing": {"worker_s": 1.0, "policy_s": 0.5, "steps": 10}} for k, episodes in enumerate(scenarios)]
    summary = {"format": RESULT_FORMAT, "policy": "straight", "predictor": "none", "suite": "stcrowd-nav",
               "suite_version": "1.0", "suite_sha256": "ab" * 32, "benchmark_version": BENCHMARK_VERSION,
               "split": "val", "episodes_per_scenario": len(scenarios[0]),
               "scenario_set": [scenario["name"] for scenario in built], "suite_scenarios": 18, "scenarios": built,
               "summary": summary_of([e for episodes in scenarios for e in episodes]), "timing": {"wall_s": 1.0}}
    return {**summary, **fields}


@st.composite
def summaries(draw: st.DrawFn) -> dict[str, Any]:
    """An honest summary of 1 to 3 scenarios of 1 to 4 random episodes each."""
    count = draw(st.integers(1, 4))
    return honest([draw(episode_lines(count)) for _ in range(draw(st.integers(1, 3)))])


@contextmanager
def folder_of(summary: dict[str, Any] | None = None, gzipped: bool = False) -> Iterator[Path]:
    """A temporary results folder holding ``summary`` as the writer writes it (gzipped as committed results are)."""
    with tempfile.TemporaryDirectory() as where:
        folder = Path(where) / "run"
        folder.mkdir()
        if summary is not None:
            text = summary_text(summary).encode()
            (folder / ("summary.json.gz" if gzipped else "summary.json")).write_bytes(
                gzip.compress(text) if gzipped else text)
        yield folder


def file_of(folder: Path) -> Path:
    return next(folder.glob("summary.json*"))


def refused(folder: Path) -> str:
    """The message of the ``LeaderboardError`` that reading ``folder`` raises."""
    with pytest.raises(LeaderboardError) as caught:
        load_result(folder)
    return str(caught.value)


# what each field holds (the test's own statement of the format, not the reader's)
TOP = {"policy": "name", "predictor": "name", "suite": "name", "suite_version": "name", "benchmark_version": "name",
       "split": "name", "suite_sha256": "sha", "episodes_per_scenario": "count", "suite_scenarios": "count",
       "scenario_set": "names", "scenarios": "scenarios", "summary": "object"}
SCENARIO = {"name": "name", "env": "env", "env_kwargs": "object", "episodes": "list", "summary": "object"}
EPISODE = {"episode": "index", "seed": "whole", "outcome": "outcome",
           **{name: "flag" if metric.kind == "rate" else "figure" for name, metric in METRICS.items()}}
numbers = st.integers(-5, 5) | st.floats(-1e3, 1e3, allow_nan=False)
lists = st.lists(st.integers(), max_size=2)
objects = st.dictionaries(st.text(max_size=3), st.integers(), max_size=2)
not_strings = st.none() | st.booleans() | numbers | lists | objects
WRONG: dict[str, st.SearchStrategy] = {
    "name": not_strings | st.just("") | st.just("x" * 301),
    "sha": not_strings | hostile_text | st.just("AB" * 32),
    "count": hostile_text | st.none() | st.booleans() | st.floats(allow_nan=False, allow_infinity=False)
    | st.integers(max_value=0) | lists | objects,
    "names": hostile_text | st.none() | numbers | objects | st.lists(st.integers() | st.none(), min_size=1, max_size=3),
    "scenarios": hostile_text | st.none() | numbers | objects | st.just([]),
    "object": hostile_text | st.none() | st.booleans() | numbers | lists,
    "list": hostile_text | st.none() | st.booleans() | numbers | objects,
    "env": not_strings | st.sampled_from(SPECS + PATHS + MARKUP) | st.from_regex(r"[a-z]{1,8}:[A-Z][a-z]{0,8}-v0",
                                                                                  fullmatch=True),
    "index": hostile_text | st.none() | st.booleans() | st.floats(0.5, 9.5) | lists | objects,
    "whole": hostile_text | st.none() | st.booleans() | st.floats(0.5, 9.5) | lists | objects,
    "outcome": not_strings | hostile_text.filter(lambda text: text not in OUTCOMES),
    "flag": hostile_text | st.none() | st.integers(0, 1) | st.floats(allow_nan=False, allow_infinity=False) | lists
    | objects,
    "figure": hostile_text | st.booleans() | lists | objects | st.floats(1e301, 1e308) | st.just(10**400),
}
"""values a field of each kind must never hold"""


def fields(summary: dict[str, Any]) -> list[tuple[tuple[Any, ...], str]]:
    """Every field of ``summary`` a reader uses: (its path of keys and indices, its kind)."""
    found = [((key,), kind) for key, kind in TOP.items()]
    for owner in [("summary",), *(("scenarios", k, "summary") for k in range(len(summary["scenarios"])))]:
        found += [((*owner, name), "object") for name in METRICS]
        found += [((*owner, name, key), "figure") for name in METRICS for key in ("value", "low", "high", "n")]
    for k, scenario in enumerate(summary["scenarios"]):
        found += [(("scenarios", k, key), kind) for key, kind in SCENARIO.items()]
        found += [(("scenarios", k, "episodes", i, key), kind) for i in range(len(scenario["episodes"]))
                  for key, kind in EPISODE.items()]
    return found


def dotted(path: tuple[Any, ...]) -> str:
    """``("scenarios", 3, "episodes", 17, "success")`` -> ``scenarios[3].episodes[17].success``."""
    return "".join(f"[{key}]" if isinstance(key, int) else f".{key}" for key in path).lstrip(".")


def replaced(summary: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    crafted = copy.deepcopy(summary)
    owner = crafted
    for key in path[:-1]:
        owner = owner[key]
    owner[path[-1]] = value
    return crafted


@settings(HOSTILE, max_examples=150)
@given(summary=summaries(), data=st.data(), gzipped=st.booleans())
def test_a_field_of_the_wrong_kind_is_refused_naming_the_file_and_the_field(summary: dict[str, Any],
                                                                            data: st.DataObject,
                                                                            gzipped: bool) -> None:
    path, kind = data.draw(st.sampled_from(fields(summary)))
    value = data.draw(WRONG[kind])
    with folder_of(replaced(summary, path, value), gzipped) as folder:
        message = refused(folder)
        assert message.startswith(f"{file_of(folder)}: {dotted(path)}: expected "), message
    assert "\n" not in message and "\x1b" not in message, "one line, no terminal escapes"


@HOSTILE
@given(summary=summaries())
def test_an_honest_summary_is_accepted_with_the_figures_of_its_episodes(summary: dict[str, Any]) -> None:
    with folder_of(summary, gzipped=True) as folder:
        result = load_result(folder)
    every = [e for scenario in summary["scenarios"] for e in scenario["episodes"]]
    assert result["summary"] == summary_of(every)
    for scenario in result["scenarios"]:
        assert scenario["summary"] == summary_of(scenario["episodes"])
    assert "| straight + none |" in markdown([result])


@settings(HOSTILE, max_examples=10)
@given(summary=summaries())
def test_an_older_summary_that_names_a_figure_by_its_former_name_is_accepted(summary: dict[str, Any]) -> None:
    older = copy.deepcopy(summary)
    for owner in (older, *older["scenarios"]):
        owner["summary"]["min_distance_m"] = owner["summary"].pop("min_step_end_gap_m")
        for episode in owner.get("episodes", []):
            if "min_step_end_gap_m" in episode:
                episode["min_distance_m"] = episode.pop("min_step_end_gap_m")
    with folder_of(older, gzipped=True) as folder:
        result = load_result(folder)
    assert result["summary"]["min_step_end_gap_m"] == summary_of(
        [e for scenario in summary["scenarios"] for e in scenario["episodes"]])["min_step_end_gap_m"]


@settings(HOSTILE, max_examples=80)
@given(summary=summaries(), data=st.data())
def test_a_stored_figure_that_its_episodes_do_not_give_is_refused_naming_it(summary: dict[str, Any],
                                                                           data: st.DataObject) -> None:
    owner = data.draw(st.sampled_from([("summary",), *(("scenarios", k, "summary")
                                                       for k in range(len(summary["scenarios"])))]))
    name, key = data.draw(st.sampled_from(sorted(METRICS))), data.draw(st.sampled_from(["value", "low", "high", "n"]))
    cells = summary
    for step in owner:
        cells = cells[step]
    stored = cells[name][key]
    if key == "n":
        wrong = stored + data.draw(st.integers(1, 5))
    elif stored is None:
        wrong = data.draw(st.floats(-1e3, 1e3, allow_nan=False))
    else:
        wrong = data.draw(st.none() | st.floats(-1e3, 1e3, allow_nan=False).map(json_value))
    assume(wrong != stored)
    with folder_of(replaced(summary, (*owner, name, key), wrong)) as folder:
        message = refused(folder)
        assert re.fullmatch(rf"{re.escape(str(file_of(folder)))}: {re.escape(dotted((*owner, name, key)))}: "
                            r"\S+ stored, \S+ from the episodes", message), message


def test_two_failed_episodes_stored_as_a_success_of_one_are_refused() -> None:
    episodes = plain_lines(Outcome.TIMEOUT, Outcome.TIMEOUT)
    summary = honest([episodes])
    summary["summary"]["success"]["value"] = 1.0
    with folder_of(summary) as folder:
        assert refused(folder) == f"{file_of(folder)}: summary.success.value: 1.0 stored, 0.0 from the episodes"
    lying = copy.deepcopy(episodes)
    lying[1]["success"] = True
    with folder_of(honest([lying])) as folder:
        assert refused(folder) == (f'{file_of(folder)}: scenarios[0].episodes[1].success: true stored, but its '
                                   'outcome "timeout" gives false')


@settings(max_examples=12, deadline=None)
@given(size=st.integers(MAX_JSON_BYTES + 1, 3 * MAX_JSON_BYTES))
@example(size=MAX_JSON_BYTES + 1)
def test_a_gzip_ratio_bomb_past_the_cap_is_refused_within_seconds(size: int) -> None:
    block = gzip.compress(b" " * BLOCK_BYTES)  # a member of one block, ~1 KB: members concatenate to any size
    with folder_of() as folder:
        with (folder / "summary.json.gz").open("wb") as out:
            out.write(gzip.compress(b"["))
            for _ in range(size // BLOCK_BYTES):
                out.write(block)
            out.write(gzip.compress(b" " * (size % BLOCK_BYTES) + b"]"))
        start = time.perf_counter()
        message = refused(folder)
        assert time.perf_counter() - start < 2.0
        assert message.startswith(f"{folder / 'summary.json.gz'}: decompresses to more than the "
                                  f"{MAX_JSON_BYTES:,} bytes") and "MAX_JSON_BYTES" in message


nesting = st.lists(st.sampled_from(['[', '{"a":']), min_size=1, max_size=8)


@settings(max_examples=30, deadline=None)
@given(summary=summaries(), depth=st.integers(0, 20_000), kinds=nesting)
@example(summary=honest([plain_lines(Outcome.GOAL)]), depth=MAX_DEPTH - 4, kinds=["["])  # the deepest read
@example(summary=honest([plain_lines(Outcome.GOAL)]), depth=MAX_DEPTH - 3, kinds=["["])  # one level more
def test_nesting_past_the_cap_is_refused_and_within_it_read(summary: dict[str, Any], depth: int,
                                                            kinds: list[str]) -> None:
    """``depth`` levels of arrays and objects inside a scenario's ``env_kwargs`` (itself 4 levels deep)."""
    opening = "".join(kinds[k % len(kinds)] for k in range(depth))
    closing = "".join("]" if kinds[k % len(kinds)] == "[" else "}" for k in reversed(range(depth)))
    text = summary_text(summary).replace('"env_kwargs":{"predictor":"none"}',
                                         f'"env_kwargs":{{"predictor":"none","deep":{opening}0{closing}}}', 1)
    with folder_of() as folder:
        (folder / "summary.json").write_text(text)
        if 4 + depth <= MAX_DEPTH:
            assert load_result(folder)["scenarios"][0]["env_kwargs"]["predictor"] == "none"
        else:
            assert refused(folder) == (f"{folder / 'summary.json'}: JSON nested more than {MAX_DEPTH} levels deep, "
                                       "deeper than a benchmark summary may be (replays.bounded_json.MAX_DEPTH)")


@settings(max_examples=5, deadline=None)
@given(extra=st.integers(1, MAX_TOKENS), unit=st.sampled_from(["0", "[]", '""', "{}"]))
def test_an_array_of_more_values_than_the_cap_is_refused_before_it_is_parsed(extra: int, unit: str) -> None:
    with folder_of() as folder:
        (folder / "summary.json").write_text("[" + ",".join([unit] * (MAX_TOKENS + extra)) + "]")
        assert refused(folder).startswith(f"{folder / 'summary.json'}: more than {MAX_TOKENS:,} JSON tokens")


CRAFTED = {
    "NaN": (b'{"format": NaN}', "not strict JSON (NaN is not JSON)"),
    "Infinity": (b'[-Infinity]', "not strict JSON (-Infinity is not JSON)"),
    "an integer of 5000 digits": (b"[" + b"7" * 5000 + b"]", "not strict JSON (Exceeds the limit"),
    "a string left open over escaped quotes": (b'"' + b'\\"' * 3_000_000, "not strict JSON (Unterminated string"),
    "bytes that are not UTF-8": (b'["\xff\xfe"]', "not UTF-8 text"),
    "a list": (b"[]", "not a benchmark summary"),
}


@pytest.mark.parametrize("name", sorted(CRAFTED))
def test_a_malformed_file_is_refused_within_seconds(name: str) -> None:
    content, expected = CRAFTED[name]
    with folder_of() as folder:
        (folder / "summary.json").write_bytes(content)
        start = time.perf_counter()
        message = refused(folder)
    assert time.perf_counter() - start < 2.0, "the bracket scan stays linear"
    assert message.startswith(f"{folder / 'summary.json'}: {expected}"), message


def test_a_fifo_a_truncated_gzip_and_an_unmigrated_summary_are_refused_naming_what_to_do() -> None:
    summary = honest([plain_lines(Outcome.GOAL)])
    with folder_of() as folder:
        os.mkfifo(folder / "summary.json")
        assert "is a FIFO (named pipe); only regular files are read" in refused(folder)
    with folder_of(summary, gzipped=True) as folder:
        packed = folder / "summary.json.gz"
        packed.write_bytes(packed.read_bytes()[:-30])
        assert refused(folder).startswith(f"{packed}: cannot read its gzip stream")
    with folder_of({k: v for k, v in summary.items() if k != "suite_sha256"}) as folder:
        message = refused(folder)
        assert "written before runs recorded suite_sha256" in message
        assert f"python -m st_sim.apps.navigation.migrate_results {folder} --benchmark-version N" in message


LABELS = ("policy", "predictor", "suite", "suite_version", "split", "scenario")


@HOSTILE
@given(summary=summaries(), where=st.sampled_from(LABELS), text=hostile_text)
@example(summary=honest([plain_lines(Outcome.TIMEOUT)]), where="policy", text="<img src=x onerror=alert(1)>")
def test_markup_in_a_label_never_reaches_markdown_raw(summary: dict[str, Any], where: str, text: str) -> None:
    assume(text not in summary["scenario_set"])
    if where == "scenario":
        summary["scenarios"][0]["name"] = summary["scenario_set"][0] = text
    else:
        summary[where] = text
    with folder_of(summary) as folder:
        result = load_result(folder)
        board, page = markdown([result]), worst_table([folder], [result])
    assert SAFE_SHOWN.fullmatch(label(result)) and SAFE_SHOWN.fullmatch(episodes_line(result).replace(",", "")), \
        "no $ for mathtext, no markup in the charts"
    clean = markdown([load_result_of(honest([s["episodes"] for s in summary["scenarios"]]))])
    assert len(board.splitlines()) == len(clean.splitlines()), "no line break"
    for document, ticks in ((board, (0,)), (page, (0, 2, 4))):
        for line in document.splitlines():
            assert not set("<>$\\\x1b\r") & set(line), line
            assert re.fullmatch(r"(?:[^&]|&#[0-9]+;)*", line), f"& only in a character reference: {line}"
            assert line.count("`") in ticks, f"code spans open and close where the table puts them: {line}"
        rows = [line for line in document.splitlines() if line.startswith("|")]
        for line in rows:
            header = next(row for row in reversed(rows[:rows.index(line) + 1]) if row.startswith("| policy |"))
            assert line.count("|") == header.count("|"), f"no table pipe: {line}"


def load_result_of(summary: dict[str, Any]) -> dict[str, Any]:
    with folder_of(summary) as folder:
        return load_result(folder)


def test_markup_and_mathtext_in_labels_draw_as_text(tmp_path: Path) -> None:
    """matplotlib would refuse an unclosed ``$`` as mathtext: the charts draw every label as text."""
    results = []
    for policy, predictor in (("$\\frac{a$", "x\ny"), ("<b>", "none")):
        summary = honest([plain_lines(Outcome.GOAL, Outcome.TIMEOUT)], policy=policy, predictor=predictor)
        summary["scenarios"][0]["name"] = summary["scenario_set"][0] = "$x_{"
        results.append(load_result_of(summary))
    assert chart(results, tmp_path / "board.png").stat().st_size > 1000
    assert scenario_chart(results, tmp_path / "scenarios.png").stat().st_size > 1000


def test_results_of_other_suite_content_metrics_or_seeds_are_not_tabled_together(tmp_path: Path) -> None:
    episodes = plain_lines(Outcome.GOAL, Outcome.TIMEOUT, Outcome.WALL)
    mine = load_result_of(honest([episodes]))
    for key, value in (("suite_sha256", "cd" * 32), ("benchmark_version", "1"), ("robot", "diff-drive"),
                       ("sensing", "realistic")):
        other = load_result_of(honest([episodes], policy="other", **{key: value}))
        with pytest.raises(LeaderboardError, match=f"different episodes \\({key} "):
            check_comparable([mine, other])
    reseeded = [{**line, "seed": line["seed"] + 1} for line in episodes]
    with pytest.raises(LeaderboardError, match="ran scenario scenario-0 on different seeds"):
        check_comparable([mine, load_result_of(honest([reseeded], policy="other"))])
    (tmp_path / "shipped").mkdir()
    (tmp_path / "shipped" / "summary.json").write_text(summary_text(honest([episodes], suite_sha256="cd" * 32)))
    joined, note = baseline_results(mine, tmp_path)
    assert joined == [] and f"suite_sha256 {'cd' * 32} there, {'ab' * 32} here" in note, \
        "a suite of other content never joins"


def paired_folders(where: Path, **differ: Any) -> tuple[Path, Path]:
    """Two runs of three scenarios on the same episodes, the second's fields ``differ``."""
    scenarios = [plain_lines(Outcome.GOAL, outcome) for outcome in (Outcome.GOAL, Outcome.TIMEOUT, Outcome.WALL)]
    first, second = where / "first", where / "second"
    for folder, summary in ((first, honest(scenarios)), (second, honest(scenarios, policy="other", **differ))):
        folder.mkdir(parents=True)
        (folder / "summary.json").write_text(summary_text(summary))
    return first, second


def test_paired_refuses_other_metrics_or_suites_naming_both_values(tmp_path: Path) -> None:
    first, second = paired_folders(tmp_path / "metrics", benchmark_version="1")
    with pytest.raises(LeaderboardError, match=f"benchmark_version '{BENCHMARK_VERSION}' vs '1'"):
        paired_text(first, second)
    first, second = paired_folders(tmp_path / "suite", suite_sha256="cd" * 32)
    with pytest.raises(LeaderboardError, match=f"suite_sha256 '{'ab' * 32}' vs '{'cd' * 32}'"):
        paired_text(first, second)


def test_paired_names_the_scenarios_that_differ_and_ends_in_words(tmp_path: Path) -> None:
    first, second = paired_folders(tmp_path)
    summary = honest([s["episodes"] for s in load_result(second)["scenarios"][:2]], policy="other")
    (second / "summary.json").write_text(summary_text(summary))
    with pytest.raises(LeaderboardError) as caught:
        paired_text(first, second)
    assert str(caught.value).endswith("ran different scenarios (only the first: scenario-2; only the second: "
                                      "none); pair them over the 2 they share: --scenarios scenario-0 scenario-1")
    text = paired_text(first, second, ("scenario-0", "scenario-1"))
    last = text.splitlines()[-1]
    assert last == "the first completes, the second does not: 0 (none)", "the same episodes: none is lost"
    assert "{" not in text


def test_paired_counts_how_the_lost_episodes_ended_in_words(tmp_path: Path) -> None:
    base = plain_lines(Outcome.GOAL, Outcome.GOAL, Outcome.GOAL, Outcome.TIMEOUT)
    worse = plain_lines(Outcome.TIMEOUT, Outcome.WALL, Outcome.TIMEOUT, Outcome.GOAL)
    for name, episodes in (("a", base), ("b", worse)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "summary.json").write_text(summary_text(honest([episodes], policy=name)))
    last = paired_text(tmp_path / "a", tmp_path / "b").splitlines()[-1]
    assert last == "the first completes, the second does not: 3 (timeout 2, wall collision at fault 1)"


def test_a_navigate_json_is_read_within_the_caps_and_its_episodes_checked(tmp_path: Path) -> None:
    from replays import strict_json

    episodes = [{k: v for k, v in line.items() if k != "episode"} for line in plain_lines(Outcome.GOAL, Outcome.WALL)]
    good, bad = tmp_path / "good.json", tmp_path / "bad.json"
    good.write_text(strict_json.dumps({"episodes": episodes}))
    assert "2 paired episodes" in paired_text(good, good)
    bad.write_text(strict_json.dumps({"episodes": [{**episodes[0], "outcome": "\x1b[2J<b>"}]}))
    with pytest.raises(LeaderboardError, match=r'bad\.json: episodes\[0\]\.outcome: expected one of "goal"'):
        paired_text(bad, bad)
    bomb = tmp_path / "bomb.json.gz"
    bomb.write_bytes(gzip.compress(b" " * (2 * MAX_JSON_BYTES)))
    with pytest.raises(LeaderboardError, match=r"bomb\.json\.gz: decompresses to more than"):
        paired_text(bomb, bomb)
    with pytest.raises(LeaderboardError, match="a benchmark folder and a navigate --json file"):
        paired_text(good, tmp_path)


def test_the_command_refuses_a_crafted_folder_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    summary = honest([plain_lines(Outcome.GOAL, Outcome.TIMEOUT)])
    summary["scenarios"][0]["episodes"][1]["success"] = "yes"
    (tmp_path / "summary.json").write_text(summary_text(summary))
    assert main(["leaderboard", str(tmp_path), "--no-baselines"]) == 1
    error = capsys.readouterr().err
    assert error == (f'error: {tmp_path / "summary.json"}: scenarios[0].episodes[1].success: expected true/false, '
                     'got "yes"\n')


RECORD_VALUES = st.none() | st.booleans() | st.text(max_size=20) | st.dictionaries(st.text(max_size=5),
                                                                                    st.text(max_size=20), max_size=3)
WRONG_RECORDS = (hostile_text | st.none() | numbers | objects |  # not a list
                 st.lists(hostile_text | numbers | lists, min_size=1, max_size=2) |  # not records
                 st.lists(st.dictionaries(st.text(max_size=5), numbers | lists | st.just("x" * 301) |
                                          st.dictionaries(st.text(max_size=3), numbers | st.none(), min_size=1),
                                          min_size=1, max_size=2), min_size=1, max_size=2))  # wrong values
"""``ran_on`` values a summary must never hold: machine records are lists of objects of short strings, flags and
objects of short strings"""


@HOSTILE
@given(summary=summaries(), ran_on=WRONG_RECORDS)
def test_machine_records_of_the_wrong_kind_are_refused_naming_the_field(summary: dict[str, Any], ran_on: Any) -> None:
    with folder_of({**summary, "ran_on": ran_on}) as folder:
        message = refused(folder)
    assert re.match(r'\S+summary\.json: ran_on(\[\d+\](\[".*"\])?)?: expected ', message), message


@HOSTILE
@given(summary=summaries(), records=st.lists(st.dictionaries(
    st.sampled_from(["commit", "tree_clean", "versions", "cpu", "simd"]) | st.text(max_size=8), RECORD_VALUES,
    max_size=5), max_size=3))
def test_machine_records_of_the_right_kind_are_read_and_tabled(summary: dict[str, Any], records: list) -> None:
    with folder_of({**summary, "ran_on": records}) as folder:
        result = load_result(folder)
    assert result["ran_on"] == records
    assert ran_on_table([result]).count("\n") >= 3


@HOSTILE
@given(summary=summaries(), data=st.data())
def test_a_checked_summary_is_cached_by_its_bytes_and_a_changed_one_is_checked_again(summary: dict[str, Any],
                                                                                     data: st.DataObject) -> None:
    with folder_of(summary, gzipped=True) as folder:
        first, again = load_result(folder), load_result(folder)
        assert again == first, "the cached result is the checked one"
        assert cached(entry_key(file_of(folder).read_bytes())) is not None
        name = data.draw(st.sampled_from(sorted(METRICS)))
        crafted = replaced(summary, ("summary", name, "value"), 1234.5)
        file_of(folder).write_bytes(gzip.compress(summary_text(crafted).encode()))
        assert f"summary.{name}" in refused(folder), "other bytes are never read from the cache"


@HOSTILE
@given(split=st.sampled_from(["val", "test"]), episodes=st.integers(1, 100),
       robot=st.sampled_from(list(ROBOTS)), sensing=st.sampled_from(list(SENSING_LEVELS)),
       scenarios=st.lists(st.sampled_from(SUITE_NAMES), min_size=1, max_size=4, unique=True))
def test_the_suggested_command_runs_a_shipped_planner_on_the_runs_episodes(split: str, episodes: int, robot: str,
                                                                           sensing: str, scenarios: list) -> None:
    like = {"split": split, "episodes_per_scenario": episodes, "robot": robot, "sensing": sensing,
            "scenario_set": scenarios, "suite_scenarios": len(SUITE_NAMES), "suite_sha256": SHIPPED_SHA256}
    words = shlex.split(same_settings_command(like))
    assert words[:4] == ["python", "-m", "st_sim", "benchmark"]
    parser = argparse.ArgumentParser()
    benchmark_cli.add_parsers(parser.add_subparsers(dest="command"))
    args = parser.parse_args([word.replace("DIR", "out") for word in words[3:]])
    assert (args.split, args.episodes, args.robot, args.sensing) == (split, episodes, robot, sensing)
    assert args.scenarios == (scenarios if len(scenarios) < len(SUITE_NAMES) else None)
    assert args.suite_file is None and args.policy == "mpc"
