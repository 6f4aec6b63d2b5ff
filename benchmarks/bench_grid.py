"""The grid runner on a real Ray cluster on this machine: one node against two, and a node killed mid-grid.

    OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy python benchmarks/bench_grid.py

Runs the same 20 evaluation jobs (``st_sim.apps.evaluate:evaluate_job`` on one task x scene x predictor, replayed
through the environment as ``st_sim evaluate`` does; 3 to 20 s each with one thread) four times, each into a
fresh folder:

1. locally, a process pool of 2 workers (``run_jobs(executor="local")``): the reference results;
2. on a Ray cluster of one node: ``ray start --head --num-cpus 1``;
3. on a new cluster of two nodes: that head and ``ray start --address HEAD --num-cpus 1``;
4. on the same two nodes, killing the second (SIGKILL to its process group) once ``--kill-after`` jobs are done.

Each node is a separate ``ray start --block`` process (its own session and process group) with its own
temporary folder and free ports, so runs 2 and 3 both start without any worker process; the driver connects
before the clock starts. Prints, per run: jobs done, jobs retried, results identical to the local run (every
field of each result JSON but the wall time and the checkpoint path), wall time, and jobs per node with their
mean wall and CPU time; then the 2-vs-1 node ratio. The nodes and this driver run without token
authentication (``RAY_AUTH_MODE=disabled``), and the nodes are killed on exit, error, Ctrl-C or SIGTERM.
``ray stop`` is never called: it would stop every Ray instance on the machine, other users' included.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

from replays import data_root
from st_sim.apps.grid import Job, JobReport, connect_ray, raise_on_failure, run_jobs

FOUR = ("eth", "hotel", "zara1", "zara2")  # UNIV's 24,334 windows would make one job as long as ten others
CELLS = ([("momentary", scene, f"shipped:momentary/{scene}") for scene in ("eth", "hotel", "zara1")]
         + [("stochastic", scene, "cvm-s") for scene in ("eth", "hotel", "zara1")]
         + [("momentary", scene, "cvm-s") for scene in ("eth", "hotel")]
         + [("stochastic", scene, f"shipped:{name}") for scene in ("eth", "hotel")
            for name in (f"stochastic/{scene}", "universal")]
         + [("stochastic", scene, name) for name in ("cvm", "linear") for scene in FOUR])
"""(task, scene, predictor source) of the 20 jobs, the longest first"""
NODE_ENV = {"RAY_AUTH_MODE": "disabled", "OMP_NUM_THREADS": "1"}
START_TIMEOUT_S = 180.0  # a node that has not joined by then is an error


def grid_jobs(folder: Path, root: str) -> list[Job]:
    """The 20 evaluation jobs, writing their JSON results into ``folder``."""
    jobs = []
    for task, scene, source in CELLS:
        label = source.replace("shipped:", "shipped-").replace("/", "-")
        output = str(folder / f"{task}_{scene}_{label}.json")
        jobs.append(Job(f"evaluate/{task}/{scene}/{label}", "st_sim.apps.evaluate:evaluate_job",
                        {"source": source, "task": task, "scene": scene, "root": root, "stream": True,
                         "momentary_from_8": False, "rerun_path": None, "output": output}, output))
    return jobs


def scores(path: str) -> dict:
    """A result JSON without the fields that may differ between runs: wall time and checkpoint path."""
    result = json.loads(Path(path).read_text())
    return {k: v for k, v in result.items() if k not in ("wall_s", "checkpoint")}


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class LocalCluster:
    """Ray nodes on this machine, one ``ray start --block`` process group each, with this process as driver.

    ``with LocalCluster(folder) as cluster:`` disconnects the driver and kills every node at the end.
    """

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.nodes: dict[str, subprocess.Popen] = {}
        self.names: dict[str, str] = {}
        """Ray node id (first 8 hex digits, as in ``JobReport.where``) -> our name"""
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"

    def __enter__(self) -> LocalCluster:
        return self

    def __exit__(self, *_) -> None:
        import ray

        ray.shutdown()
        for name in list(self.nodes):
            self.kill(name)

    def start(self, name: str) -> None:
        """Start node ``name`` with 1 CPU and wait until it has joined; the first one is the head, and this
        process connects to it as the driver."""
        import ray

        head = not self.nodes
        args = (["--head", f"--port={self.port}", "--include-dashboard=false", f"--dashboard-port={free_port()}"]
                if head else [f"--address={self.address}"])
        command = [str(Path(sys.executable).with_name("ray")), "start", "--block", "--num-cpus=1",
                   f"--temp-dir={self.folder / name}", "--disable-usage-stats",
                   f"--dashboard-agent-listen-port={free_port()}", *args]
        self.folder.mkdir(parents=True, exist_ok=True)
        with open(self.folder / f"{name}.log", "w") as log:
            self.nodes[name] = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                                                env={**os.environ, **NODE_ENV})
        deadline = time.monotonic() + START_TIMEOUT_S
        while True:
            if self.nodes[name].poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"ray node {name} did not start; see {self.folder / name}.log")
            if head and not ray.is_initialized():
                if self._head_listens():
                    connect_ray(self.address)
            else:
                new = [node["NodeID"][:8] for node in ray.nodes() if node["Alive"] and node["NodeID"][:8] not in
                       self.names]
                if new:
                    self.names[new[0]] = name
                    return
            time.sleep(0.5)

    def kill(self, name: str) -> None:
        """SIGKILL the node's process group, as a lost machine; its Ray workers exit when their raylet dies."""
        node = self.nodes.pop(name)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(node.pid, signal.SIGKILL)
        node.wait()

    def _head_listens(self) -> bool:
        with socket.socket() as sock:
            return sock.connect_ex(("127.0.0.1", self.port)) == 0


