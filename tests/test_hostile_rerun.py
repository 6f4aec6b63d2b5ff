"""Rerun recordings are never lost: no overwriting, a readable file after GC, exit, Ctrl-C or kill -9, and two
writers to one path get an error. A failed write (full disk, file-size limit) stops the run with an error naming
the file and leaves a readable recording or none; a bad target is refused when the env is made.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import threading
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rrd_files import logged_steps

import envs  # noqa: F401  (registers the ids)
from st_sim.rerun_file import FLUSH_TIMEOUT_S
from st_sim.rerun_log import RecordingPathError, RerunLogger


def replay_env(path: Path) -> gym.Env:
    return gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False, rerun=str(path)).unwrapped


def test_step_after_close_keeps_the_finished_recording(tmp_path: Path) -> None:
    out = tmp_path / "run.rrd"
    env = replay_env(out)
    env.reset(seed=0, options={"start_index": 20})
    for _ in range(39):
        env.step(np.zeros(2))
    env.close()
    assert logged_steps(out) == 40
    env.step(np.zeros(2))  # starts a new recording under a new name
    env.close()
    assert logged_steps(out) == 40, "the finished recording was overwritten"
    assert env.rerun_paths == [out, tmp_path / "run-1.rrd"] and logged_steps(tmp_path / "run-1.rrd") == 1


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(runs=st.integers(1, 4))
def test_existing_recordings_are_never_overwritten(tmp_path_factory, toy_scene, runs: int) -> None:
    folder = tmp_path_factory.mktemp("numbered")
    for run in range(runs):
        with RerunLogger(folder / "run.rrd", toy_scene) as log:
            for step in range(run + 1):
                log.log_step(step, np.zeros((1, 2)), [run])
    names = ["run.rrd"] + [f"run-{n}.rrd" for n in range(1, runs)]
    assert sorted(p.name for p in folder.glob("*.rrd")) == sorted(names)
    assert [logged_steps(folder / name) for name in names] == list(range(1, runs + 1))
    assert not list(folder.glob(".*")), "lock or temp files left behind"


def test_two_writers_to_one_path_get_an_error(tmp_path: Path) -> None:
    out = tmp_path / "same.rrd"
    first, second = replay_env(out), replay_env(out)
    first.reset(seed=0)
    with pytest.raises(RecordingPathError, match="another logger"):
        second.reset(seed=1)
    for _ in range(5):
        first.step(np.zeros(2))
    first.close()
    assert logged_steps(out) == 6 and list(tmp_path.glob("*.rrd")) == [out]


@pytest.mark.parametrize("target", ["folder", "device"])
def test_a_folder_or_device_is_not_a_recording_path(tmp_path: Path, toy_scene, target: str) -> None:
    path = {"folder": tmp_path, "device": Path("/dev/null")}[target]
    with pytest.raises(RecordingPathError, match="folder or a special file"):
        RerunLogger(path, toy_scene)


WRITER = """
import gc, os, signal, sys, time
import gymnasium as gym, numpy as np, envs
mode, path = sys.argv[1], sys.argv[2]
env = gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False, rerun=path)
env.reset(seed=0, options={"start_index": 20})
for step in range(10):
    env.step(np.zeros(2))
if mode == "gc":
    del env
    gc.collect()
    os._exit(0)  # no interpreter shutdown: only the garbage collector finished the file
if mode == "kill":
    time.sleep(1.1)  # longer than FLUSH_EVERY_S: the next step flushes
    env.step(np.zeros(2))
    os.kill(os.getpid(), signal.SIGKILL)
if mode == "interrupt":
    print("stepping", flush=True)
    while True:
        *_, terminated, truncated, _ = env.step(np.zeros(2))
        if terminated or truncated:
            env.reset()
# mode "exit": the interpreter exits without close()
"""


MODES = ("gc", "exit", "kill", "interrupt")


def default_sigint() -> None:
    """In the writer before exec: Ctrl-C's default action, so Python turns it into KeyboardInterrupt (an
    ignored SIGINT, as some test runners and pools leave it, would be inherited and ignored)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture(scope="module")
def unclosed_runs(tmp_path_factory) -> Path:
    """One writer process per mode, run side by side; returns their folder (``<mode>.rrd`` each)."""
    folder = tmp_path_factory.mktemp("unclosed")
    procs = {mode: subprocess.Popen([sys.executable, "-c", WRITER, mode, str(folder / f"{mode}.rrd")],
                                    stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                    preexec_fn=default_sigint) for mode in MODES}
    assert procs["interrupt"].stdout.readline().strip() == "stepping"
    procs["interrupt"].send_signal(signal.SIGINT)  # Ctrl-C: KeyboardInterrupt inside a step
    for proc in procs.values():
        proc.communicate(timeout=300)
    return folder


@pytest.mark.parametrize("mode", MODES)
def test_an_unclosed_env_leaves_a_readable_recording_under_its_name(unclosed_runs: Path, mode: str) -> None:
    out = unclosed_runs / f"{mode}.rrd"
    assert out.is_file(), sorted(p.name for p in unclosed_runs.iterdir())
    assert logged_steps(out) >= 11, f"{mode}: {logged_steps(out)} of at least 11 steps"
    assert not list(unclosed_runs.glob(".*.part")), "hidden partial file left instead of the recording"


def test_a_lock_left_by_a_killed_writer_does_not_block_the_next(unclosed_runs: Path, toy_scene) -> None:
    out = unclosed_runs / "kill.rrd"
    assert (unclosed_runs / ".kill.rrd.lock").exists()
    with RerunLogger(out, toy_scene) as log:
        log.log_step(0, np.zeros((1, 2)), [0])
    assert log.path == unclosed_runs / "kill-1.rrd" and logged_steps(out) >= 11
    assert not (unclosed_runs / ".kill.rrd.lock").exists()


