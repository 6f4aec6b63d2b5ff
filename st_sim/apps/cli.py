"""``python -m st_sim <command>``: evaluate predictors, run the demo."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from replays.atomic import write_text_atomic
from replays.constants import TASKS
from st_sim.apps.navigation import cli as navigation_cli


def run_evaluate(args: argparse.Namespace) -> int:
    """Evaluate a predictor on one task's test windows; print a markdown table, optionally write JSON."""
    from predictor.registry import make_predictor
    from st_sim.apps.evaluate import evaluate_task, markdown_table

    def factory(task: str, scene: str):
        return make_predictor(args.predictor, task, scene, args.data_root, args.runs, args.train_missing,
                              progress=not args.quiet)

    tasks = list(TASKS) if args.task == "all" else [args.task]
    for task in tasks:
        scenes = args.scenes if args.scenes and len(tasks) == 1 else None
        result = evaluate_task(factory, task, scenes, momentary_from_8=args.momentary_from_8,
                               root=args.data_root, progress=not args.quiet, stream=not args.no_stream,
                               rerun_path=args.rerun)
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
    from st_sim.apps.demo import run_demo as demo

    demo(steps=args.steps, rerun_path=args.rerun, seed=args.seed)
    return 0


def run_plot(args: argparse.Namespace) -> int:
    """PNG of one test window: photo, map overlay, histories, futures, anchors before/after adaptation, truth."""
    from predictor.registry import make_predictor
    from replays.scenes import load_scene
    from replays.windows import load_windows
    from st_sim.plot import plot_prediction

    windows = load_windows(args.task, args.scene, "test", args.data_root)
    if not 0 <= args.step < windows.num_groups:
        raise SystemExit(f"--step must be a window index in 0..{windows.num_groups - 1} for {args.scene}")
    keep = windows.group == args.step
    scene = load_scene(args.scene, args.data_root)
    model = make_predictor(args.predictor, args.task, args.scene, args.data_root, args.runs)
    num_samples = TASKS[args.task]["num_samples"]
    if hasattr(model, "predict_detailed"):
        detail = model.predict_detailed(windows.obs[keep], windows.group[keep], scene, num_samples)
        futures, prototype, adapted = detail.futures, detail.prototype_anchors, detail.adapted_anchors
    else:
        futures = model.predict(windows.obs[keep], windows.group[keep], scene, num_samples)
        prototype = adapted = None
    frame = int(windows.frame[keep][0])
    path = plot_prediction(scene, windows.obs[keep], futures, args.out, gt_m=windows.fut[keep],
                           prototype_anchors_m=prototype, adapted_anchors_m=adapted,
                           title=f"{args.scene} {args.task}, window {args.step} (frame {frame}), {args.predictor}")
    print(f"wrote {path}")
    return 0


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON through a temp file and a rename, so a crash never leaves half a file."""
    write_text_atomic(path, json.dumps(data, indent=1))


COMMANDS = {"evaluate": run_evaluate, "demo": run_demo, "plot": run_plot}
COMMANDS["navigate"] = navigation_cli.run


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
    evaluate.add_argument("--no-stream", action="store_true",
                          help="skip the replay through the spectator env (default: run it and check that it "
                               "agrees with the offline windows)")
    evaluate.add_argument("--rerun", default=None,
                          help="write the stream replay to Rerun: FILE.rrd -> FILE_<task>_<scene>_<recording>.rrd")
    evaluate.add_argument("--quiet", action="store_true", help="no progress bar")

    plot = commands.add_parser("plot", help="PNG of one test window with predictions and anchors")
    plot.add_argument("--scene", default="zara1", help="scene (default: zara1)")
    plot.add_argument("--step", type=int, default=0, help="window index in the test split (default: 0)")
    plot.add_argument("--task", choices=list(TASKS), default="stochastic", help="task (default: stochastic)")
    plot.add_argument("--predictor", default="singular", help="predictor name or checkpoint (default: singular)")
    plot.add_argument("--runs", default="runs", help="checkpoint folder for singular (default: runs)")
    plot.add_argument("--out", default="stcrowd_plot.png", help="PNG path (default: stcrowd_plot.png)")
    plot.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")

    navigation_cli.add_parser(commands)
    demo = commands.add_parser("demo", help="simulated crossing with an ego robot and predictions (no data needed)")
    demo.add_argument("--steps", type=int, default=150, help="env steps of 0.4 s (default: 150)")
    demo.add_argument("--rerun", default="stcrowd_demo.rrd", help="Rerun recording path (default: stcrowd_demo.rrd)")
    demo.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return COMMANDS[args.command](args)
