"""What a benchmark run costs before its first chunk: ``benchmark.check_run`` (the policy built and, since the run's
identity holds what it reads, its first episode run under an audit hook), timed for a few policies, optionally beside
another checkout in the same run.

    OMP_NUM_THREADS=1 python benchmarks/bench_start.py --repeats 3 [--base OTHER_CHECKOUT]

Each checkout is timed in a fresh interpreter (``PYTHONPATH`` set to it); the first call of a process loads the
predictor's checkpoint, so it is printed apart from the median of the others.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
POLICIES = (("mpc", "singular"), ("straight", "none"))
CHILD = """
import statistics, sys, time
from envs.suite import load_suite
from st_sim.apps.navigation import benchmark
suite, out, repeats = load_suite(), sys.argv[1], int(sys.argv[2])
for policy, predictor in {policies}:
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        run = benchmark.BenchmarkRun(policy, f"{{out}}/{{policy}}-{{i}}", predictor=predictor)
        # a checkout with the run's plan resolves it here (its suite loaded again); an older one took the suite
        benchmark.check_run(run, benchmark.plan_run(run) if hasattr(benchmark, "plan_run") else suite)
        times.append(time.perf_counter() - start)
    print(f"{{policy}} + {{predictor}}: first {{times[0]:.2f}} s, then median {{statistics.median(times[1:]):.2f}} s")
"""


def timed(checkout: Path, repeats: int) -> str:
    """The child's lines for ``checkout``."""
    env = {**os.environ, "PYTHONPATH": str(checkout), "OMP_NUM_THREADS": "1"}
    with tempfile.TemporaryDirectory() as out:
        done = subprocess.run([sys.executable, "-c", CHILD.format(policies=POLICIES), out, str(repeats)], env=env,
                              cwd=out, capture_output=True, text=True, check=True)
    return done.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="calls per policy, the first included (default 3)")
    parser.add_argument("--base", type=Path, default=None, help="another checkout to time in the same run")
    args = parser.parse_args()
    for name, checkout in (("this checkout", REPO), ("base", args.base)):
        if checkout is not None:
            print(f"{name} ({checkout}):\n{timed(checkout, max(args.repeats, 2))}")


if __name__ == "__main__":
    main()
