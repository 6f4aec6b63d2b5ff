"""Run a grid of independent jobs on this machine (a process pool) or on a Ray cluster, with the same results.

A ``Job`` names an importable function, its keyword arguments and the file it writes (atomically) when it
is done. The driver only schedules and gathers: a job whose output already exists is skipped, so rerunning
the same command after a crash (of a worker or of the driver) redoes at most the jobs that were in flight.
Every job runs with one thread (``OMP_NUM_THREADS=1``, ``torch.set_num_threads(1)``), seeded by its own
arguments, so where it runs cannot change what it writes.

    jobs = [Job("train/stochastic/eth/seed0", "predictor.train:run", {...}, "runs/.../train.json"), ...]
    reports = run_jobs(jobs)                                  # local process pool, one worker per core
    reports = run_jobs(jobs, executor="ray", address="auto")  # an existing Ray cluster (pip install -e ".[ray]")
"""

from __future__ import annotations

import importlib
import os
import socket
import time
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from tqdm import tqdm

EXECUTORS = ("local", "ray")
MAX_ATTEMPTS = 3  # a job whose worker dies (killed, out of memory, node lost) is tried this often in all
THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


class GridError(RuntimeError):
    """Jobs of a grid failed; the message lists them with their errors."""


@dataclass(frozen=True)
class Job:
    """One unit of a grid.

    Attributes:
        name: unique, path-like (``train/stochastic/eth/seed0``).
        target: ``"package.module:function"``, called as ``function(**kwargs)`` in a worker.
        kwargs: plain, picklable arguments.
        output: file the function writes (atomically) when it finishes; present = done.
    """

    name: str
    target: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    output: str = ""

    def done(self) -> bool:
        return Path(self.output).is_file()


@dataclass
class JobReport:
    """What became of one job: ``status`` is done, skipped (output already there) or failed."""

    name: str
    status: str
    wall_s: float = 0.0
    where: str = ""
    attempts: int = 0
    error: str | None = None


def _one_thread() -> None:
    for var in THREAD_VARS:
        os.environ[var] = "1"
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # jobs that do not use torch
        pass


def execute(job: Job) -> JobReport:
    """Run ``job`` here, with one thread; its own exceptions become a failed report (not retried)."""
    _one_thread()
    start = time.perf_counter()
    where = f"{socket.gethostname()}:{os.getpid()}"
    try:
        module, _, name = job.target.partition(":")
        function: Callable[..., Any] = getattr(importlib.import_module(module), name)
        function(**job.kwargs)
        if job.output and not job.done():
            raise GridError(f"{job.name}: finished but wrote no {job.output}")
    except Exception as err:
        detail = "".join(traceback.format_exception_only(type(err), err)).strip()
        return JobReport(job.name, "failed", time.perf_counter() - start, where, 1, detail)
    return JobReport(job.name, "done", time.perf_counter() - start, where, 1)


def run_jobs(jobs: Sequence[Job], executor: str = "local", workers: int | None = None, address: str | None = None,
             progress: bool = True, desc: str = "jobs") -> list[JobReport]:
    """Run every unfinished job; returns one report per job, in the order given.

    Args:
        executor: "local" (a spawn process pool; never imports Ray) or "ray".
        workers: parallel jobs for "local" (default: the number of cores).
        address: Ray cluster address (``"auto"``, ``"HOST:PORT"``); None starts a local Ray instance.
    """
    if executor not in EXECUTORS:
        raise ValueError(f"executor={executor!r}: expected one of {', '.join(EXECUTORS)}")
    names = [job.name for job in jobs]
    if len(set(names)) != len(names):
        raise ValueError("job names must be unique")
    reports = {job.name: JobReport(job.name, "skipped") for job in jobs if job.done()}
    pending = [job for job in jobs if job.name not in reports]
    if pending:
        with tqdm(total=len(pending), desc=desc, unit="job", disable=not progress) as bar:
            run = _run_local if executor == "local" else _run_ray
            for report in run(pending, workers, address):
                reports[report.name] = report
                bar.update()
    return [reports[job.name] for job in jobs]


