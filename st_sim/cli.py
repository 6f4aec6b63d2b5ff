"""``python -m st_sim <command>``: evaluate predictors, run the demo."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

from replays.constants import TASKS


def run_evaluate(args: argparse.Namespace) -> int:
    """Evaluate a predictor on one task's test windows; print a markdown table, optionally write JSON."""
    from predictor.registry import make_predictor
    from st_sim.evaluate import evaluate_task, markdown_table

    def factory(task: str, scene: str):
        return make_predictor(args.predictor, task, scene, args.data_root, args.runs, args.train_missing,
                              progress=not args.quiet)

    tasks = list(TASKS) if args.task == "all" else [args.task]
    for task in tasks:
        scenes = args.scenes if args.scenes and len(tasks) == 1 else None
        result = evaluate_task(factory, task, scenes, momentary_from_8=args.momentary_from_8,
                               root=args.data_root, progress=not args.quiet)
        result["predictor"] = args.predictor
        result["momentary_protocol"] = "from-8" if args.momentary_from_8 else "own-2-frame-windows"
        table = markdown_table(result, args.predictor)
        print(table + "\n")
        if args.json and len(tasks) == 1:
            write_json_atomic(Path(args.json), result)
            print(f"wrote {args.json}")
        if args.out:
            write_json_atomic(Path(args.out) / f"{task}.json", result)
            write_text_atomic(Path(args.out) / f"{task}.md", table + "\n")
            print(f"wrote {args.out}/{task}.json and {task}.md")
    return 0


def run_demo(args: argparse.Namespace) -> int:
    """Run the embedded default: a simulated crossing with an ego and the shipped predictor."""
    from st_sim.demo import run_demo as demo

    demo(steps=args.steps, rerun_path=args.rerun, seed=args.seed)
    return 0


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON through a temp file and a rename, so a crash never leaves half a file."""
    write_text_atomic(path, json.dumps(data, indent=1))


def write_text_atomic(path: Path, text: str) -> None:
    """Write text through a temp file and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, path)


COMMANDS = {"evaluate": run_evaluate, "demo": run_demo}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m st_sim", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)

    evaluate = commands.add_parser("evaluate", help="score a predictor on a benchmark task's test windows")
    evaluate.add_argument("--task", choices=[*TASKS, "all"], default="stochastic",
                          help="benchmark task, or all five (default: stochastic)")
    evaluate.add_argument("--predictor", default="cvm-s",
                          help="cvm | cvm-s | linear | singular | checkpoint file or folder (default: cvm-s)")
    evaluate.add_argument("--scenes", nargs="+", default=None,
                          help="scenes (eth hotel univ zara1 zara2) or domain pairs (A2B ...); default: all")
    evaluate.add_argument("--momentary-from-8", action="store_true",
                          help="momentary task: score the 8-frame protocol's samples on their last 2 frames "
                               "(default: the loader's own 2-frame windows)")
    evaluate.add_argument("--json", default=None, help="also write the results to this JSON file (one task)")
    evaluate.add_argument("--out", default=None, help="write <task>.json and <task>.md into this folder")
    evaluate.add_argument("--runs", default="runs", help="checkpoint folder <task>/<scene>/best.pt (default: runs)")
    evaluate.add_argument("--train-missing", action="store_true",
                          help="singular: train any checkpoint that does not exist yet (resumes)")
    evaluate.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    evaluate.add_argument("--quiet", action="store_true", help="no progress bar")

    demo = commands.add_parser("demo", help="simulated crossing with an ego robot and predictions (no data needed)")
    demo.add_argument("--steps", type=int, default=150, help="env steps of 0.4 s (default: 150)")
    demo.add_argument("--rerun", default="stcrowd_demo.rrd", help="Rerun recording path (default: stcrowd_demo.rrd)")
    demo.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return COMMANDS[args.command](args)
