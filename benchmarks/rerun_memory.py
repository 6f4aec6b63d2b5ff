"""Resident memory of a process that records a long replay to Rerun, against the same replay unrecorded.

    OMP_NUM_THREADS=1 python benchmarks/rerun_memory.py --steps 4000 --out runs/rerun_memory

Each variant runs in a fresh interpreter (so one's memory never counts in the other's): STCrowd-Univ-v0 with the
robot standing, CVM forecasts (the figure is about the recording, not the predictor), forecasts not kept
(``env.unwrapped.forecasts = None``), one episode of ``--steps`` steps. Prints the resident set size (VmRSS)
every ``--every`` steps, the growth from the first print to the last, the wall time and the size of the .rrd.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def rss_mb() -> float:
    """This process's resident set size [MB] (Linux /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def run(steps: int, every: int, rrd: str | None) -> None:
    """One variant, in this process: print `step rss_mb` lines, then `wall_s <seconds>`."""
    import gymnasium as gym

    import envs  # noqa: F401

    env = gym.make("STCrowd-Univ-v0", predictor="cvm", max_episode_steps=steps + 1,
                   **({} if rrd is None else {"rerun": rrd}))
    env.unwrapped.forecasts = None
    env.reset(seed=0)
    start = time.perf_counter()
    for step in range(steps):
        *_, terminated, truncated, _ = env.step(np.zeros(2))
        if terminated or truncated:
            env.reset()
        if step % every == 0 or step == steps - 1:
            print(step, f"{rss_mb():.1f}", flush=True)
    env.close()
    print("wall_s", f"{time.perf_counter() - start:.1f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=4000, help="env steps of 0.4 s (default: 4000)")
    parser.add_argument("--every", type=int, default=500, help="print the memory every this many steps (default: 500)")
    parser.add_argument("--out", type=Path, default=Path("runs/rerun_memory"), help="folder for the recording")
    parser.add_argument("--variant", choices=["off", "on"], help=argparse.SUPPRESS)  # one run, in a child process
    args = parser.parse_args()
    if args.variant is not None:
        run(args.steps, args.every, None if args.variant == "off" else str(args.out / "univ.rrd"))
        return
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "univ.rrd").unlink(missing_ok=True)
    print(f"| recording | RSS at step 0 [MB] | RSS at step {args.steps - 1} [MB] | growth [MB] | wall [s] "
          "| .rrd [MB] |")
    print("|---|---|---|---|---|---|")
    for variant in ("off", "on"):
        lines = subprocess.run([sys.executable, __file__, "--variant", variant, "--steps", str(args.steps),
                                "--every", str(args.every), "--out", str(args.out)],
                               check=True, capture_output=True, text=True).stdout.split("\n")
        rows = [line.split() for line in lines if line]
        trace = [float(mb) for step, mb in rows if step != "wall_s"]
        wall = next(value for key, value in rows if key == "wall_s")
        size = f"{(args.out / 'univ.rrd').stat().st_size / 2**20:.0f}" if variant == "on" else "-"
        print(f"| {variant} | {trace[0]:.0f} | {trace[-1]:.0f} | {trace[-1] - trace[0]:+.0f} | {wall} | {size} |  "
              f"trace: {' '.join(f'{mb:.0f}' for mb in trace)}")


if __name__ == "__main__":
    main()
