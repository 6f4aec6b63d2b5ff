"""Rerun recordings are never lost: no overwriting, a readable file after GC, exit, Ctrl-C or kill -9, and two
writers to one path get an error.
"""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import rerun as rr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from st_sim.rerun_log import RecordingPathError, RerunLogger


def logged_steps(path: Path) -> int:
    """Distinct ``step`` values in a recording (read with Rerun's own reader, as the viewer would)."""
    steps: set[int] = set()
    for chunk in rr.chunk.RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        if "step" in batch.schema.names:
            steps |= set(batch.column("step").to_pylist())
    return len(steps)


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
