"""Peak memory and time of reading crafted results folders, against a committed summary: what a hostile folder can
cost ``python -m st_sim leaderboard`` (``result_folder.load_result``, which reads within ``replays.bounded_json``'s
caps, checks every field and computes every figure again).

    OMP_NUM_THREADS=1 python benchmarks/hostile_results.py --out runs/hostile_results

Each folder is read in a fresh interpreter, so one's memory never counts in another's; it prints its peak resident
set size (``ru_maxrss``) and the time ``load_result`` took. The folders: the imports alone; a committed summary; bombs
past a cap (a gzip ratio bomb of 1 GiB, nesting 100,000 deep, a flat array of 5 million values, a file past the size
cap); files just inside every cap, which reach the parser and take the most memory a file can (floats, distinct
strings, a wide object, empty arrays, one string of 4-byte characters); and honest summaries as large as the caps let
through (one scenario of many episodes, many scenarios of two), whose figures are all computed again.
"""

from __future__ import annotations

import argparse
import gzip
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
NORMAL = REPO / "results" / "benchmark" / "mpc-singular"
BOMB_BYTES = 1 << 30  # decompressed size of the gzip ratio bomb [B]
BLOCK = b" " * (1 << 20)


def gzip_bomb(folder: Path) -> None:
    with gzip.open(folder / "summary.json.gz", "wb", compresslevel=9) as out:
        out.write(b"[")
        for _ in range(BOMB_BYTES // len(BLOCK)):
            out.write(BLOCK)
        out.write(b"]")


def write(name: str, text: Callable[[], str]) -> Callable[[Path], None]:
    """A maker of a plain ``summary.json`` holding ``text()``."""
    def make(folder: Path) -> None:
        (folder / name).write_text(text())
    return make


def inside_caps(unit: str, tokens: int, opening: str = "[", closing: str = "]") -> Callable[[], str]:
    """A flat container of ``unit`` repeated to just under ``MAX_TOKENS`` (``tokens``: tokens of one unit)."""
    from replays.bounded_json import MAX_TOKENS

    count = MAX_TOKENS // tokens - 10
    return lambda: opening + ",".join(unit.format(k) for k in range(count)) + closing


def tokens(text: str) -> int:
    """About the tokens ``replays.bounded_json`` counts in ``text`` (more where strings hold brackets or commas)."""
    return sum(text.count(char) for char in "[]{},:") + text.count('"') // 2


def honest_at_the_caps(per_scenario: int | None) -> Callable[[Path], None]:
    """A maker of a valid summary, built by the benchmark's own code from a committed one's episodes, as large as the
    caps let through: one scenario of as many episodes as fit (``per_scenario`` None), or as many scenarios of
    ``per_scenario`` episodes as fit, every figure stored as its episodes give it."""
    def make(folder: Path) -> None:
        from replays.bounded_json import MAX_JSON_BYTES, MAX_TOKENS
        from replays.bounded_json import read_json as read_summary
        from st_sim.apps.navigation.benchmark import summary_of, summary_text

        summary = read_summary(NORMAL / "summary.json.gz")
        template = summary["scenarios"][0]

        def scenario(index: int, count: int) -> dict:
            episodes = [{**template["episodes"][k % len(template["episodes"])], "episode": k} for k in range(count)]
            return {**template, "name": f"s{index:05d}", "episodes": episodes, "summary": summary_of(episodes)}

        def fitting(text: str) -> float:
            return 0.9 * min(MAX_JSON_BYTES / len(text), MAX_TOKENS / tokens(text))

        if per_scenario is None:
            probe = scenario(0, 100)
            scenarios = [scenario(0, int(100 * fitting(summary_text({"scenarios": [probe]}))))]
        else:
            count = int(fitting(summary_text({"scenarios": [scenario(0, per_scenario)]})))
            scenarios = [scenario(index, per_scenario) for index in range(count)]
        summary.update(episodes_per_scenario=len(scenarios[0]["episodes"]), suite_scenarios=len(scenarios),
                       scenario_set=[s["name"] for s in scenarios], scenarios=scenarios,
                       summary=summary_of([e for s in scenarios for e in s["episodes"]]))
        (folder / "summary.json").write_text(summary_text(summary))
    return make


CASES: dict[str, Callable[[Path], None] | None] = {
    "imports only": None,
    "committed summary (mpc-singular)": lambda folder: (folder / "summary.json.gz").write_bytes(
        (NORMAL / "summary.json.gz").read_bytes()),
    "gzip bomb, 1 GiB of JSON": gzip_bomb,
    "nesting 100,000 deep": write("summary.json", lambda: "[" * 100_000 + "]" * 100_000),
    "flat array of 5 M values": write("summary.json", lambda: "[" + "0," * 5_000_000 + "0]"),
    "file of 17 MiB": write("summary.json", lambda: "[" + " " * (17 << 20) + "]"),
    "inside the caps: floats": write("summary.json", inside_caps("1.5e300", 1)),
    "inside the caps: distinct strings": write("summary.json", inside_caps('"{:06d}"', 2)),
    "inside the caps: wide object": write("summary.json", inside_caps('"{:07d}":0', 3, "{", "}")),
    "inside the caps: empty arrays": write("summary.json", inside_caps("[]", 3)),
    "inside the caps: 4-byte characters": write("summary.json", lambda: '["' + "a" * (16_000_000) + '\\ud83d\\ude00"]'),
    "honest summary at the caps: one scenario": honest_at_the_caps(None),
    "honest summary at the caps: scenarios of 2 episodes": honest_at_the_caps(2),
}


def read(folder: Path | None) -> None:
    """One case, in this process: print ``peak_mb seconds outcome``."""
    from st_sim.apps.navigation.result_folder import LeaderboardError, load_result

    start = time.perf_counter()
    outcome = "-"
    if folder is not None:
        try:
            result = load_result(folder)
            outcome = (f"accepted ({len(result['scenarios'])} scenarios, "
                       f"{sum(len(s['episodes']) for s in result['scenarios'])} episodes)")
        except LeaderboardError as err:
            outcome = "refused: " + str(err).removeprefix(f"{folder}/")
    seconds = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kilobytes
    print(f"{peak_mb:.0f}\t{seconds:.2f}\t{outcome}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/hostile_results"), help="folder for the crafted files")
    parser.add_argument("--read", type=Path, default=None, help=argparse.SUPPRESS)  # one case, in a child process
    parser.add_argument("--imports-only", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.read is not None or args.imports_only:
        read(args.read)
        return
    print("| folder | size on disk [MB] | peak RSS [MB] | over the committed summary's [MB] | time [s] | outcome |")
    print("|---|---|---|---|---|---|")
    normal_mb = None
    for index, (name, make) in enumerate(CASES.items()):
        command = [sys.executable, __file__, "--imports-only"]
        size = "-"
        if make is not None:
            folder = args.out / f"case{index}"
            folder.mkdir(parents=True, exist_ok=True)
            for old in folder.iterdir():
                old.unlink()
            make(folder)
            size = f"{sum(path.stat().st_size for path in folder.iterdir()) / 1e6:.2f}"
            command = [sys.executable, __file__, "--read", str(folder)]
        peak, seconds, outcome = subprocess.run(command, check=True, capture_output=True, text=True
                                                ).stdout.strip().split("\t")
        normal_mb = float(peak) if name.startswith("committed") else normal_mb
        over = "-" if normal_mb is None else f"{float(peak) - normal_mb:+.0f}"
        print(f"| {name} | {size} | {peak} | {over} | {seconds} | {outcome[:150]} |", flush=True)


if __name__ == "__main__":
    main()
