"""``python -m st_sim <command>`` (or ``stcrowd <command>``): evaluate predictors, plot a window, run the demo,
navigate, benchmark a navigation policy on the suite, replay one of its episodes and compare results, validate the
reactive pedestrians."""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.constants import TASKS
from st_sim.apps import reactive_validate
from st_sim.apps.navigation import benchmark_cli, episode_replay
from st_sim.apps.navigation import cli as navigation_cli
from st_sim.command_line import (
    CliError,
    add_debug_flag,
    add_grid_arguments,
    check_writable,
    positive_int,
    run_guarded,
)

if TYPE_CHECKING:
    from st_sim.apps.evaluate import Plan


def run_evaluate(args: argparse.Namespace) -> int:
    """Evaluate predictors on benchmark tasks (seeds x scenes); print markdown tables (and, for several predictors,
    their comparison), optionally write JSON."""
    from st_sim.apps.evaluate import TRAIN_ESTIMATE_S, forget_stale_results, raise_on_job_failure
    from st_sim.apps.grid import run_jobs, summary_lines

    plans = evaluation_plans(args)
    grid = {"executor": args.executor, "workers": args.workers, "address": args.ray_address,
            "progress": not args.quiet}
    reports = []
    missing = [job for plan in plans for job in plan.train_jobs()]
    if missing:
        names = ", ".join(job.name.removeprefix("train/") for job in missing[:6]) + (" ..." if len(missing) > 6 else "")
        if args.no_train:
            raise CliError(f"{len(missing)} checkpoints are missing ({names}); drop --no-train to train them")
        workers = args.workers or os.cpu_count() or 1
        estimate_s = sum(TRAIN_ESTIMATE_S[TASKS[job.kwargs["task"]]["num_samples"] > 1] for job in missing)
        print(f"training {len(missing)} missing models into {args.runs}/ ({names}); about "
              f"{estimate_s / 60 / min(workers, len(missing)):.0f} min with {workers} workers")
        reports += run_jobs(missing, desc="train", **grid)
        raise_on_job_failure(reports)
    jobs = {plan.predictor: plan.evaluation_jobs() for plan in plans}
    for plan in plans:
        forget_stale_results(plan, jobs[plan.predictor], need_samples=len(plans) > 1)
        if len(plans) > 1:  # job names are unique within a grid
            jobs[plan.predictor] = [replace(job, name=f"{job.name} ({plan.predictor})") for job in jobs[plan.predictor]]
    reports += run_jobs([job for plan_jobs in jobs.values() for job in plan_jobs], desc="evaluate", **grid)
    raise_on_job_failure(reports)
    for task in plans[0].tasks:
        report_task(args, task, {plan.predictor: {
            (scene, seed): json.loads(Path(job.output).read_text())
            for job, (t, scene, seed) in zip(jobs[plan.predictor], plan.cells(), strict=True) if t == task}
            for plan in plans})
    if not args.quiet:
        print("\n".join(summary_lines(reports)))
    return 0


def evaluation_plans(args: argparse.Namespace) -> list[Plan]:
    """One ``Plan`` per ``--predictor``, after checking the flags and that every plug-in spec imports (before any
    work)."""
    from predictor.plugins import is_plugin_spec, resolve_factory
    from st_sim.apps.evaluate import Plan, file_label, task_scenes

    tasks = tuple(TASKS) if args.task == "all" else (args.task,)
    if args.json and len(tasks) > 1:
        raise CliError("--json takes one task; use --out DIR for --task all")
    labels = [file_label(name) for name in args.predictor] + ["comparison"]  # file names of several predictors
    if len(args.predictor) > 1 and len(set(labels)) < len(labels):
        raise CliError(f"--predictor {' '.join(args.predictor)}: each must be given once, and their file names "
                       f"({', '.join(labels[:-1])}) must differ from each other and from 'comparison'")
    for path in filter(None, [args.json, args.out]):
        check_writable(Path(path) if path == args.out else Path(path).parent)
    scenes = {task: tuple(args.scenes if args.scenes and len(tasks) == 1 else task_scenes(task)) for task in tasks}
    for task in tasks:
        unknown = [scene for scene in scenes[task] if scene not in task_scenes(task)]
        if unknown:
            raise CliError(f"--scenes {' '.join(unknown)}: not in the {task} table; expected some of "
                           f"{' '.join(task_scenes(task))}")
    for name in filter(is_plugin_spec, args.predictor):
        resolve_factory(name)
    return [Plan(name, tasks, scenes, tuple(args.seeds), args.runs, args.data_root, not args.no_stream,
                 args.momentary_from_8, args.rerun, not args.no_shipped) for name in args.predictor]


