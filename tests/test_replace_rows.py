"""``replace_rows`` keeps a result truthful about its code: after any sequence of partial re-runs on other code, each
scenario carries the identity of the code that made its episodes (the re-run ones their run's, the others the
result's own), a new run that does not record its code is refused, and a crafted ``scenario_identity`` is refused
by every reader naming the file and the field."""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from st_sim.apps.navigation.benchmark import (
    RAN_ON,
    SCENARIO_IDENTITY,
    BenchmarkRun,
    run_benchmark,
    summary_of,
    summary_text,
)
from st_sim.apps.navigation.migrate_results import MigrationError
from st_sim.apps.navigation.replace_rows import replace_rows
from st_sim.apps.navigation.result_folder import CODE_IDENTITY, INPUTS, LeaderboardError, identity_of, load_result

SCENARIOS = ("frontal-approach", "overtaking", "crossing-angle")


@pytest.fixture(scope="module")
def base_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A committed result of three scenarios, one episode each."""
    out = tmp_path_factory.mktemp("results") / "base"
    run_benchmark(BenchmarkRun("straight", str(out), predictor="none", split="val", episodes=1, scenarios=SCENARIOS),
                  workers=1, progress=False)
    return out


def raw_summary(folder: Path) -> dict[str, Any]:
    return json.loads((folder / "summary.json").read_text())


def other_code(base: dict[str, Any], k: int) -> dict[str, Any]:
    """A code identity, inputs and machine record other than ``base``'s, the ``k``-th (even: no predictor's parts, as
    a run without a predictor records)."""
    return {"fingerprint": {"declared": f"policy v{k}"},
            "predictor_fingerprint": {} if k % 2 == 0 else {"declared": f"predictor v{k}"},
            "trust_policy_file": False, "stcrowd": {"version": f"0.{k}", "source_sha256": f"{k:064x}"},
            INPUTS: {"read weights.npz": f"{k:064x}"}, RAN_ON: [{**base[RAN_ON][0], "commit": f"{k:040x}"}]}


def partial_run(base: dict[str, Any], names: list[str], code: dict[str, Any], folder: Path) -> Path:
    """A run of the scenarios ``names`` of ``base`` only, as made on ``code`` (its episodes ``base``'s)."""
    scenarios = [entry for entry in base["scenarios"] if entry["name"] in names]
    summary = {**base, **code, "scenarios": scenarios, "scenario_set": [entry["name"] for entry in scenarios],
               "summary": summary_of([episode for entry in scenarios for episode in entry["episodes"]])}
    folder.mkdir()
    (folder / "summary.json").write_text(summary_text(summary))
    return folder


def code_of(summary: dict[str, Any]) -> dict[str, Any]:
    """What ``identity_of`` gives for a scenario a summary (or a code identity) made: its code identity and inputs."""
    return {key: summary[key] for key in (*CODE_IDENTITY, INPUTS) if key in summary}


@settings(max_examples=20, deadline=None)
@given(reruns=st.lists(st.lists(st.sampled_from(SCENARIOS), min_size=1, max_size=3, unique=True), min_size=1,
                       max_size=3))
def test_each_scenario_carries_the_identity_of_the_code_it_ran_on(base_run: Path, reruns: list[list[str]]) -> None:
    """Re-run subsets one after another, each on other code: a scenario's identity is that of the last run that made
    its episodes; the result's own stays the code of the scenarios never re-run."""
    base = raw_summary(base_run)
    own = code_of(base)
    expected = dict.fromkeys(SCENARIOS, own)
    machines = {}
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        shutil.copytree(base_run, old)
        for k, names in enumerate(reruns, 1):
            code = other_code(base, k)
            replace_rows(old, partial_run(base, names, code, Path(tmp) / f"rerun{k}"))
            identity = code_of(code)
            expected |= dict.fromkeys(names, identity)
            machines |= dict.fromkeys(names, code[RAN_ON])
        merged = load_result(old)
    for name in SCENARIOS:
        assert identity_of(merged, name) == expected[name], f"[{name}] re-runs {reruns}"
    assert code_of(merged) == own, "the result's own identity: the code never re-run"
    assert {name: entry[RAN_ON] for name, entry in merged[SCENARIO_IDENTITY].items()} == machines
    assert all(record in merged[RAN_ON] for records in machines.values() for record in records)


def test_a_new_run_itself_replaced_in_part_passes_on_each_scenarios_own_identity(base_run: Path,
                                                                                tmp_path: Path) -> None:
    base = raw_summary(base_run)
    first, second = other_code(base, 1), other_code(base, 2)
    new = partial_run(base, list(SCENARIOS[:2]), first, tmp_path / "new")
    replace_rows(new, partial_run(base, [SCENARIOS[1]], second, tmp_path / "newer"))
    old = tmp_path / "old"
    shutil.copytree(base_run, old)
    replace_rows(old, new)
    merged = load_result(old)
    assert [identity_of(merged, name) for name in SCENARIOS] == [code_of(code) for code in (first, second, base)]


@pytest.mark.parametrize("missing", [*CODE_IDENTITY, RAN_ON])
def test_a_new_run_that_records_no_code_identity_is_refused(base_run: Path, tmp_path: Path, missing: str) -> None:
    base = raw_summary(base_run)
    code = {key: value for key, value in other_code(base, 1).items() if key != missing}
    new = partial_run({key: value for key, value in base.items() if key != missing}, [SCENARIOS[0]], code,
                      tmp_path / "new")
    old = tmp_path / "old"
    shutil.copytree(base_run, old)
    with pytest.raises(MigrationError, match=f"{new}: its summary records no {missing}: which code"):
        replace_rows(old, new)
    assert raw_summary(old) == base, "nothing written"


PART = st.sampled_from(CODE_IDENTITY)
NOT_AN_OBJECT = st.one_of(st.none(), st.text(max_size=4), st.integers(), st.booleans(),
                          st.lists(st.integers(), max_size=2))
CRAFTED = st.one_of(
    st.tuples(st.just("not an object"), NOT_AN_OBJECT),
    st.tuples(st.just("unknown scenario"), st.text(max_size=12).filter(lambda name: name not in SCENARIOS)),
    st.tuples(st.just("entry not an object"), NOT_AN_OBJECT),
    st.tuples(st.just("part missing"), PART),
    st.tuples(st.just("part of the wrong kind"), st.tuples(PART, NOT_AN_OBJECT)))
"""the ways a ``scenario_identity`` can be malformed, with what each holds"""


def crafted_field(kind: str, value: Any, scenario: str, identity: dict[str, Any]) -> Any:
    """A ``scenario_identity`` malformed as ``kind`` says (``identity``: a well-formed entry)."""
    if kind == "not an object":
        return value
    if kind == "unknown scenario":
        return {value: identity}
    if kind == "entry not an object":
        return {scenario: value}
    if kind == "part missing":
        return {scenario: {key: part for key, part in identity.items() if key != value}}
    key, bad = value
    if key == "trust_policy_file" and isinstance(bad, bool):
        bad = "yes"
    return {scenario: {**identity, key: bad}}


@settings(max_examples=40, deadline=None)
@given(crafted=CRAFTED, scenario=st.sampled_from(SCENARIOS))
def test_a_crafted_scenario_identity_is_refused_naming_the_file_and_the_field(base_run: Path,
                                                                             crafted: tuple[str, Any],
                                                                             scenario: str) -> None:
    base = raw_summary(base_run)
    identity = {key: base[key] for key in (*CODE_IDENTITY, RAN_ON)}
    field = crafted_field(*crafted, scenario, identity)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "summary.json").write_text(summary_text({**base, SCENARIO_IDENTITY: field}))
        with pytest.raises(LeaderboardError) as refused:
            load_result(folder)
    assert str(refused.value).startswith(f"{folder / 'summary.json'}: {SCENARIO_IDENTITY}"), str(refused.value)


def test_a_well_formed_scenario_identity_is_read(base_run: Path, tmp_path: Path) -> None:
    base = raw_summary(base_run)
    code = other_code(base, 1)
    (tmp_path / "summary.json").write_text(summary_text({**base, SCENARIO_IDENTITY: {SCENARIOS[1]: code}}))
    result = load_result(tmp_path)
    assert identity_of(result, SCENARIOS[1]) == code_of(code)
    assert identity_of(result, SCENARIOS[0]) == code_of(base)
