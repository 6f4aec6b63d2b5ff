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
import sys
import threading
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
PARENT_POLL_S = 1.0  # a local worker checks this often whether its driver is still alive [s]


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
    """What became of one job: ``status`` is done, skipped (output already there) or failed.

    ``wall_s`` and ``cpu_s`` are the last attempt's wall and CPU time [s]; a wall time well above the CPU time
    of a one-thread job means the machine was shared (waiting for a core).
    """

    name: str
    status: str
    wall_s: float = 0.0
    where: str = ""
    attempts: int = 0
    error: str | None = None
    cpu_s: float = 0.0


def one_thread() -> None:
    """One thread for this process: the variables cover a later ``import torch``, the call an earlier one."""
    for var in THREAD_VARS:
        os.environ[var] = "1"
    torch = sys.modules.get("torch")  # not imported here: a worker whose jobs never use torch skips its start-up
    if torch is not None:
        torch.set_num_threads(1)


def execute(job: Job) -> JobReport:
    """Run ``job`` here, with one thread; its own exceptions become a failed report (not retried)."""
    one_thread()
    start, cpu_start = time.perf_counter(), time.process_time()
    status, error = "done", None
    try:
        module, _, name = job.target.partition(":")
        function: Callable[..., Any] = getattr(importlib.import_module(module), name)
        function(**job.kwargs)
        if job.output and not job.done():
            raise GridError(f"{job.name}: finished but wrote no {job.output}")
    except Exception as err:
        status, error = "failed", "".join(traceback.format_exception_only(type(err), err)).strip()
    return JobReport(job.name, status, time.perf_counter() - start, f"{socket.gethostname()}:{os.getpid()}", 1,
                     error, time.process_time() - cpu_start)


def run_jobs(jobs: Sequence[Job], executor: str = "local", workers: int | None = None, address: str | None = None,
             progress: bool = True, desc: str = "jobs") -> list[JobReport]:
    """Run every unfinished job; returns one report per job, in the order given.

    Args:
        executor: "local" (a spawn process pool; never imports Ray) or "ray".
        workers: parallel jobs: the local pool's size, or the CPUs of a Ray instance started here (default: the
            number of cores); a Ray cluster given by ``address`` runs as many as it has CPUs.
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
    """Yield reports as jobs finish. A killed worker breaks the whole pool: the pool is rebuilt, the jobs that
    had started in it are charged an attempt and retried, and the jobs that had not are resubmitted free."""
    attempts = dict.fromkeys((job.name for job in jobs), 0)
    pending, idle_breaks = list(jobs), 0
    context = get_context("spawn")
    while pending:
        size = min(workers or os.cpu_count() or 1, len(pending))
        started, began = context.SimpleQueue(), set()  # names of the jobs this pool's workers began
        broken: list[Job] = []
        with ProcessPoolExecutor(size, mp_context=context, initializer=_init_local_worker,
                                 initargs=(started,)) as pool:
            futures: dict[Future, Job] = {pool.submit(_execute_local, job): job for job in pending}
            while futures:
                finished, _ = wait(futures, return_when=FIRST_COMPLETED)
                _drain(started, began)  # at every completion, so the pipe never fills
                for future in finished:
                    job = futures.pop(future)
                    try:
                        report = future.result()
                    except BrokenProcessPool:
                        broken.append(job)
                        continue
                    attempts[job.name] += 1
                    report.attempts = attempts[job.name]
                    yield report
        _drain(started, began)
        pending = [job for job in broken if job.name not in began]
        in_flight = [job for job in broken if job.name in began]
        if broken and not in_flight:
            idle_breaks += 1
            if idle_breaks >= MAX_ATTEMPTS:
                raise GridError(f"the local worker pool broke {idle_breaks} times before any job started")
        for job in in_flight:
            attempts[job.name] += 1
            if attempts[job.name] < MAX_ATTEMPTS:
                pending.append(job)
            else:
                yield JobReport(job.name, "failed", attempts=attempts[job.name], error="its worker process died "
                                f"{attempts[job.name]} times (killed or out of memory)")


def _drain(queue: Any, into: set[str]) -> None:
    while not queue.empty():
        into.add(queue.get())


_started: Any = None  # in a local pool's worker: the driver's queue of started job names


def _init_local_worker(started: Any) -> None:
    global _started
    one_thread()
    _started = started
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()


def _exit_with_parent(parent: int) -> None:
    """End this worker once the driver that started it is gone (``kill -9`` of the driver leaves no orphans)."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def _execute_local(job: Job) -> JobReport:
    _started.put(job.name)  # before the job runs, so a job that kills its worker is known to have been in flight
    return execute(job)


def connect_ray(address: str | None = None, workers: int | None = None) -> None:
    """Connect this process to a Ray cluster, or start Ray here without ``address`` (``workers`` CPUs, default all
    cores); nothing if already connected. Jobs run with one thread: the thread variables go to every worker."""
    try:
        import ray
    except ImportError as err:
        raise GridError('executor "ray" needs Ray: pip install -e ".[ray]"') from err
    if ray.is_initialized():
        return
    try:
        ray.init(address=address, num_cpus=workers if address is None else None, log_to_driver=False,
                 configure_logging=False, runtime_env={"env_vars": dict.fromkeys(THREAD_VARS, "1")})
    except ConnectionError as err:
        raise GridError(f"cannot connect to the Ray cluster at {address} ({err}). If the cluster uses token "
                        "authentication (`ray start` turns it on where ~/.ray/auth_token exists), set "
                        "RAY_AUTH_MODE=token here and give this machine the cluster's token (RAY_AUTH_TOKEN or "
                        "~/.ray/auth_token); a cluster started with RAY_AUTH_MODE=disabled needs neither") from err


def _run_ray(jobs: list[Job], workers: int | None, address: str | None):
    """Yield reports as jobs finish on Ray; jobs on a dead worker or node are resubmitted."""
    connect_ray(address, workers)
    import ray

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
    """One line per job that ran (wall and CPU time, where, attempts), then a count line."""
    lines = [f"{r.name}: {r.status} in {r.wall_s:.0f} s ({r.cpu_s:.0f} s CPU) on {r.where}"
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
