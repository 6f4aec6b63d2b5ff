"""Load time of every benchmark window of all five scenes and tasks, cold (parse + cut) and from cache.

    OMP_NUM_THREADS=1 STCROWD_DATA=../shared/datasets/eth_ucy python benchmarks/bench_load.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile

CHILD = """
import time
t = time.perf_counter()
from replays import load_windows
from replays.constants import TASKS, SPLITS
from replays.scenes import SCENE_NAMES
from st_sim.apps.evaluate import DOMAIN_PAIRS
n = 0
for task in TASKS:
    for scene in (DOMAIN_PAIRS if task.startswith("domain") else SCENE_NAMES):
        for split in SPLITS:
            n += len(load_windows(task, scene, split))
print(f"{time.perf_counter() - t:.3f} {n}")
"""


def timed_run(cache: str) -> tuple[float, int]:
    """Run the loading in a fresh interpreter (nothing in memory); returns (seconds, samples)."""
    env = dict(os.environ, STCROWD_CACHE=cache, OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True)
    if out.returncode:
        sys.exit(f"bench_load: loading failed:\n{out.stderr}")
    seconds, samples = out.stdout.split()
    return float(seconds), int(samples)


def main() -> None:
    print("all windows of the tasks x (5 scenes | 20 domain pairs) x 3 splits, fresh interpreter each run")
    for repeat in range(3):
        with tempfile.TemporaryDirectory() as cache:
            cold, samples = timed_run(cache)
            warm, _ = timed_run(cache)
        print(f"run {repeat + 1}: {samples} samples  cold {cold:.2f} s  from cache {warm:.2f} s  "
              f"(ratio {cold / warm:.1f}x)")


if __name__ == "__main__":
    main()
