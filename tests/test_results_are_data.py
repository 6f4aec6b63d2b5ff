"""A results folder and a suite file are data: nothing they name runs and nothing they name is written. Crafted
summaries whose policy, predictor, env id or env keywords name a module or a path are refused by ``episode`` with one
line saying how to give them, and the module is never imported; crafted suite scenarios are refused when read."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from envs.suite import SCENARIO_KEYWORDS, SuiteError, check_scenario, load_suite
from st_sim.apps.cli import main
from st_sim.apps.navigation.benchmark import BenchmarkRun, run_benchmark

HOSTILE = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
SCENARIO = "frontal-approach"
PAYLOAD = "import pathlib\npathlib.Path(__file__).with_name('RAN').write_text('ran')\n{body}\n"
"""a module that leaves a file RAN beside it when it is imported"""
module_names = st.from_regex(r"[a-z][a-z0-9_]{0,8}(\.[a-z][a-z0-9_]{0,8}){0,2}", fullmatch=True)
paths = st.sampled_from(["/srv/x.rrd", "../../x.rrd", "~/x", "C:/x", "./x.rrd", "a/../b", "/etc/passwd", "x:y"])


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("results") / "run"
    run_benchmark(BenchmarkRun("straight", str(out), predictor="none", split="val", episodes=1,
                               scenarios=(SCENARIO,)), workers=1, progress=False)
    return out


def hostile_copy(run_folder: Path, where: Path, edit: callable) -> Path:
    """A copy of the run's summary in ``where/folder`` with ``edit`` applied, and a payload module beside it."""
    folder = where / "folder"
    folder.mkdir(parents=True, exist_ok=True)
    summary = json.loads((run_folder / "summary.json").read_text())
    edit(summary)
    (folder / "summary.json").write_text(json.dumps(summary))
    (folder / "payload.py").write_text(PAYLOAD.format(body="class P:\n    pass\ndef make(**k):\n    return P()"))
    return folder


EDITS = {
    "policy spec": lambda s, name: s.update(policy=f"{name}:P"),
    "policy file": lambda s, name: s.update(policy=f"sb3:{name.replace('.', '/')}.zip"),
    "predictor spec": lambda s, name: s.update(predictor=f"{name}:make"),
    "env id": lambda s, name: s["scenarios"][0].update(env=f"{name}:X-v0"),
    "env predictor": lambda s, name: s["scenarios"][0]["env_kwargs"].update(predictor=f"{name}:make"),
    "env rerun": lambda s, name: s["scenarios"][0]["env_kwargs"].update(rerun=f"/srv/{name}.rrd"),
    "env root": lambda s, name: s["scenarios"][0]["env_kwargs"].update(root=f"/srv/{name}"),
    "env pretrained": lambda s, name: s["scenarios"][0]["env_kwargs"].update(pretrained=f"../{name}"),
}


@HOSTILE
@given(edit=st.sampled_from(sorted(EDITS)), name=st.sampled_from(["payload", "folder.payload"]) | module_names)
def test_a_results_folder_that_names_code_or_a_path_is_refused_and_nothing_it_names_runs(
        run_folder: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture,
        edit: str, name: str) -> None:
    where = tmp_path / edit.replace(" ", "-") / name
    folder = hostile_copy(run_folder, where, lambda summary: EDITS[edit](summary, name))
    monkeypatch.chdir(where)  # the folder's parent, on sys.path as `python -m st_sim` puts it
    monkeypatch.syspath_prepend(str(where))
    assert main(["episode", str(folder), SCENARIO, "0"]) == 1
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1, error
    assert "--policy" in error or "--predictor" in error or "env" in error, error
    assert not (folder / "RAN").exists(), "the folder's module ran"
    assert "payload" not in sys.modules and "folder.payload" not in sys.modules


