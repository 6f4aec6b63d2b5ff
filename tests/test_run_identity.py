"""A benchmark run knows everything that decided its episodes: each part of its identity (the policy's helper modules
and data files, a plug-in predictor, the shipped checkpoints, STCrowd's own code, the suite's content, the trust flag)
edited between two runs into one folder is refused on resume, naming the part; namespace packages run."""

from __future__ import annotations

import importlib
import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from st_sim.apps.navigation import benchmark
from st_sim.apps.navigation.benchmark import BenchmarkError, BenchmarkRun, run_benchmark
from st_sim.apps.navigation.fingerprint import ReadAudit, source_parts

MODULE_NUMBERS = iter(range(10**6))  # every throwaway package gets a new name (imports are cached per name)
HEAD_FOR_GOAL = ("    def act(self, obs):\n        ego = obs['ego']\n        way = ego[4:6] - ego[:2]\n"
                 "        return SPEED * way / max(float(np.hypot(*way)), 1.0)\n")


def bench(out: Path, policy: str, predictor: str = "none", suite_file: str | None = None) -> dict:
    run = BenchmarkRun(policy, str(out), predictor=predictor, split="val", episodes=1,
                       scenarios=("frontal-approach",), suite_file=suite_file)
    return run_benchmark(run, workers=1, progress=False)


def fresh_name(stem: str) -> str:
    return f"{stem}_{os.getpid()}_{next(MODULE_NUMBERS)}"


