"""``python -m predictor <command>``: train a SingularTrajectory model, evaluate a checkpoint."""

from __future__ import annotations

import argparse
from dataclasses import fields

from predictor.devices import DEVICE_HELP
from predictor.train import TrainConfig
from replays.constants import TASKS
from st_sim.command_line import add_debug_flag, positive_int, run_guarded


def run_train(args: argparse.Namespace) -> int:
    from predictor.train import main as train

    overrides = {f.name: getattr(args, f.name) for f in fields(TrainConfig) if getattr(args, f.name, None) is not None}
    overrides["progress"] = not args.quiet
    best = train(TrainConfig(**overrides))
    print(f"best checkpoint: {best}")
    return 0


def run_evaluate(args: argparse.Namespace) -> int:
    from predictor.checkpoint import load, read_checkpoint
    from st_sim.metrics import format_metric
    from st_sim.scoring import evaluate_offline

    state = read_checkpoint(args.checkpoint)
    task, scene = state["train_config"]["task"], args.scene or state["train_config"]["scene"]
    model = load(args.checkpoint)
    r = evaluate_offline(model, task, scene, steps=args.steps, root=args.data_root)
    print(f"{task}/{scene}: {r.samples} samples  ADE {format_metric(r.ade, '.4f')}  FDE {format_metric(r.fde, '.4f')}  "
          f"map-violation {format_metric(r.map_violation, '.2f', 100)}% "
          f"(GT {format_metric(r.gt_map_violation, '.2f', 100)}%)  "
          f"collisions {format_metric(r.collision_rate, '.2f', 100)}%  paper {r.paper_ade} / {r.paper_fde}  "
          f"({r.wall_s:.1f} s)")
    return 0


def run_export(args: argparse.Namespace) -> int:
    from predictor.export import export_checkpoint

    entry = export_checkpoint(args.checkpoint, args.name, args.data_root)
    print(f"{args.name}: {entry['file']} ({entry['size_bytes'] / 1e6:.2f} MB) test {entry['test']}")
    return 0


COMMANDS = {"train": run_train, "evaluate": run_evaluate, "export": run_export}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m predictor", description=__doc__)
    add_debug_flag(parser)
    commands = parser.add_subparsers(dest="command", required=True)
    defaults = TrainConfig()

    train = commands.add_parser("train", help="train one model; resumes from OUT/last.pt")
    train.add_argument("--task", choices=list(TASKS), default=defaults.task, help=f"(default: {defaults.task})")
    train.add_argument("--scene", default=defaults.scene,
                       help=f"test scene (leave-one-out) or domain pair like A2B (default: {defaults.scene})")
    train.add_argument("--out", required=True, help="output folder for last.pt and best.pt")
    train.add_argument("--epochs", type=int, help="training epochs (default: 16 for tasks with S > 1, 6 for S = 1)")
    train.add_argument("--lr-schedule", choices=["cosine", "step"],
                       help="learning rate after the warm-up: cosine decay to zero, or constant and multiplied by "
                            "--lr-gamma at each of --lr-stages equal parts of the run "
                            f"(default: {defaults.lr_schedule})")
    train.add_argument("--lr-stages", type=int, help=f"parts of the step schedule (default: {defaults.lr_stages})")
    train.add_argument("--lr-gamma", type=float,
                       help=f"learning-rate factor between parts of the step schedule (default: {defaults.lr_gamma})")
    train.add_argument("--warmup-epochs", type=float,
                       help=f"linear learning-rate warm-up, 0 = none (default: {defaults.warmup_epochs})")
    train.add_argument("--min-steps", type=int, help="least optimiser steps; small training sets get more epochs "
                       f"(default: {defaults.min_steps})")
    train.add_argument("--objective", choices=["e2e", "eps"],
                       help=f"training objective (default: {defaults.objective})")
    train.add_argument("--k", type=int, help=f"Singular-space dimension (default: {defaults.k})")
    train.add_argument("--steps", type=int, help=f"DDIM steps M (default: {defaults.steps})")
    train.add_argument("--sampler", choices=["x0-cosine", "eps-linear"],
                       help="the refiner predicts the clean residual under a cosine noise schedule, or the noise "
                            f"under the authors' linear betas (1e-4 to 5e-2) (default: {defaults.sampler})")
    train.add_argument("--fixed-anchors", dest="adapt_anchors", action="store_const", const=False,
                       help="use fixed prototype anchors (default: map-adaptive)")
    train.add_argument("--anchor-off-image", choices=["pull", "keep"],
                       help=f"anchor end points off the image (default: {defaults.anchor_off_image})")
    train.add_argument("--anchor-bend", choices=["ramp", "scale"],
                       help=f"anchor bending shape (default: {defaults.anchor_bend})")
    train.add_argument("--no-adapt-output", dest="adapt_output", action="store_const", const=False,
                       help="do not bend the refined futures onto the map at inference (default: bend them)")
    train.add_argument("--no-output-on-map", dest="output_on_map", action="store_const", const=False,
                       help="leave predicted points inside walls where the refiner put them (default: move those "
                            "deeper than 0.1 m onto the nearest walkable pixel)")
    train.add_argument("--mirror-paths", dest="mirror_paths", action="store_const", const=True,
                       help="fit the Singular spaces and anchors on the training futures and their left/right "
                            "mirror images (default: as recorded)")
    train.add_argument("--init-noise", type=float,
                       help=f"scale of the sampler's starting noise, 0 = a deterministic chain "
                            f"(default: {defaults.init_noise})")
    train.add_argument("--fixed-noise", dest="fixed_noise", action="store_const", const=True,
                       help="start every training chain from the sampler's fixed noise, the draw inference uses "
                            "(default: a fresh draw per agent and step)")
    train.add_argument("--stand-speed", dest="stand_speed_m", type=float,
                       help="agents whose last step is shorter [m per 0.4 s step] keep constant velocity at "
                            "inference (default: 0.05 for single-sample tasks, else off)")
    train.add_argument("--seed", type=int, help=f"random seed (default: {defaults.seed})")
    train.add_argument("--threads", type=int, help=f"torch threads (default: {defaults.threads})")
    train.add_argument("--device", help=f"where the refiner trains: {DEVICE_HELP} (default: {defaults.device})")
    train.add_argument("--data-root", help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    train.add_argument("--quiet", action="store_true", help="no progress bars")

    evaluate = commands.add_parser("evaluate", help="score a checkpoint on its task's test split")
    evaluate.add_argument("--checkpoint", required=True, help="best.pt or last.pt")
    evaluate.add_argument("--scene", help="test scene or pair (default: the one it was trained for)")
    evaluate.add_argument("--steps", type=positive_int, default=None,
                          help="DDIM steps at inference (default: as trained)")
    evaluate.add_argument("--data-root", help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    export = commands.add_parser("export", help="ship a checkpoint in predictor/pretrained/ (fp16 + manifest)")
    export.add_argument("--checkpoint", required=True, help="best.pt to ship")
    export.add_argument("--name", required=True, help="name for load_pretrained, e.g. stochastic/eth or universal")
    export.add_argument("--data-root", help="ETH/UCY folder (default: $STCROWD_DATA or the cache)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded(COMMANDS[args.command], args)