def kill_when_done(cluster: LocalCluster, name: str, jobs: list[Job], count: int, stop: threading.Event) -> None:
    """Kill node ``name`` as soon as ``count`` of ``jobs`` have written their output (or ``stop`` is set)."""
    while not stop.wait(0.2):
        if sum(job.done() for job in jobs) >= count:
            cluster.kill(name)
            return


def timed_run(jobs: list[Job], **grid) -> tuple[list[JobReport], float]:
    """Run a grid; returns its reports and wall time [s]."""
    start = time.perf_counter()
    reports = run_jobs(jobs, progress=False, **grid)
    raise_on_failure(reports)
    return reports, time.perf_counter() - start


def row(setting: str, reports: list[JobReport], wall_s: float, jobs: list[Job], reference: list[Job],
        names: dict[str, str]) -> str:
    """A table row: setting, jobs done, retried, identical to the local results, wall time, jobs per node."""
    done = sum(r.status == "done" for r in reports)
    retried = sum(r.attempts > 1 for r in reports)
    same = ("reference" if jobs is reference else
            f"{sum(scores(a.output) == scores(b.output) for a, b in zip(jobs, reference, strict=True))}/{len(jobs)}")
    times = defaultdict(list)
    for r in reports:
        times[names.get(r.where.removeprefix("ray node ")[:8], "local pool")].append((r.wall_s, r.cpu_s))
    nodes = ", ".join(f"{name} {len(t)} × {statistics.fmean(w for w, _ in t):.1f} s "
                      f"({statistics.fmean(c for _, c in t):.1f} s CPU)" for name, t in sorted(times.items()))
    return f"| {setting} | {done} | {retried} | {same} | {wall_s:.1f} | {nodes} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--kill-after", type=int, default=5,
                        help="kill node 2 once this many jobs of the last run are done (default: 5)")
    parser.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    args = parser.parse_args()
    root = str(data_root(args.data_root).resolve())  # absolute: Ray workers run in their own folders
    os.environ.update(NODE_ENV)  # before Ray is imported: this driver, like the nodes, runs without tokens
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # so the `with` blocks kill the nodes on SIGTERM too
    folder = Path(tempfile.mkdtemp(prefix="stcrowd-grid-"))  # short: Ray's socket paths live under it
    rows, walls, load_start = [], {}, os.getloadavg()[0]
    try:
        reference = grid_jobs(folder / "local", root)
        reports, walls["local"] = timed_run(reference, executor="local", workers=2)
        rows.append(row("local pool, 2 workers", reports, walls["local"], reference, reference, {}))
        with LocalCluster(folder / "1node") as cluster:
            cluster.start("head")
            jobs = grid_jobs(folder / "1node-results", root)
            reports, walls["1 node"] = timed_run(jobs, executor="ray", address=cluster.address)
            rows.append(row("Ray, 1 node (1 CPU)", reports, walls["1 node"], jobs, reference, cluster.names))
        with LocalCluster(folder / "2nodes") as cluster:
            cluster.start("head")
            cluster.start("node2")
            jobs = grid_jobs(folder / "2nodes-results", root)
            reports, walls["2 nodes"] = timed_run(jobs, executor="ray", address=cluster.address)
            rows.append(row("Ray, 2 nodes (1 CPU each)", reports, walls["2 nodes"], jobs, reference, cluster.names))

            jobs, stop = grid_jobs(folder / "killed-results", root), threading.Event()
            killer = threading.Thread(target=kill_when_done, args=(cluster, "node2", jobs, args.kill_after, stop))
            killer.start()
            try:
                reports, wall_s = timed_run(jobs, executor="ray", address=cluster.address)
            finally:
                stop.set()
                killer.join()
            rows.append(row(f"Ray, 2 nodes, node2 killed after {args.kill_after} jobs", reports, wall_s, jobs,
                            reference, cluster.names))
            retried = [f"{r.name} ({r.attempts} attempts)" for r in reports if r.attempts > 1]
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    print(f"{len(CELLS)} evaluation jobs per run, one thread each; jobs per node: count × mean wall (CPU) time")
    print(f"{os.cpu_count()} cores; load average {load_start:.1f} at the start, {os.getloadavg()[0]:.1f} at the end\n")
    print("| run | jobs done | retried | identical to local | wall s | jobs per node |")
    print("|---|---|---|---|---|---|")
    print("\n".join(rows))
    print(f"\nwall time, 2 nodes / 1 node: {walls['2 nodes'] / walls['1 node']:.2f}")
    print(f"retried after the kill: {', '.join(retried) or 'none (node2 had no job in flight)'}")


if __name__ == "__main__":
    main()