def report_task(args: argparse.Namespace, task: str, cells: dict[str, dict[tuple[str, int], dict]]) -> None:
    """Print one task's table per predictor (``cells``: predictor -> (scene, seed) -> result) and, for several,
    their comparison; write them where ``--json`` / ``--out`` say (one file per predictor, plus the comparison)."""
    from st_sim.apps.evaluate import aggregate, compare, comparison_table, file_label, markdown_table

    several = len(cells) > 1
    for name, per_cell in cells.items():
        result = aggregate(task, name, per_cell)
        result["momentary_protocol"] = "from-8" if args.momentary_from_8 else "own-2-frame-windows"
        table = markdown_table(result)
        print(table + "\n")
        write_outputs(args, task, file_label(name) if several else None, result, table)
    if several:
        comparison = compare(task, cells)
        table = comparison_table(comparison)
        print(table + "\n")
        write_outputs(args, task, "comparison", comparison, table)


def write_outputs(args: argparse.Namespace, task: str, suffix: str | None, data: dict, table: str) -> None:
    """``--json FILE`` -> FILE (``FILE_<suffix>.json`` with a suffix); ``--out DIR`` -> ``<task>.json`` and
    ``<task>.md`` (``<task>_<suffix>.*``)."""
    if args.json:
        path = Path(args.json)
        if suffix is not None:
            path = path.with_name(f"{path.stem}_{suffix}{path.suffix or '.json'}")
        write_json_atomic(path, data)
        print(f"wrote {path}")
    if args.out:
        stem = task if suffix is None else f"{task}_{suffix}"
        write_json_atomic(Path(args.out) / f"{stem}.json", data)
        write_text_atomic(Path(args.out) / f"{stem}.md", table + "\n")
        print(f"wrote {args.out}/{stem}.json and {stem}.md")


def run_demo(args: argparse.Namespace) -> int:
    """Run the embedded default: a simulated crossing with an ego and the shipped predictor."""
    from st_sim.apps.demo import run_demo as demo

    demo(steps=args.steps, rerun_path=args.rerun, seed=args.seed)
    return 0


def plot_window(task: str, scene_name: str, step: int, predictor: str, out: str | Path, runs: str = "runs",
                root: str | None = None) -> Path:
    """PNG of one test window: photo, map overlay, histories, futures, anchors before/after adaptation, truth."""
    from predictor.registry import make_predictor
    from replays.scenes import load_scene
    from replays.windows import load_windows
    from st_sim.plot import plot_prediction

    windows = load_windows(task, scene_name, "test", root)
    if not 0 <= step < windows.num_groups:
        raise CliError(f"--step {step}: must be a window index in 0..{windows.num_groups - 1} for {scene_name}")
    keep = windows.group == step
    scene = load_scene(scene_name, root)
    model = make_predictor(predictor, task, scene_name, root, runs)
    num_samples = TASKS[task]["num_samples"]
    if hasattr(model, "predict_detailed"):
        detail = model.predict_detailed(windows.obs[keep], windows.group[keep], scene, num_samples)
        futures, prototype, adapted = detail.futures, detail.prototype_anchors, detail.adapted_anchors
    else:
        futures = model.predict(windows.obs[keep], windows.group[keep], scene, num_samples)
        prototype = adapted = None
    frame = int(windows.frame[keep][0])
    return plot_prediction(scene, windows.obs[keep], futures, out, gt_m=windows.fut[keep],
                           prototype_anchors_m=prototype, adapted_anchors_m=adapted,
                           title=f"{scene_name} {task}, window {step} (frame {frame}), {predictor}")


def run_plot(args: argparse.Namespace) -> int:
    check_writable(Path(args.out).parent)
    print(f"wrote {plot_window(args.task, args.scene, args.step, args.predictor, args.out, args.runs, args.data_root)}")
    return 0


README_FIGURES = (("zara1", 120), ("eth", 30))  # (scene, test window) of the figures the README shows


