"""What the kernel's open watch (``st_sim.apps.navigation.open_watch``) costs: the time to open and close one file,
and to start the watch, in fresh processes with and without it, alternated, in the same run.

    OMP_NUM_THREADS=1 python benchmarks/bench_open_watch.py --opens 20000 --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CHILD = """
import sys, time
sys.path.insert(0, {repo!r})
from st_sim.apps.navigation import open_watch
path, opens, watched = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
start = time.perf_counter()
if watched:
    assert open_watch.start(), open_watch.unavailable()
started_s = time.perf_counter() - start
start = time.perf_counter()
for _ in range(opens):
    open(path, "rb").close()
print(started_s, (time.perf_counter() - start) / opens * 1e6)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--opens", type=int, default=20_000, help="opens timed per process")
    parser.add_argument("--repeats", type=int, default=5, help="processes per variant, alternated")
    args = parser.parse_args()
    code = CHILD.format(repo=str(REPO))
    with tempfile.NamedTemporaryFile(suffix=".bin") as file:
        file.write(b"x" * 1024)
        file.flush()
        runs: dict[bool, list[dict]] = {False: [], True: []}
        for _ in range(args.repeats):
            for watched in (False, True):
                out = subprocess.run([sys.executable, "-c", code, file.name, str(args.opens), str(int(watched))],
                                     capture_output=True, text=True, check=True).stdout
                start_s, open_us = map(float, out.split())
                runs[watched].append({"start_s": start_s, "open_us": open_us})
    plain = statistics.median(run["open_us"] for run in runs[False])
    watched = statistics.median(run["open_us"] for run in runs[True])
    start_ms = statistics.median(run["start_s"] for run in runs[True]) * 1e3
    print(f"open+close, median of {args.repeats} processes x {args.opens} opens: unwatched {plain:.2f} us, "
          f"watched {watched:.2f} us ({watched - plain:+.2f} us, {watched / plain:.1f}x)")
    print(f"starting the watch (watcher process, filter): median {start_ms:.1f} ms")


if __name__ == "__main__":
    main()