def test_a_run_whose_policy_is_not_shipped_replays_when_the_user_names_it_and_only_as_identified(
        run_folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    spec = "st_sim.apps.navigation.straight:StraightPlanner"
    folder = tmp_path / "own"
    run_benchmark(BenchmarkRun(spec, str(folder), predictor="none", split="val", episodes=1, scenarios=(SCENARIO,)),
                  workers=1, progress=False)
    assert main(["episode", str(folder), SCENARIO, "0"]) == 1
    assert "give it yourself with --policy SPEC" in capsys.readouterr().err
    assert main(["episode", str(folder), SCENARIO, "0", "--policy", spec]) == 0
    assert "every figure equals the run's line" in capsys.readouterr().out
    forged = hostile_copy(folder, tmp_path, lambda summary: summary.update(fingerprint={"source x.py": "0" * 64}))
    assert main(["episode", str(forged), SCENARIO, "0", "--policy", spec]) == 1
    err = capsys.readouterr().err
    assert "not the one the run identified: " in err and "source x.py is gone" in err, err


forbidden_keys = st.sampled_from(["rerun", "root", "recording", "predictor", "config", "crowd", "render_mode",
                                  "device"]) | st.text(min_size=1, max_size=12).filter(
    lambda key: key not in SCENARIO_KEYWORDS)


@HOSTILE
@given(data=st.data())
def test_a_scenario_that_names_a_module_or_a_path_or_an_unknown_keyword_is_refused(data: st.DataObject) -> None:
    kind = data.draw(st.sampled_from(["env", "key", "value", "type"]))
    env, kwargs = "STCrowd-Eth-v0", {"pedestrians": "reactive"}
    if kind == "env":
        env = data.draw(module_names.map(lambda name: f"{name}:X-v0") | st.sampled_from(
            ["CartPole-v1", "Nowhere-v0", "", "STCrowd-Eth-v0 "]) | st.integers() | st.none())
    elif kind == "key":
        kwargs[data.draw(forbidden_keys)] = data.draw(st.text(max_size=8) | st.booleans())
    elif kind == "value":
        key = data.draw(st.sampled_from([k for k, kind in SCENARIO_KEYWORDS.items() if kind is str]))
        kwargs[key] = data.draw(paths | module_names.map(lambda name: f"{name}:make"))
    else:
        key = data.draw(st.sampled_from(sorted(SCENARIO_KEYWORDS)))
        kwargs[key] = data.draw(st.lists(st.integers(), max_size=2) | st.floats() | st.dictionaries(
            st.text(max_size=3), st.integers(), max_size=2) | (st.text(max_size=3) if SCENARIO_KEYWORDS[key] is bool
                                                               else st.booleans()))
    with pytest.raises(SuiteError, match=r"^where: "):
        check_scenario(env, kwargs, "where")


def test_every_shipped_scenario_passes_the_allow_list_and_a_suite_file_with_a_path_is_refused(tmp_path: Path) -> None:
    suite = load_suite()
    for scenario in suite.scenarios:
        check_scenario(scenario.env, dict(scenario.env_kwargs), scenario.name)
    raw = json.loads(suite.path.read_text())
    hostile = copy.deepcopy(raw)
    hostile["scenarios"][0]["env_kwargs"] = {"rerun": str(tmp_path / "anywhere.rrd")}
    (tmp_path / "suite.json").write_text(json.dumps(hostile))
    with pytest.raises(SuiteError, match=r"suite\.json: scenarios\[0\] \(sim-crossing\): env_kwargs 'rerun'"):
        load_suite(tmp_path / "suite.json")


def test_a_summary_from_before_the_identity_fields_is_migrated_only_if_its_episodes_are_the_suites(
        run_folder: Path, tmp_path: Path) -> None:
    from st_sim.apps.navigation.migrate_results import MigrationError, migrate

    fresh = json.loads((run_folder / "summary.json").read_text())
    old = {key: value for key, value in fresh.items() if key not in ("suite_sha256", "benchmark_version")}
    (tmp_path / "summary.json").write_text(json.dumps(old))
    migrate(tmp_path, "2", load_suite())
    migrated = json.loads((tmp_path / "summary.json").read_text())
    assert (migrated["suite_sha256"], migrated["benchmark_version"]) == (fresh["suite_sha256"], "2")
    old["scenarios"][0]["episodes"][0]["seed"] += 1
    (tmp_path / "summary.json").write_text(json.dumps(old))
    with pytest.raises(MigrationError, match="episode 0 of frontal-approach has seed"):
        migrate(tmp_path, "2", load_suite())


def test_a_summary_naming_the_machines_files_loses_them_and_keeps_every_other_part(run_folder: Path,
                                                                                  tmp_path: Path) -> None:
    from st_sim.apps.navigation.fingerprint import cache_dir
    from st_sim.apps.navigation.migrate_results import drop_machine_reads

    summary = json.loads((run_folder / "summary.json").read_text())
    cached = f"read {cache_dir().resolve() / 'sums-0.json'}"
    summary["fingerprint"] |= {"read /etc/passwd": "a" * 64, "read w.npz": "b" * 64}
    summary["inputs"] |= {cached: "c" * 64, "read /etc/model.pt": "d" * 64}
    summary["scenario_identity"] = {SCENARIO: {"inputs": {"read /etc/hosts": "e" * 64, "read x.bin": "f" * 64}}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    assert "dropped" in drop_machine_reads(tmp_path)
    migrated = json.loads((tmp_path / "summary.json").read_text())
    assert "read /etc/passwd" not in migrated["fingerprint"] and "read w.npz" in migrated["fingerprint"]
    assert cached not in migrated["inputs"] and "read /etc/model.pt" in migrated["inputs"]
    assert migrated["scenario_identity"][SCENARIO]["inputs"] == {"read x.bin": "f" * 64}
    assert "read /etc/hosts, read /etc/passwd, 1 file(s) of the derived-data cache dropped by migrate_results " \
        "--drop-machine-reads" in migrated["migrated"] and str(cache_dir()) not in migrated["migrated"]
    assert {key: value for key, value in migrated.items() if key not in ("fingerprint", "inputs", "scenario_identity",
                                                                          "migrated")} == \
        {key: value for key, value in summary.items() if key not in ("fingerprint", "inputs", "scenario_identity")}
    assert "names no file" in drop_machine_reads(tmp_path), "a second pass changes nothing"


JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.text(max_size=8)
                    | st.sampled_from(["read /etc/passwd", "read w.npz"]),
                    lambda inner: st.lists(inner, max_size=3)
                    | st.dictionaries(st.sampled_from(["read /etc/passwd", "read w.npz", SCENARIO, "inputs"]), inner,
                                      max_size=3), max_leaves=8)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(field=st.sampled_from(["fingerprint", "inputs", "scenario_identity", "migrated", None]), value=JSON)
def test_a_hostile_summary_is_migrated_or_refused_naming_it_never_a_traceback(tmp_path: Path, field: str | None,
                                                                               value: object) -> None:
    from st_sim.apps.navigation.migrate_results import MigrationError, drop_machine_reads

    summary = value if field is None else {"fingerprint": {"read /etc/passwd": "a"}, field: value}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    try:
        drop_machine_reads(tmp_path)
    except MigrationError as err:
        assert "summary.json" in str(err)
        return
    kept = json.loads((tmp_path / "summary.json").read_text())
    assert not any(part.startswith("read /etc/") for key in ("fingerprint", "inputs")
                   if isinstance(kept.get(key), dict) for part in kept[key])


def test_rows_of_a_committed_result_are_replaced_only_by_a_run_of_the_same_policy_and_episodes(
        run_folder: Path, tmp_path: Path) -> None:
    from st_sim.apps.navigation.migrate_results import MigrationError
    from st_sim.apps.navigation.replace_rows import replace_rows
    from st_sim.apps.navigation.result_folder import load_result

    old = tmp_path / "old"
    run_benchmark(BenchmarkRun("straight", str(old), predictor="none", split="val", episodes=1,
                               scenarios=(SCENARIO, "overtaking")), workers=1, progress=False)
    replace_rows(old, run_folder)
    merged = load_result(old)
    assert merged["scenario_set"] == [SCENARIO, "overtaking"] and SCENARIO in merged["migrated"]
    assert merged["scenarios"][0]["episodes"] == load_result(run_folder)["scenarios"][0]["episodes"]
    other = tmp_path / "other"
    run_benchmark(BenchmarkRun("straight", str(other), predictor="cvm", split="val", episodes=1,
                               scenarios=(SCENARIO,)), workers=1, progress=False)
    with pytest.raises(MigrationError, match="predictor 'none' there, 'cvm'"):
        replace_rows(old, other)