def run_figures(args: argparse.Namespace) -> int:
    """Regenerate the README's figures with the shipped stochastic models."""
    check_writable(Path(args.out))
    for scene, step in README_FIGURES:
        path = plot_window("stochastic", scene, step, "singular", Path(args.out) / f"{scene}_window{step}.png",
                           root=args.data_root)
        print(f"wrote {path}")
    return 0


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON through a temp file and a rename, so a crash never leaves half a file."""
    write_text_atomic(path, strict_json.dumps(data, indent=1))


COMMANDS = {"evaluate": run_evaluate, "demo": run_demo, "plot": run_plot, "figures": run_figures,
            "navigate": navigation_cli.run, "reactive-validate": reactive_validate.run,
            "benchmark": benchmark_cli.run_benchmark_command, "leaderboard": benchmark_cli.run_leaderboard_command,
            "episode": episode_replay.run, "verify": episode_replay.run_verify}


def build_parser() -> argparse.ArgumentParser:
    prog = "stcrowd" if Path(sys.argv[0]).name == "stcrowd" else "python -m st_sim"
    parser = argparse.ArgumentParser(prog=prog, description=__doc__)
    add_debug_flag(parser)
    commands = parser.add_subparsers(dest="command", required=True)

    evaluate = commands.add_parser("evaluate", help="score predictors on a benchmark task's test windows")
    evaluate.add_argument("--task", choices=[*TASKS, "all"], default="stochastic",
                          help="benchmark task, or all five (default: stochastic)")
    evaluate.add_argument("--predictor", nargs="+", default=["cvm-s"],
                          help="cvm | cvm-s | linear | singular | a plug-in package.module:name | checkpoint file or "
                               "folder; several: a table each, then one comparing them on the same windows, each "
                               "against the first (default: cvm-s)")
    evaluate.add_argument("--scenes", nargs="+", default=None,
                          help="scenes (eth hotel univ zara1 zara2) or domain pairs (A2B ...); default: all")
    evaluate.add_argument("--momentary-from-8", action="store_true",
                          help="momentary task: score the 8-frame protocol's samples on their last 2 frames "
                               "(default: the loader's own 2-frame windows)")
    evaluate.add_argument("--json", default=None, metavar="FILE",
                          help="also write the results to this JSON file (one task); several predictors: "
                               "FILE_<predictor>.json each and FILE_comparison.json")
    evaluate.add_argument("--out", default=None, metavar="DIR",
                          help="write <task>.json and <task>.md into this folder; several predictors: "
                               "<task>_<predictor>.json/.md each and <task>_comparison.json/.md")
    evaluate.add_argument("--seeds", type=int, nargs="+", default=[0],
                          help="singular: training seeds; each row is the mean ± sd over them (default: 0)")
    evaluate.add_argument("--runs", default="runs",
                          help="singular: training folder <task>/<scene>/seed<k>/ (default: runs); missing models "
                               "are trained there, seed 0 falls back to the shipped checkpoint where one exists")
    evaluate.add_argument("--no-shipped", action="store_true",
                          help="singular: train seed 0 into --runs too instead of using the shipped checkpoints")
    evaluate.add_argument("--no-train", action="store_true",
                          help="singular: fail instead of training missing checkpoints (default: train them)")
    add_grid_arguments(evaluate)
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
    plot.add_argument("--predictor", default="singular",
                      help="predictor name, plug-in package.module:name or checkpoint (default: singular)")
    plot.add_argument("--runs", default="runs", help="checkpoint folder for singular (default: runs)")
    plot.add_argument("--out", default="stcrowd_plot.png", help="PNG path (default: stcrowd_plot.png)")
    plot.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")

    figures = commands.add_parser("figures", help="regenerate the README's figures (shipped stochastic models)")
    figures.add_argument("--out", default="figures", help="folder for the PNGs (default: figures; the README's "
                         "copies live in docs/)")
    figures.add_argument("--data-root", default=None, help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")

    navigation_cli.add_parser(commands)
    benchmark_cli.add_parsers(commands)
    episode_replay.add_parser(commands)
    episode_replay.add_verify_parser(commands)
    reactive_validate.add_parser(commands)
    demo = commands.add_parser("demo", help="simulated crossing with an ego robot and predictions (no data needed)")
    demo.add_argument("--steps", type=positive_int, default=150,
                      help="step budget of 0.4 s env steps; whole episodes run until it is used (default: 150)")
    demo.add_argument("--rerun", default="stcrowd_demo.rrd", help="Rerun recording path (default: stcrowd_demo.rrd)")
    demo.add_argument("--seed", type=int, default=0, help="episode seed (default: 0)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded(COMMANDS[args.command], args)
