"""A benchmark run knows everything that decided its episodes: each part of its identity (the policy's helper modules
and data files, a plug-in predictor, the shipped checkpoints, STCrowd's own code, the suite's content, the trust flag)
edited between two runs into one folder is refused on resume, naming the part; namespace packages run."""

from __future__ import annotations

import importlib
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import hypothesis
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from st_sim.apps.navigation import benchmark, fingerprint
from st_sim.apps.navigation.benchmark import BenchmarkError, BenchmarkRun, run_benchmark
from st_sim.apps.navigation.fingerprint import ChunkInputs, InputsError, ReadAudit, source_parts

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
    assert {"version", "source_sha256", "version numpy"} <= set(summary["stcrowd"])
    manifest = predictor.checkpoint.pretrained_manifest()
    swapped = json.loads(json.dumps(manifest))
    first = next(iter(swapped["checkpoints"].values()))
    first["sha256"] = "0" * 64
    monkeypatch.setattr(predictor.checkpoint, "pretrained_manifest", lambda: swapped)
    with pytest.raises(BenchmarkError, match="predictor 'singular' changed: checkpoints changed"):
        run = BenchmarkRun("straight", str(tmp_path / "run"), predictor="singular", split="val", episodes=1,
                           scenarios=("frontal-approach",))
        benchmark.check_run(run, benchmark.plan_run(run))
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


def speed_policy(on_path: Path, stem: str, speed: str, from_episode: int = 1, imports: str = "os") -> str:
    """A throwaway policy (``import numpy as np`` and ``imports``) that sets its speed to the expression ``speed`` on
    the reset of every episode from ``from_episode`` on (1 = the first; 1.0 before) and heads for the goal at it;
    returns its spec."""
    name = fresh_name(stem)
    (on_path / f"{name}.py").write_text(
        f"import {imports}\nimport numpy as np\n\nclass Policy:\n    def __init__(self):\n"
        "        self.episodes, self.speed = 0, 1.0\n    def reset(self):\n        self.episodes += 1\n"
        f"        if self.episodes >= {from_episode}:\n            self.speed = {speed}\n"
        + HEAD_FOR_GOAL.replace("SPEED", "self.speed"))
    return f"{name}:Policy"


def late_reader(on_path: Path, weights: Path, read_from_episode: int) -> str:
    """A throwaway policy that reads ``weights`` (np.load) on the reset of episode ``read_from_episode`` (1 = the
    first) and heads for the goal at the speed it holds; returns its spec."""
    return speed_policy(on_path, "late", f"float(np.load({str(weights)!r})['speed'])", read_from_episode)