@pytest.mark.parametrize("target", ["under-a-file", "proc", "empty"])
def test_an_unwritable_target_is_refused_when_the_env_is_made(tmp_path: Path, target: str) -> None:
    (tmp_path / "notes.txt").write_text("a file, not a folder")
    path = {"under-a-file": str(tmp_path / "notes.txt" / "run.rrd"), "proc": "/proc/stcrowd-test.rrd",
            "empty": ""}[target]
    with pytest.raises(RecordingPathError, match="rerun") as raised:
        gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False, rerun=path)
    assert path in str(raised.value), raised.value
    assert isinstance(raised.value, ValueError)


def test_a_home_relative_target_is_written_under_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "home").mkdir()
    (tmp_path / "work").mkdir()
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.chdir(tmp_path / "work")
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False, rerun="~/runs/zara1.rrd")
    env.reset(seed=0)
    env.step(np.zeros(2))
    env.close()
    out = tmp_path / "home" / "runs" / "zara1.rrd"
    assert env.unwrapped.rerun_paths == [out] and logged_steps(out) == 2
    assert not any((tmp_path / "work").iterdir()), "a literal ./~ folder was made"


LIMITED_WRITER = """
import resource, sys, time
import gymnasium as gym, numpy as np, envs
path, when = sys.argv[1], sys.argv[2]
env = gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False, rerun=path, max_episode_steps=100_000)
limit = 1000
if when == "later":
    env.reset(seed=0, options={"start_index": 0})
    time.sleep(1.1)  # longer than FLUSH_EVERY_S: the next step flushes, and the scene and two steps reach the file
    env.step(np.zeros(2))
    limit = env.unwrapped.rerun_paths[0].stat().st_size + 1000
resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))  # writes beyond it fail (EFBIG)
print(limit, flush=True)
if when == "first":
    env.reset(seed=0, options={"start_index": 0})
for _ in range(5000):
    env.step(np.zeros(2))
env.close()
"""


@pytest.mark.parametrize("when", ["first", "later"])
def test_a_failed_write_stops_the_run_naming_the_file(tmp_path: Path, when: str) -> None:
    out = tmp_path / "run.rrd"
    proc = subprocess.run([sys.executable, "-c", LIMITED_WRITER, str(out), when], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode != 0, "the run went on as if the recording had been written"
    assert "RecordingWriteError" in proc.stderr and f"{out}: writing the Rerun recording failed" in proc.stderr, \
        proc.stderr[-2000:]
    if when == "first":
        assert not out.exists(), "an empty recording was left behind"
    else:
        limit = int(proc.stdout.split()[0])
        assert out.stat().st_size <= limit - 1000, "the file keeps bytes of the failed write"
        assert logged_steps(out) >= 2, "the readable prefix lost the steps written before the failure"
    assert not list(tmp_path.glob(".*")), "lock file left behind"


def limit_file_size() -> None:
    """In a child before exec: every write that would make a file longer than 1 byte fails with EFBIG."""
    resource.setrlimit(resource.RLIMIT_FSIZE, (1, resource.RLIM_INFINITY))


def test_navigate_names_the_recording_it_cannot_write(tmp_path: Path) -> None:
    folder = tmp_path / "rerun"
    proc = subprocess.run([sys.executable, "-m", "st_sim", "navigate", "--env", "STCrowd-SimCrossing-v1",
                           "--policy", "straight", "--predictor", "none", "--episodes", "2", "--quiet",
                           "--rerun", str(folder)], capture_output=True, text=True, timeout=600,
                          preexec_fn=limit_file_size, env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    expected = folder / "STCrowd-SimCrossing-v1_straight_none_seed0.rrd"
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert f"error: {expected}: writing the Rerun recording failed: File too large" in proc.stderr, proc.stderr[-2000:]
    assert sorted(p.name for p in folder.iterdir()) == [], "a recording (or its lock) was left behind"


def test_the_demo_names_the_recording_it_cannot_write(tmp_path: Path) -> None:
    """docs/rerun.md: ``demo``, like ``navigate``, prints a failed write as one ``error:`` line and exits with 1."""
    target = tmp_path / "demo.rrd"
    proc = subprocess.run([sys.executable, "-m", "st_sim", "demo", "--steps", "3", "--rerun", str(target)],
                          capture_output=True, text=True, timeout=600, preexec_fn=limit_file_size,
                          env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
    assert proc.returncode == 1, proc.stderr[-2000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, proc.stderr[-2000:]
    assert errors[0].startswith(f"error: {target}: writing the Rerun recording failed: File too large"), errors
    assert "Traceback" not in proc.stderr and not target.exists(), "a traceback or a recording was left"


def test_a_forked_child_holding_the_pipe_does_not_hold_up_close(tmp_path: Path, toy_scene) -> None:
    log = RerunLogger(tmp_path / "forked.rrd", toy_scene)
    log.log_step(0, np.zeros((1, 2)), [0])
    child = os.fork()
    if child == 0:  # inherits Rerun's end of the pipe and keeps it open until it is killed
        signal.pause()
        os._exit(0)
    try:
        log.log_step(1, np.ones((1, 2)), [0])
        closer = threading.Thread(target=log.close)
        closer.start()
        closer.join(timeout=FLUSH_TIMEOUT_S / 2)  # waiting for the pipe's end would take FLUSH_TIMEOUT_S
        assert not closer.is_alive(), "close waits for the forked child to let go of the pipe"
    finally:
        os.kill(child, signal.SIGKILL)
        os.waitpid(child, 0)
    assert logged_steps(tmp_path / "forked.rrd") == 2
