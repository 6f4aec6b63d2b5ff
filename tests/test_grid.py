"""The grid runner: local process pool and Ray give byte-identical results; finished jobs are skipped; a killed
worker's job is retried (pool and Ray), and a job that always kills its worker fails alone; the local path never
imports Ray."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import pytest
from ray_session import OBJECT_STORE_BYTES, connect_kwargs

from predictor.train import TRAIN_SUMMARY, TrainConfig
from st_sim.apps.grid import MAX_ATTEMPTS, GridError, Job, raise_on_failure, run_jobs

TINY = {"epochs": 1, "min_steps": 0, "dim": 32, "denoiser_dim": 32, "max_train_windows": 60, "batch_agents": 256,
        "progress": False}


def tiny_grid(folder: Path) -> tuple[list[Job], list[Job]]:
    """Two small training jobs and an evaluation of each model."""
    train, evaluate = [], []
    for task, scene in (("stochastic", "zara1"), ("deterministic", "hotel")):
        out = folder / task / scene
        cfg = TrainConfig(task=task, scene=scene, out=str(out), **TINY)
        train.append(Job(f"train/{task}/{scene}", "predictor.train:train_job", asdict(cfg), str(out / TRAIN_SUMMARY)))
        result = folder / f"{task}_{scene}.json"
        evaluate.append(Job(f"evaluate/{task}/{scene}", "st_sim.apps.evaluate:evaluate_job",
                            {"source": str(out / "best.pt"), "task": task, "scene": scene, "root": None,
                             "stream": False, "momentary_from_8": False, "rerun_path": None, "output": str(result)},
                            str(result)))
    return train, evaluate


def run_tiny_grid(folder: Path, executor: str) -> dict[str, bytes]:
    train, evaluate = tiny_grid(folder)
    for jobs in (train, evaluate):
        raise_on_failure(run_jobs(jobs, executor=executor, workers=2, progress=False))
    files = [Path(job.kwargs["out"]) / "best.pt" for job in train] + [Path(job.output) for job in evaluate]
    return {str(f.relative_to(folder)): f.read_bytes() for f in files}


def scores_only(data: bytes) -> bytes:
    """An evaluation JSON without its wall time and checkpoint path (which names the grid's folder)."""
    import json

    result = json.loads(data)
    del result["wall_s"], result["checkpoint"]
    return json.dumps(result, sort_keys=True).encode()


@pytest.fixture(scope="module")
def local_ray():
    """Ray on this machine with 2 CPUs; its workers see the data root and the job functions of these tests."""
    import ray  # part of the dev extra

    ray.init(num_cpus=2, object_store_memory=OBJECT_STORE_BYTES, **connect_kwargs(Path(__file__).parent))
    yield
    ray.shutdown()


def test_local_and_ray_grids_give_identical_checkpoints_and_results(tmp_path, local_ray):
    local = run_tiny_grid(tmp_path / "local", "local")
    on_ray = run_tiny_grid(tmp_path / "ray", "ray")
    assert local.keys() == on_ray.keys()
    for name in local:
        if name.endswith(".pt"):
            assert local[name] == on_ray[name], f"{name} differs between the local and the Ray grid"
        else:
            assert scores_only(local[name]) == scores_only(on_ray[name]), name


def test_a_killed_ray_worker_loses_only_its_job_which_is_retried(tmp_path, local_ray):
    dies, writes = str(tmp_path / "dies.txt"), str(tmp_path / "w.txt")
    jobs = [Job("dies", "grid_targets:die_once", {"output": dies}, dies),
            Job("write", "grid_targets:write", {"output": writes, "text": "ok"}, writes)]
    reports = run_jobs(jobs, executor="ray", progress=False)
    assert [r.status for r in reports] == ["done", "done"], reports
    assert reports[0].attempts == 2 and reports[1].attempts == 1, reports
    assert reports[0].where.startswith("ray node") and Path(dies).read_text() == "survived"


def test_finished_jobs_are_skipped_and_failures_are_reported_by_name(tmp_path):
    jobs = [Job(f"write{i}", "grid_targets:write", {"output": str(tmp_path / f"{i}.txt"), "text": str(i)},
                str(tmp_path / f"{i}.txt")) for i in range(3)]
    never = str(tmp_path / "never.txt")
    jobs.append(Job("broken", "grid_targets:fail", {"output": never}, never))
    first = run_jobs(jobs, workers=2, progress=False)
    assert [r.status for r in first] == ["done", "done", "done", "failed"]
    assert "ValueError: cannot make" in first[3].error
    with pytest.raises(GridError, match="broken: ValueError"):
        raise_on_failure(first)
    (tmp_path / "1.txt").unlink()  # as if the driver died before this job finished
    again = run_jobs(jobs, workers=2, progress=False)
    assert [r.status for r in again] == ["skipped", "done", "skipped", "failed"]
    assert (tmp_path / "1.txt").read_text() == "1"


def test_a_killed_worker_loses_only_its_job_which_is_retried(tmp_path):
    jobs = [Job("dies", "grid_targets:die_once", {"output": str(tmp_path / "dies.txt")}, str(tmp_path / "dies.txt"))]
    jobs += [Job(f"write{i}", "grid_targets:write", {"output": str(tmp_path / f"{i}.txt"), "text": "ok"},
                 str(tmp_path / f"{i}.txt")) for i in range(3)]
    reports = run_jobs(jobs, workers=2, progress=False)
    assert all(r.status == "done" for r in reports), reports
    assert reports[0].attempts == 2 and (tmp_path / "dies.txt").read_text() == "survived"


def test_a_job_that_always_kills_its_worker_fails_alone(tmp_path):
    """Jobs queued behind it when the pool breaks are resubmitted without being charged an attempt."""
    never = str(tmp_path / "never.txt")
    jobs = [Job("dies", "grid_targets:die", {"output": never}, never)]
    jobs += [Job(f"write{i}", "grid_targets:write", {"output": str(tmp_path / f"{i}.txt"), "text": "ok"},
                 str(tmp_path / f"{i}.txt")) for i in range(3)]
    reports = run_jobs(jobs, workers=1, progress=False)
    assert (reports[0].status, reports[0].attempts) == ("failed", MAX_ATTEMPTS), reports[0]
    assert "died 3 times" in reports[0].error
    for r in reports[1:]:
        assert (r.status, r.attempts) == ("done", 1), r


def test_the_local_executor_never_imports_ray(tmp_path):
    code = ("import sys; from st_sim.apps.grid import Job, run_jobs; "
            f"r = run_jobs([Job('w', 'grid_targets:write', {{'output': {str(tmp_path / 'w.txt')!r}, 'text': 'x'}}, "
            f"{str(tmp_path / 'w.txt')!r})], progress=False); "
            "assert r[0].status == 'done', r; assert 'ray' not in sys.modules, 'ray was imported'")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    subprocess.run([sys.executable, "-c", code], check=True, env=env, timeout=120)


def test_the_navigation_benchmark_gives_the_same_episodes_on_ray(tmp_path, local_ray):
    from st_sim.apps.navigation.benchmark import BenchmarkRun, run_benchmark

    for executor, workers in (("local", 2), ("ray", None)):  # worker processes both: --perturb patches this one
        run_benchmark(BenchmarkRun("straight", str(tmp_path / executor), predictor="none", split="val", episodes=3,
                                   scenarios=("frontal-approach", "hotel-reactive")),
                      executor=executor, workers=workers, progress=False)
    assert (tmp_path / "ray" / "episodes.jsonl").read_text() == (tmp_path / "local" / "episodes.jsonl").read_text()