def _run_local(jobs: list[Job], workers: int | None, _address: str | None):
    """Yield reports as jobs finish; a broken pool (a killed worker) is rebuilt and its jobs retried."""
    attempts = dict.fromkeys((job.name for job in jobs), 0)
    pending = list(jobs)
    while pending:
        size = min(workers or os.cpu_count() or 1, len(pending))
        lost: list[Job] = []
        with ProcessPoolExecutor(size, mp_context=get_context("spawn"), initializer=_one_thread) as pool:
            futures: dict[Future, Job] = {pool.submit(execute, job): job for job in pending}
            while futures:
                finished, _ = wait(futures, return_when=FIRST_COMPLETED)
                for future in finished:
                    job = futures.pop(future)
                    attempts[job.name] += 1
                    try:
                        report = future.result()
                    except BrokenProcessPool:
                        if attempts[job.name] < MAX_ATTEMPTS:
                            lost.append(job)
                            continue
                        report = JobReport(job.name, "failed", error="its worker process died "
                                           f"{attempts[job.name]} times (killed or out of memory)")
                    report.attempts = attempts[job.name]
                    yield report
        pending = lost


def _run_ray(jobs: list[Job], _workers: int | None, address: str | None):
    """Yield reports as jobs finish on Ray; jobs on a dead worker or node are resubmitted."""
    try:
        import ray
    except ImportError as err:
        raise GridError('executor "ray" needs Ray: pip install -e ".[ray]"') from err
    if not ray.is_initialized():
        ray.init(address=address, log_to_driver=False, configure_logging=False,
                 runtime_env={"env_vars": dict.fromkeys(THREAD_VARS, "1")})
    remote = ray.remote(num_cpus=1, max_retries=0)(_execute_on_ray)
    attempts = dict.fromkeys((job.name for job in jobs), 0)
    refs: dict[Any, Job] = {}

    def submit(job: Job) -> None:
        attempts[job.name] += 1
        refs[remote.remote(job)] = job

    for job in jobs:
        submit(job)
    while refs:
        ready, _ = ray.wait(list(refs), num_returns=1)
        job = refs.pop(ready[0])
        try:
            report = ray.get(ready[0])
        except ray.exceptions.RayError as err:  # the worker or its node died: the job itself never failed
            if attempts[job.name] < MAX_ATTEMPTS:
                submit(job)
                continue
            report = JobReport(job.name, "failed", error=f"lost {attempts[job.name]} times: {type(err).__name__}")
        report.attempts = attempts[job.name]
        yield report


def _execute_on_ray(job: Job) -> JobReport:
    report = execute(job)
    import ray

    report.where = f"ray node {ray.get_runtime_context().get_node_id()[:8]} pid {os.getpid()}"
    return report


def summary_lines(reports: Sequence[JobReport]) -> list[str]:
    """One line per job that ran (wall time, where, attempts), then a count line."""
    lines = [f"{r.name}: {r.status} in {r.wall_s:.0f} s on {r.where}"
             + (f" ({r.attempts} attempts)" if r.attempts > 1 else "") + (f": {r.error}" if r.error else "")
             for r in reports if r.status != "skipped"]
    counts = {status: sum(r.status == status for r in reports) for status in ("done", "skipped", "failed")}
    lines.append(", ".join(f"{n} {status}" for status, n in counts.items()))
    return lines


def raise_on_failure(reports: Sequence[JobReport]) -> None:
    """Raise ``GridError`` naming every failed job."""
    failed = [r for r in reports if r.status == "failed"]
    if failed:
        raise GridError(f"{len(failed)} of {len(reports)} jobs failed: "
                        + "; ".join(f"{r.name}: {r.error}" for r in failed))