def test_weights_under_the_home_cache_are_part_of_the_identity(on_path: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    home = tmp_path / "home"
    monkeypatch.setenv("HOME", str(home))
    weights = home / ".cache" / "hub" / "weights.npz"
    weights.parent.mkdir(parents=True)
    np.savez(weights, speed=np.array(1.0))
    spec = late_reader(on_path, weights, 1)
    held = bench(tmp_path / "run", spec)["fingerprint"]
    assert f"read {weights.resolve()}" in held, held
    np.savez(weights, speed=np.array(0.5))
    refused(tmp_path / "run", spec, r"weights\.npz changed")


def test_a_file_first_read_in_a_later_episode_is_an_input_and_a_resume_after_it_changed_is_refused(
        on_path: Path, tmp_path: Path) -> None:
    weights = tmp_path / "late.npz"
    np.savez(weights, speed=np.array(1.0))
    spec = late_reader(on_path, weights, 2)
    run = BenchmarkRun(spec, str(tmp_path / "run"), predictor="none", split="val", episodes=2,
                       scenarios=("frontal-approach",))
    summary = run_benchmark(run, workers=1, progress=False)
    assert f"read {weights.resolve()}" not in summary["fingerprint"], "the first episode does not read it"
    assert f"read {weights.resolve()}" in summary["inputs"], summary["inputs"]
    run_benchmark(run, workers=1, progress=False)  # unchanged: resumes
    np.savez(weights, speed=np.array(0.5))
    with pytest.raises(BenchmarkError, match=r"inputs changed since they ran .*late\.npz changed"):
        run_benchmark(run, workers=1, progress=False)


NATIVE_READERS = {  # read a 1 x 1 grey image and close it without Python's open: an expression of PATH
    "imread": "int(cv2.imread(PATH, cv2.IMREAD_GRAYSCALE)[0, 0])",
    "a program": "(100 if subprocess.run(['cat', PATH], capture_output=True, check=True).stdout else 0)",
}


def grey(path: Path, value: int) -> None:
    import cv2

    assert cv2.imwrite(str(path), np.full((1, 1), value, np.uint8))


@pytest.mark.parametrize("reader", sorted(NATIVE_READERS))
@pytest.mark.parametrize("workers", [1, 2])
def test_a_file_native_code_reads_in_a_later_episode_is_an_input(on_path: Path, tmp_path: Path, reader: str,
                                                                  workers: int) -> None:
    """OpenCV's imread and a program the policy runs read past Python's open; the kernel's open watch sees them, in
    the process that runs the chunk (one worker: this one; two: a pool's), and a resume after the file changed is
    refused, naming it."""
    weights = tmp_path / "speed.png"
    grey(weights, 100)
    spec = speed_policy(on_path, "nativelate", f"{NATIVE_READERS[reader].replace('PATH', repr(str(weights)))} / 100",
                        from_episode=2, imports="os, subprocess, cv2")
    run = BenchmarkRun(spec, str(tmp_path / "run"), predictor="none", split="val", episodes=2,
                       scenarios=("frontal-approach",))
    summary = run_benchmark(run, workers=workers, progress=False)
    assert f"read {weights.resolve()}" in summary["inputs"], summary["inputs"]
    grey(weights, 50)
    with pytest.raises(BenchmarkError, match=r"inputs changed since they ran .*speed\.png changed"):
        run_benchmark(run, workers=workers, progress=False)


def test_a_run_records_the_versions_of_the_packages_it_loaded_and_the_data_override(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    summary = bench(tmp_path / "run", "straight")
    assert summary["stcrowd"]["version numpy"] == np.__version__
    assert summary["inputs"]["version python"] and summary["modified_data_allowed"] is False
    monkeypatch.setenv("STCROWD_ALLOW_MODIFIED_DATA", "1")
    refused(tmp_path / "run", "straight", "modified_data_allowed False there, True now")


def test_an_input_that_changes_while_a_chunk_runs_is_an_error(tmp_path: Path) -> None:
    data = tmp_path / "w.bin"
    data.write_bytes(b"1")
    inputs = ChunkInputs(tmp_path / "chunk.inputs.json")
    with ReadAudit() as audit:
        data.read_bytes()
        inputs.keep(audit)
        assert ChunkInputs(tmp_path / "chunk.inputs.json").parts == inputs.parts, "kept on disk"
        alias = tmp_path / "alias.bin"  # another name of the same file: what the run opened is not written
        os.link(data, alias)
        subprocess.run([sys.executable, "-c", f"open({str(alias)!r}, 'wb').write(b'22')"], check=True)
        with pytest.raises(InputsError, match=r"w\.bin changed while the run read it"):
            inputs.keep(audit)


def test_a_policy_that_looks_up_its_user_reads_no_input_about_the_machine(on_path: Path, tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """``getpass.getuser`` without $USER reads /etc/passwd through the C library (torch's compiler does, on import):
    the machine's, not the policy's, so neither its fingerprint nor its inputs name it (another machine could not
    verify the run), while a data file it reads beside stays one."""
    for variable in ("LOGNAME", "USER", "LNAME", "USERNAME"):
        monkeypatch.delenv(variable, raising=False)
    weights = tmp_path / "w.npz"
    np.savez(weights, speed=np.array(1.0))
    spec = speed_policy(on_path, "whoami", "[getpass.getuser(), socket.getaddrinfo('localhost', 80)] and "
                        f"float(np.load({str(weights)!r})['speed'])", imports="getpass, socket")
    summary = bench(tmp_path / "run", spec)
    named = {*summary["fingerprint"], *summary["inputs"]}
    assert f"read {weights.resolve()}" in named, named
    assert not {part for part in named if part.startswith("read /etc/")}, named


@settings(max_examples=60, deadline=None)
@given(machine=st.sampled_from(sorted(fingerprint.MACHINE_FILES)),
       other=st.from_regex(r"/etc/[a-z][a-z0-9_]{0,12}\.(npz|pt|conf)", fullmatch=True))
def test_only_the_machine_files_and_the_derived_data_cache_are_not_inputs(machine: str, other: str) -> None:
    assert fingerprint.not_an_input(f"read {machine}")
    assert fingerprint.not_an_input(f"read {fingerprint.cache_dir().resolve() / 'sums-0.json'}")
    assert not fingerprint.not_an_input(f"read {other}") or other in fingerprint.MACHINE_FILES
    assert not fingerprint.not_an_input(f"module {machine}") and not fingerprint.not_an_input(f"version {machine}")
    audit = ReadAudit()
    audit.opened(machine, "r")
    assert not audit.files


@settings(max_examples=40, deadline=None)
@given(root=st.sampled_from(["/usr/src/app", "/usr/local/share", "/etc", "/opt/models", "~/.cache/hub",
                             "~/.config/x", sys.prefix]),
       name=st.from_regex(r"[a-z][a-z0-9_]{0,12}\.(npz|pt|bin|onnx|json)", fullmatch=True))
def test_no_folder_is_skipped_for_where_it_lies(root: str, name: str) -> None:
    path = Path(root).expanduser() / name
    assert not fingerprint._own(path.resolve()), f"{path} would not be recorded"


def test_only_stcrowd_the_standard_library_and_pseudo_files_are_skipped_and_packages_go_by_version() -> None:
    for skipped in (os.__file__, fingerprint.__file__, "/proc/self/status"):
        assert fingerprint._own(Path(skipped).resolve()), skipped
    assert not fingerprint._own(Path(np.__file__).resolve()), "an installed package is not skipped"
    assert fingerprint._part("module numpy", Path(np.__file__).resolve()) == {}, "STCrowd's: in its identity"
    assert fingerprint._part("module hypothesis", Path(hypothesis.__file__).resolve()) == {
        "version hypothesis": hypothesis.__version__}, "any other distribution: the policy's, by version"


def test_verify_refuses_a_run_whose_policy_read_a_file_that_changed_since(on_path: Path, tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture) -> None:
    from st_sim.apps.cli import main

    weights = tmp_path / "late.npz"
    np.savez(weights, speed=np.array(1.0))
    spec = late_reader(on_path, weights, 2)
    run_benchmark(BenchmarkRun(spec, str(tmp_path / "run"), predictor="none", split="val", episodes=2,
                               scenarios=("frontal-approach",)), workers=1, progress=False)
    assert main(["verify", str(tmp_path / "run"), "--policy", spec, "--per-scenario", "2", "--quiet"]) == 0
    capsys.readouterr()
    np.savez(weights, speed=np.array(0.5))
    assert main(["verify", str(tmp_path / "run"), "--policy", spec, "--quiet"]) == 1
    assert re.search(r"files the run's episodes read are not the same here: read \S*late\.npz changed",
                     capsys.readouterr().err)


def system_library(stem: str, other: bool = False, outside: Path = Path("/nonexistent")) -> Path:
    """The file of a shared library this process has mapped whose name starts with ``stem`` (``other``: whose name
    does not, libc's or another: a library of other bytes), not under ``outside`` (a test's own copies, which the
    process may have mapped first)."""
    for line in Path("/proc/self/maps").read_text().splitlines():
        name = line.split(None, 5)[-1]
        if name.startswith("/") and ".so" in Path(name).name and Path(name).name.startswith(stem) != other \
                and not Path(name).is_relative_to(outside):
            return Path(name)
    raise AssertionError(f"no library {'other than' if other else 'named'} {stem}* mapped in this process")


def test_a_native_library_a_policy_loads_is_part_of_its_identity(on_path: Path, tmp_path: Path) -> None:
    """Native code reads past Python's audit hook; what it maps (here a library loaded with ctypes) is seen in the
    process's memory map, hashed, and a change between two runs into one folder is refused, naming it."""
    library = tmp_path / "model.so"
    shutil.copyfile(system_library("libm.so"), library)
    name = fresh_name("native")
    (on_path / f"{name}.py").write_text(
        f"import ctypes\nimport numpy as np\nSPEED = 1.0\n\nclass Policy:\n    def __init__(self):\n"
        f"        self.library = ctypes.CDLL({str(library)!r})\n" + HEAD_FOR_GOAL)
    spec = f"{name}:Policy"
    held = bench(tmp_path / "run", spec)["fingerprint"]
    assert f"read {library.resolve()}" in held, held
    bench(tmp_path / "run", spec)  # the same library: resumes
    retrained = tmp_path / "model.so.new"  # a new file in its place: the loaded one's pages stay as they were
    shutil.copyfile(system_library("libm.so", other=True, outside=tmp_path), retrained)
    os.replace(retrained, library)
    refused(tmp_path / "run", spec, r"model\.so changed")


@pytest.mark.parametrize("kind", ["module", "version"])
def test_verify_checks_the_identity_of_every_scenario_and_names_other_versions_once(
        kind: str, on_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """A run whose second scenario was re-run on other code (``scenario_identity``, as ``replace_rows`` writes it):
    ``verify --policy`` checks that scenario's own identity too; a module that differs is refused naming it, another
    version of a package is named once and left to the episodes, which here reproduce."""
    from st_sim.apps.cli import main

    weights = tmp_path / "w.npz"
    np.savez(weights, speed=np.array(1.0))
    spec = late_reader(on_path, weights, 1)
    run_benchmark(BenchmarkRun(spec, str(tmp_path / "run"), predictor="none", split="val", episodes=1,
                               scenarios=("frontal-approach", "overtaking")), workers=1, progress=False)
    path = tmp_path / "run" / "summary.json"
    summary = json.loads(path.read_text())
    own = {key: summary[key] for key in ("fingerprint", "predictor_fingerprint", "stcrowd", "trust_policy_file")}
    part, value = ((f"module {spec.split(':')[0]}", "sha256 " + "0" * 64) if kind == "module"
                   else ("version numpy", "0.0.1"))
    own["fingerprint"] = {**own["fingerprint"], part: value}
    second = summary["scenarios"][1]["name"]
    path.write_text(json.dumps({**summary, "scenario_identity": {second: own}}))
    code = main(["verify", str(tmp_path / "run"), "--policy", spec, "--quiet"])
    printed = capsys.readouterr()
    if kind == "module":
        assert code == 1 and f"{part} changed" in printed.err, printed
    else:
        assert code == 0 and printed.out.count("version numpy") == 1, printed