@pytest.fixture
def on_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A folder on sys.path for throwaway user code."""
    folder = tmp_path / "code"
    folder.mkdir()
    monkeypatch.syspath_prepend(str(folder))
    importlib.invalidate_caches()
    return folder


def refused(out: Path, policy: str, match: str, **options: str) -> None:
    with pytest.raises(BenchmarkError, match=match):
        bench(out, policy, **options)


def test_a_policy_whose_data_file_changed_is_refused_naming_the_file(on_path: Path, tmp_path: Path) -> None:
    name = fresh_name("datapolicy")
    np.savez(on_path / "weights.npz", speed=np.array(1.0))
    (on_path / f"{name}.py").write_text(
        "import numpy as np\nfrom pathlib import Path\n\nclass Policy:\n    def __init__(self):\n"
        "        self.speed = float(np.load(Path(__file__).with_name('weights.npz'))['speed'])\n"
        + HEAD_FOR_GOAL.replace("SPEED", "self.speed"))
    spec = f"{name}:Policy"
    held = bench(tmp_path / "run", spec)["fingerprint"]
    assert any(part.startswith("read ") and part.endswith("weights.npz") for part in held), held
    bench(tmp_path / "run", spec)  # the same files: resumes (nothing to do)
    np.savez(on_path / "weights.npz", speed=np.array(0.5))
    refused(tmp_path / "run", spec, r"read \S*weights\.npz changed")


def test_a_policy_whose_helper_module_changed_is_refused_naming_the_module(on_path: Path, tmp_path: Path) -> None:
    name, helper = fresh_name("single"), fresh_name("helper")
    (on_path / f"{helper}.py").write_text("SPEED = 1.0\n")
    (on_path / f"{name}.py").write_text(f"import numpy as np\nfrom {helper} import SPEED\n\nclass Policy:\n"
                                        + HEAD_FOR_GOAL)
    spec = f"{name}:Policy"
    bench(tmp_path / "run", spec)
    (on_path / f"{helper}.py").write_text("SPEED = 0.5\n")
    refused(tmp_path / "run", spec, f"module {helper} changed")


def test_a_policy_in_a_namespace_package_runs_and_its_files_are_identified(on_path: Path, tmp_path: Path) -> None:
    package = on_path / fresh_name("namespace")  # a folder without __init__.py
    package.mkdir()
    (package / "policy.py").write_text("import numpy as np\nSPEED = 1.0\n\nclass Policy:\n" + HEAD_FOR_GOAL)
    importlib.invalidate_caches()
    spec = f"{package.name}.policy:Policy"
    summary = bench(tmp_path / "run", spec)
    assert summary["fingerprint"]["source policy.py"] == source_parts(f"{package.name}.policy")["source policy.py"]
    (package / "policy.py").write_text("import numpy as np\nSPEED = 0.5\n\nclass Policy:\n" + HEAD_FOR_GOAL)
    refused(tmp_path / "run", spec, "source policy.py changed")


def test_a_plugin_predictor_edited_between_runs_is_refused(on_path: Path, tmp_path: Path) -> None:
    name = fresh_name("predictor")
    source = ("import numpy as np\nclass Still:\n    def predict(self, obs, group, scene, num_samples):\n"
              "        return np.repeat(obs[:, None, -1:], num_samples, 1).repeat(12, 2).astype(np.float32)\n"
              "def make(**keywords):\n    return Still()\n")
    (on_path / f"{name}.py").write_text(source)
    spec = f"{name}:make"
    held = bench(tmp_path / "run", "straight", predictor=spec)["predictor_fingerprint"]
    assert f"source {name}.py" in held
    (on_path / f"{name}.py").write_text(source + "# retrained\n")
    refused(tmp_path / "run", "straight", f"predictor '{name}:make' changed: source {name}.py changed",
            predictor=spec)


def test_the_shipped_predictors_checkpoints_and_stcrowds_own_code_are_part_of_the_identity(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import predictor.checkpoint

    summary = bench(tmp_path / "run", "straight", predictor="singular")
    assert set(summary["predictor_fingerprint"]) == {"checkpoints"}
    assert set(summary["stcrowd"]) == {"version", "source_sha256"}
    manifest = predictor.checkpoint.pretrained_manifest()
    swapped = json.loads(json.dumps(manifest))
    first = next(iter(swapped["checkpoints"].values()))
    first["sha256"] = "0" * 64
    monkeypatch.setattr(predictor.checkpoint, "pretrained_manifest", lambda: swapped)
    with pytest.raises(BenchmarkError, match="predictor 'singular' changed: checkpoints changed"):
        benchmark.check_run(BenchmarkRun("straight", str(tmp_path / "run"), predictor="singular", split="val",
                                         episodes=1, scenarios=("frontal-approach",)), benchmark.load_suite())
    monkeypatch.setattr(predictor.checkpoint, "pretrained_manifest", lambda: manifest)
    edited = {**summary["stcrowd"], "source_sha256": "f" * 64}  # as if a scoring constant had been changed
    monkeypatch.setattr(benchmark, "stcrowd_identity", lambda: edited)
    refused(tmp_path / "run", "straight", "STCrowd.s version, code or data changed: source_sha256 changed",
            predictor="singular")


def test_a_run_on_another_robot_or_sensing_is_refused_on_resume(tmp_path: Path) -> None:
    out = tmp_path / "run"
    run = BenchmarkRun("straight", str(out), predictor="none", split="val", episodes=1, scenarios=("frontal-approach",))
    summary = run_benchmark(run, workers=1, progress=False)
    assert (summary["robot"], summary["sensing"]) == ("holonomic", "oracle")
    for change in ({"robot": "diff-drive"}, {"sensing": "range"}):
        key = next(iter(change))
        with pytest.raises(BenchmarkError, match=f"{key} '"):
            run_benchmark(replace(run, **change), workers=1, progress=False)


def test_another_suite_under_the_same_name_and_version_is_refused_on_resume(tmp_path: Path) -> None:
    raw = json.loads(benchmark.load_suite().path.read_text())
    path = tmp_path / "suite.json"
    path.write_text(json.dumps(raw))
    bench(tmp_path / "run", "straight", suite_file=str(path))
    raw["scenarios"][3]["env_kwargs"] = {"pedestrians_see_ego": False}  # frontal-approach, other settings
    path.write_text(json.dumps(raw))
    refused(tmp_path / "run", "straight", "suite_sha256", suite_file=str(path))


def test_an_audit_records_what_is_read_outside_the_installed_packages_only(tmp_path: Path) -> None:
    data, skipped = tmp_path / "data.bin", tmp_path / "out" / "kept.bin"
    skipped.parent.mkdir()
    data.write_bytes(b"1"), skipped.write_bytes(b"2")
    with ReadAudit([skipped.parent]) as audit:
        data.read_bytes(), skipped.read_bytes(), np.__file__ and Path(np.__file__).read_bytes()
        (tmp_path / "written.bin").write_bytes(b"3")
    assert audit.files == {data.resolve()}


def test_a_run_records_where_it_ran_and_the_leaderboard_shows_it(tmp_path: Path, capsys: pytest.CaptureFixture
                                                                  ) -> None:
    from st_sim.apps.cli import main
    from st_sim.apps.navigation.provenance import PACKAGES

    summary = bench(tmp_path / "run", "straight")
    (record,) = summary["ran_on"]
    assert set(record) == {"commit", "tree_clean", "python", "versions", "machine", "cpu", "simd"}
    assert set(record["versions"]) == set(PACKAGES) and set(record["simd"]) == {"numpy", "torch", "numba"}
    assert json.loads((tmp_path / "run" / "run.json").read_text())["ran_on"] == [record]
    bench(tmp_path / "run", "straight")  # a resume on the same machine adds no record
    assert json.loads((tmp_path / "run" / "run.json").read_text())["ran_on"] == [record]
    assert main(["leaderboard", str(tmp_path / "run"), "--no-baselines", "--ran-on"]) == 0
    table = capsys.readouterr().out.split("### Where they ran")[1]
    assert f"| straight + none | {str(record['commit'])[:12]} |" in table and record["versions"]["numpy"] in table
