"""Train a SingularTrajectory model for one task and scene (or domain pair); reads top to bottom.

    python -m predictor train --task stochastic --scene zara1 --out runs/stochastic/zara1
"""

from __future__ import annotations

import json
import math
import os
import random
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from predictor.anchors import BEND_SHAPES, OFF_IMAGE_MODES, prototype_anchors
from predictor.checkpoint import model_state, read_checkpoint, save_atomic
from predictor.config_check import check_config
from predictor.devices import resolve_device
from predictor.model import ModelConfig, SingularTrajectory, window_batches
from predictor.normalize import SLOW_SPEED_M, agent_frames
from predictor.refiner import SAMPLERS, Refiner
from predictor.singular_space import fit_singular_space
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.constants import TASKS
from replays.data_root import data_root, expected_sums
from replays.scenes import load_scene, scene_of_recording
from replays.windows import Windows, load_windows, split_files
from st_sim.command_line import check_writable

# Single-sample tasks (deterministic, domain; S = 1): one mean anchor must follow each agent's own speed, so
# more agents are speed-scaled than for S = 20 (both settings measured: RESULTS.md).
SINGLE_SAMPLE_SLOW_SPEED_M = 0.1  # slow-population threshold for S = 1 [m per step]
SINGLE_SAMPLE_SCALE_FLOOR_M = 0.05  # slow agents' speed-scale floor for S = 1 [m per step]
# Deterministic leave-one-out models instead take the static threshold of the authors' per-scene configs [m per
# step], static agents unscaled: better validation FDE than the rule above on four of five scenes (RESULTS,
# component swaps). UNIV's 0 leaves in the static population only agents without a heading (normalize).
DETERMINISTIC_STATIC_M = {"eth": 0.021, "hotel": 0.014, "univ": 0.0, "zara1": 0.015, "zara2": 0.014}
# Epochs by the task's number of samples: S > 1 models train 16 epochs (validation FDE lower than after 6 on
# every stochastic scene it lengthens: RESULTS, issue 31); S = 1 models keep 6, which a minute on one core allows.
MULTI_SAMPLE_EPOCHS = 16
SINGLE_SAMPLE_EPOCHS = 6
LR_SCHEDULES = ("cosine", "step")
TRAIN_SUMMARY = "train.json"  # written when a run has finished: selected epoch, per-epoch history, wall time


@dataclass(frozen=True)
class TrainConfig:
    task: str = "stochastic"
    """stochastic | deterministic | momentary | fewshot | domain"""
    scene: str = "zara1"
    """test scene (leave-one-out) or domain pair such as A2B"""
    out: str = "runs/stochastic/zara1/seed0"
    """output folder: last.pt (resumable state), best.pt (selected on validation FDE), train.json (when done)"""
    epochs: int | None = None
    """passes over the training windows (more when needed to reach ``min_steps``); None: ``MULTI_SAMPLE_EPOCHS``
    for tasks with S > 1, ``SINGLE_SAMPLE_EPOCHS`` for S = 1"""
    min_steps: int = 300
    """least number of optimiser steps: small training sets (few-shot, domain sources) get more epochs"""
    batch_agents: int = 512
    """agents per batch (whole windows are kept together)"""
    lr: float = 1e-3
    """AdamW peak learning rate"""
    weight_decay: float = 1e-4
    """AdamW weight decay"""
    warmup_epochs: float = 0.5
    """linear warm-up of the learning rate over this many epochs (0: none), then ``lr_schedule``"""
    lr_schedule: str = "cosine"
    """"cosine": decay to zero over the epochs after the warm-up; "step": constant, multiplied by ``lr_gamma`` at
    the start of each of ``lr_stages`` equal parts of the run (the authors' schedule: 256 epochs halved every 64)"""
    lr_stages: int = 4
    """"step" schedule: equal parts of the run, each at ``lr_gamma`` times the rate of the one before"""
    lr_gamma: float = 0.5
    """"step" schedule: learning-rate factor from one part to the next"""
    clip_grad: float = 1.0
    """gradient-norm clipping"""
    objective: str = "e2e"
    """e2e: best-of-S ADE (+ FDE) through the unrolled DDIM chain; eps: the paper's epsilon MSE"""
    fde_weight: float = 1.0
    """e2e loss = min-over-S ADE + fde_weight * min-over-S FDE"""
    k: int = 4
    """Singular-space dimension K"""
    dim: int = 256
    """width of the refiner's context transformer"""
    denoiser_dim: int = 128
    """width of the refiner's denoiser MLP"""
    layers: int = 1
    """interaction transformer layers of the refiner"""
    dropout: float = 0.0
    """dropout in the refiner's interaction layers while training"""
    steps: int = 10
    """M, DDIM steps"""
    sampler: str = "x0-cosine"
    """the refiner's diffusion (``ModelConfig.sampler``): "x0-cosine" or the authors' "eps-linear" """
    adapt_anchors: bool = True
    """map-adaptive anchors (False = fixed prototypes)"""
    anchor_off_image: str = "pull"
    """anchor end points off the scene image: "pull" onto the nearest walkable pixel, or "keep" (agents leave view)"""
    anchor_bend: str = "ramp"
    """anchor bending shape: "ramp" (linear offset over time) or "scale" (about the last observed point)"""
    adapt_output: bool = True
    """at inference, bend the refined futures onto the map as the anchors are (training is unaffected)"""
    output_on_map: bool = True
    """at inference, move predicted points still off the walkable map onto it (see ModelConfig.output_on_map)"""
    slow_speed_m: float | None = None
    """slow-population threshold [m per 0.4 s step]; None: DETERMINISTIC_STATIC_M of the scene for deterministic
    models, 0.1 for the other single-sample tasks (domain), 0.3 otherwise"""
    slow_scale_floor_m: float | None = None
    """0: slow agents unscaled; > 0: scaled by max(speed, this) [m per step]; None: 0.05 for single-sample tasks
    but deterministic, 0 otherwise"""
    mirror_paths: bool = False
    """fit the Singular spaces and prototype anchors on the training futures and their left/right mirror images
    (a laterally symmetric basis; the mean anchor of single-sample tasks then has no sideways drift)"""
    world_features: bool = True
    """world-frame inputs (centroid offset, velocity); False = orientation-invariant inputs"""
    zero_start: bool = True
    """the refiner's output layer starts at zero, so training starts from the anchors"""
    init_noise: float = 1.0
    """scale of the sampler's starting noise x_M (0 = a deterministic refinement chain)"""
    fixed_noise: bool = False
    """e2e training starts every chain from the sampler's fixed noise, the draw inference uses (the authors' code),
    instead of a fresh draw per agent and step"""
    stand_speed_m: float | None = None
    """inference only: slower agents [m per 0.4 s step] keep constant velocity; None: 0.05 for single-sample
    tasks, 0 (off) otherwise"""
    max_train_windows: int | None = None
    """use only the first N training windows (quick checks and tests); None = all"""
    seed: int = 0
    """seeds numpy, torch, python and the batch order"""
    threads: int = 1
    """torch CPU threads (1 is fastest on a shared 2-core machine)"""
    device: str = "auto"
    """where the refiner trains: auto (a CUDA GPU when torch sees one, else the CPU), cpu, cuda, cuda:N or mps; the
    checkpoint is the same file either way"""
    data_root: str | None = None
    """ETH/UCY folder (default: $STCROWD_DATA or the cache)"""
    progress: bool = True
    """show progress bars"""
    ema_decay: float = 0.0
    """0: validate and keep the trained weights; in (0, 1): validate and keep their exponential moving average
    over the optimiser steps (this decay per step), which varies less from run to run [-]"""
    select_tolerance_m: float = 0.002
    """a later epoch replaces the selected one unless its validation FDE is worse by more than this [m]
    (near-ties go to the later epoch, so float differences between machines do not flip the choice)"""

    def __post_init__(self) -> None:
        check_config(self, {
            "epochs": (1, 10_000), "min_steps": (0, 10**7), "batch_agents": (2, 10**6), "lr": (1e-8, 1.0),
            "weight_decay": (0.0, 1.0), "warmup_epochs": (0.0, 10_000.0), "clip_grad": (1e-6, 1e6),
            "fde_weight": (0.0, 100.0), "k": (1, 24), "dim": (4, 4096), "denoiser_dim": (4, 4096),
            "steps": (1, 1000), "layers": (1, 16), "dropout": (0.0, 0.9), "lr_stages": (1, 10_000),
            "lr_gamma": (1e-6, 1.0),
            "init_noise": (0.0, 100.0), "seed": (0, 2**31 - 1), "threads": (1, 256),
            "select_tolerance_m": (0.0, 10.0), "max_train_windows": (1, 10**9), "ema_decay": (0.0, 0.99999),
            "slow_speed_m": (0.0, 10.0), "slow_scale_floor_m": (0.0, 10.0), "stand_speed_m": (0.0, 10.0),
        }, choices={"task": tuple(TASKS), "objective": ("e2e", "eps"), "anchor_off_image": OFF_IMAGE_MODES,
                    "anchor_bend": BEND_SHAPES, "lr_schedule": LR_SCHEDULES, "sampler": SAMPLERS})
        if self.dim % 4:
            raise ValueError(f"TrainConfig.dim={self.dim}: must be a multiple of the 4 attention heads")


COSMETIC_FIELDS = ("out", "threads", "device", "data_root", "progress")  # change neither the model nor the data


def model_fields(cfg: TrainConfig) -> dict:
    """The configuration without its cosmetic fields: what a checkpoint records and a resume must match."""
    return {k: v for k, v in asdict(cfg).items() if k not in COSMETIC_FIELDS}


def with_task_defaults(cfg: TrainConfig) -> TrainConfig:
    """``cfg`` with its task-dependent defaults filled in (``epochs``), as a run records them."""
    if cfg.epochs is not None:
        return cfg
    single = TASKS[cfg.task]["num_samples"] == 1
    return replace(cfg, epochs=SINGLE_SAMPLE_EPOCHS if single else MULTI_SAMPLE_EPOCHS)


def lr_factor(step: int, cfg: TrainConfig, per_epoch: int, epochs: int) -> float:
    """Learning rate of optimiser step ``step`` (0-based) as a share of ``cfg.lr``, for a run of ``epochs`` epochs of
    ``per_epoch`` steps: the linear warm-up, then ``cfg.lr_schedule`` (the step schedule moves at epoch ends)."""
    warmup = max(1, int(cfg.warmup_epochs * per_epoch))
    ramp = min(1.0, (step + 1) / warmup)
    if cfg.lr_schedule == "step":
        return ramp * cfg.lr_gamma ** (step // per_epoch * cfg.lr_stages // epochs)
    total = epochs * per_epoch
    return min(ramp, 0.5 * (1 + math.cos(math.pi * min(1.0, max(0, step - warmup) / max(1, total - warmup)))))


def split_scenes(windows: Windows, root) -> tuple[list, np.ndarray]:
    """Scenes of a split's recordings and each sample's index into that list."""
    names = sorted({scene_of_recording(r).name for r in np.unique(windows.recording)})
    scenes = [load_scene(n, root) for n in names]
    index = np.array([names.index(scene_of_recording(r).name) for r in windows.recording], np.int64)
    return scenes, index


def fit_model(cfg: TrainConfig, train: Windows) -> SingularTrajectory:
    """Singular spaces, prototype anchors and coefficient scales from the training windows; fresh refiner."""
    task = TASKS[cfg.task]
    single = task["num_samples"] == 1
    per_scene = DETERMINISTIC_STATIC_M.get(cfg.scene) if cfg.task == "deterministic" else None
    floor_m = cfg.slow_scale_floor_m
    if floor_m is None:
        floor_m = SINGLE_SAMPLE_SCALE_FLOOR_M if single and per_scene is None else 0.0
    slow_speed_m = cfg.slow_speed_m
    if slow_speed_m is None:
        slow_speed_m = per_scene if per_scene is not None else SINGLE_SAMPLE_SLOW_SPEED_M if single else SLOW_SPEED_M
    shared = {f.name: getattr(cfg, f.name) for f in fields(ModelConfig) if hasattr(cfg, f.name)}  # same-named
    model_cfg = ModelConfig(**{**shared, "obs_len": task["obs_len"], "num_samples": task["num_samples"],
                               "slow_speed_m": slow_speed_m, "slow_scale_floor_m": floor_m, "noise_seed": cfg.seed})
    frames = agent_frames(train.obs, model_cfg.scale_by_speed, model_cfg.slow_speed_m, model_cfg.slow_scale_floor_m)
    futures = frames.to_agent(train.fut.astype(np.float64))
    spaces, anchors, coef_scale, residual_scale = [], [], [], []
    needed = max(cfg.k, model_cfg.num_samples)  # paths to fit a K-dimensional space and S anchors
    for side, population in (("not slower", ~frames.slow), ("slower", frames.slow)):  # 0 = moving, 1 = slow
        paths = futures[population]  # (n, 12, 2) agent frame: x ahead, y to the left
        if len(paths) < needed:
            raise TrainingError(f"{cfg.task}/{cfg.scene}: only {len(paths)} training agents are {side} than "
                                f"slow_speed_m={slow_speed_m} m per step, at least {needed} are needed to fit their "
                                "Singular space and anchors: change slow_speed_m or train on more windows")
        if cfg.mirror_paths:
            paths = np.concatenate([paths, paths * np.array([1.0, -1.0])])
        space = fit_singular_space(paths, cfg.k)
        coefs = space.project(paths)
        protos = prototype_anchors(coefs, model_cfg.num_samples, cfg.seed)
        nearest = np.linalg.norm(coefs[:, None] - protos[None], axis=-1).min(axis=1)
        spaces.append(space)
        anchors.append(protos)
        coef_scale.append(coefs.std())
        residual_scale.append(np.sqrt((nearest**2).mean() / cfg.k))
    return SingularTrajectory(model_cfg, spaces, np.stack(anchors), np.array(coef_scale), np.array(residual_scale),
                              Refiner(model_cfg.refiner_config()))


def split_tensors(model: SingularTrajectory, windows: Windows, root) -> dict[str, torch.Tensor]:
    """All inputs of a split at once (anchors adapted here, once), plus the agent-frame truth in metres."""
    scenes, index = split_scenes(windows, root)
    inputs = model.prepare(windows.obs, windows.group, scenes, index)
    tensors = model.tensors(inputs)
    local = inputs.frames.to_agent(windows.fut.astype(np.float64))  # (N, 12, 2) agent frame, speed units
    truth = local * inputs.frames.scale_m[:, None, None]
    tensors["truth_m"] = torch.from_numpy(truth.astype(np.float32))  # (N, 12, 2) agent-frame axes, metres
    coefs = np.zeros((len(windows), model.cfg.k))
    for p, space in enumerate(model.spaces):
        mask = inputs.population == p
        coefs[mask] = space.project(local[mask])
    residual = (coefs[:, None] - inputs.anchors) / model.residual_scale[inputs.population][:, None, None]
    tensors["residual"] = torch.from_numpy(residual.astype(np.float32))  # (N, S, K) clean x0 for eps training
    return tensors


def rollout(model: SingularTrajectory, t: dict[str, torch.Tensor], idx: torch.Tensor, noise_seed: int | None,
            steps: int | None = None) -> torch.Tensor:
    """Agent-frame predictions in metres (B, S, 12, 2) for samples ``idx`` through the full DDIM chain.

    ``noise_seed``: fresh starting noise per agent (training); None: the model's fixed sampler noise (inference,
    and training with ``fixed_noise``).
    """
    refiner = model.refiner
    anchors = t["anchors"][idx]
    ctx = refiner.context(t["history"][idx], anchors, t["group"][idx])
    if noise_seed is None:
        noise = model.sampler_noise().expand_as(anchors)
    else:
        generator = torch.Generator().manual_seed(noise_seed)
        noise = (model.cfg.init_noise * torch.randn(anchors.shape, generator=generator)).to(anchors.device)
    residual = refiner.sample(anchors, ctx, noise, steps)
    return model.paths_local(anchors, residual, t["population"][idx]) * t["scale_m"][idx][:, None, None, None]


def best_of_s(pred_m: torch.Tensor, truth_m: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-agent min-over-S ADE and FDE (B,) in metres."""
    dist = (pred_m - truth_m[:, None]).norm(dim=-1)  # (B, S, 12)
    return dist.mean(-1).min(1).values, dist[..., -1].min(1).values


@torch.no_grad()
def validate(model: SingularTrajectory, t: dict[str, torch.Tensor], batch_agents: int) -> tuple[float, float]:
    """Mean best-of-S ADE and FDE in metres over a split."""
    model.refiner.eval()
    ade, fde = [], []
    for idx in window_batches(t["group"], batch_agents, None):
        a, f = best_of_s(rollout(model, t, idx, noise_seed=None), t["truth_m"][idx])
        ade.append(a)
        fde.append(f)
    return float(torch.cat(ade).mean()), float(torch.cat(fde).mean())


def data_checksums(cfg: TrainConfig, root: Path) -> dict[str, str]:
    """SHA-256 of every file of the training and validation splits (from the project's sums)."""
    sums = expected_sums()
    files = split_files(cfg.task, cfg.scene, "train", root) + split_files(cfg.task, cfg.scene, "val", root)
    return {str(f.relative_to(root)): sums.get(str(f.relative_to(root)), "unlisted") for f in files}


class WeightAverage:
    """Exponential moving average of a module's parameters over the optimiser steps (off when decay is 0)."""

    def __init__(self, module: torch.nn.Module, decay: float):
        self.module, self.decay = module, decay
        self.shadow = {name: p.detach().clone() for name, p in module.named_parameters()} if decay > 0 else {}

    @torch.no_grad()
    def update(self) -> None:
        """Fold the module's current parameters into the average."""
        for name, p in self.module.named_parameters():
            if name in self.shadow:
                self.shadow[name].mul_(self.decay).add_(p.detach(), alpha=1 - self.decay)

    @contextmanager
    def applied(self) -> Iterator[None]:
        """The averaged parameters in the module inside the block, the trained ones again after it."""
        if not self.shadow:
            yield
            return
        trained = {name: p.detach().clone() for name, p in self.module.named_parameters()}
        with torch.no_grad():
            for name, p in self.module.named_parameters():
                p.copy_(self.shadow[name])
        try:
            yield
        finally:
            with torch.no_grad():
                for name, p in self.module.named_parameters():
                    p.copy_(trained[name])

    def state_dict(self) -> dict[str, torch.Tensor]:
        return dict(self.shadow)

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        for name, value in state.items():
            if name in self.shadow:
                self.shadow[name].copy_(value)


class TrainingError(RuntimeError):
    """A training run cannot start, resume or produce a checkpoint (the message says what to do)."""


def main(cfg: TrainConfig) -> Path:
    """Train one model; returns ``OUT/best.pt``. Resumes from ``OUT/last.pt``; writes ``OUT/train.json`` last."""
    # ---- seeding, threads, output folder (checked before any work)
    cfg = with_task_defaults(cfg)
    random.seed(cfg.seed)
    np.random.seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.threads)
    device = resolve_device(cfg.device)
    out = Path(cfg.out)
    check_writable(out)  # before any work
    run_name = f"{cfg.task}__{cfg.scene}__seed{cfg.seed}"

    # ---- data: windows -> model statistics -> precomputed tensors (obs T_obs, pred 12 steps of 0.4 s)
    root = data_root(cfg.data_root)
    train = load_windows(cfg.task, cfg.scene, "train", root)
    if cfg.max_train_windows is not None:
        train = train.subset(train.group < cfg.max_train_windows)
    val = load_windows(cfg.task, cfg.scene, "val", root)
    model = fit_model(cfg, train).to(device)
    t_train, t_val = ({name: tensor.to(device) for name, tensor in split_tensors(model, windows, root).items()}
                      for windows in (train, val))
    checksums = data_checksums(cfg, root)
    recorded = {"train_config": model_fields(cfg), "data_checksums": checksums}  # what every checkpoint carries

    # ---- optimiser and schedule: AdamW, linear warm-up then cosine decay or steps (per batch)
    refiner = model.refiner
    resume = read_checkpoint(out / "last.pt") if (out / "last.pt").is_file() else None
    if resume is not None:  # an interrupted run: same data -> same spaces and anchors; restore the weights
        defaults = model_fields(TrainConfig())  # a field newer than the run counts as its default
        changed = sorted(k for k, v in recorded["train_config"].items()
                         if resume["train_config"].get(k, defaults[k]) != v)
        if resume["data_checksums"] != checksums:
            changed.append("training data")
        if changed:
            raise TrainingError(f"{out / 'last.pt'}: an unfinished run with other settings ({', '.join(changed)}); "
                                f"use another --out, or delete {out} to throw that progress away")
        refiner.load_state_dict(resume["model"]["weights"])
    optimizer = torch.optim.AdamW(refiner.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    per_epoch = len(window_batches(t_train["group"], cfg.batch_agents, None))
    epochs = max(cfg.epochs, math.ceil(cfg.min_steps / per_epoch))
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda i: lr_factor(i, cfg, per_epoch, epochs))
    start_epoch, best, history = 0, {"fde": float("inf")}, []
    average = WeightAverage(refiner, cfg.ema_decay)
    if resume is not None:
        optimizer.load_state_dict(resume["optimizer"])
        schedule.load_state_dict(resume["schedule"])
        average.load_state_dict(resume.get("average", {}))
        start_epoch, best, history = resume["epoch"] + 1, resume["best"], resume["history"]
        print(f"{run_name}: resuming after epoch {start_epoch}")

    # ---- loop: epochs -> batches -> loss -> clip -> step; validation FDE picks best.pt
    generator = torch.Generator()
    began = time.perf_counter() - (history[-1]["wall_s"] if history else 0.0)  # wall time counts earlier epochs
    for epoch in range(start_epoch, epochs):
        refiner.train()
        generator.manual_seed(cfg.seed * 1000 + epoch)
        losses = []
        bar = tqdm(window_batches(t_train["group"], cfg.batch_agents, generator), desc=f"{run_name} epoch {epoch + 1}/"
                   f"{epochs}", leave=False, disable=not cfg.progress)
        for step, idx in enumerate(bar):
            if cfg.objective == "e2e":
                noise_seed = None if cfg.fixed_noise else epoch * 100_000 + step
                ade, fde = best_of_s(rollout(model, t_train, idx, noise_seed=noise_seed),
                                     t_train["truth_m"][idx])
                loss = ade.mean() + cfg.fde_weight * fde.mean()
            else:
                anchors = t_train["anchors"][idx]
                ctx = refiner.context(t_train["history"][idx], anchors, t_train["group"][idx])
                loss = refiner.eps_loss(t_train["residual"][idx], anchors, ctx, generator)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(refiner.parameters(), cfg.clip_grad)
            lr = optimizer.param_groups[0]["lr"]  # the rate of this step, for the epoch's record
            optimizer.step()
            schedule.step()
            average.update()
            losses.append(loss.item())
            bar.set_postfix(loss=f"{np.mean(losses[-20:]):.4f}")
        with average.applied():  # validation and best.pt see the averaged weights (when averaging)
            val_ade, val_fde = validate(model, t_val, cfg.batch_agents)
            if math.isfinite(val_fde) and val_fde <= best["fde"] + cfg.select_tolerance_m:  # near-ties: later epoch
                best = {"fde": val_fde, "ade": val_ade, "epoch": epoch + 1}
                save_atomic({"model": model_state(model), **recorded, "best": best}, out / "best.pt")
        record = {"epoch": epoch + 1, "train/loss": float(np.mean(losses)), "train/last_lr": lr,
                  "val/ade_m": val_ade, "val/fde_m": val_fde, "wall_s": time.perf_counter() - began}
        history.append(record)
        if epochs <= 20 or (epoch + 1) % (epochs // 10) == 0 or epoch + 1 == epochs:  # at most ~20 lines
            print(f"{run_name} epoch {epoch + 1}: loss {record['train/loss']:.4f}  val ADE {val_ade:.4f}  "
                  f"FDE {val_fde:.4f}  ({record['wall_s']:.0f} s)")
        save_atomic({"model": model_state(model), **recorded, "best": best, "history": history, "epoch": epoch,
                     "epochs": epochs, "optimizer": optimizer.state_dict(), "schedule": schedule.state_dict(),
                     "average": average.state_dict()}, out / "last.pt")

    # ---- the run's summary, written last: its presence marks a finished run
    if not (out / "best.pt").is_file():
        raise TrainingError(f"{run_name}: no epoch gave a finite validation FDE, so no {out / 'best.pt'} was written")
    summary = {**recorded, "best": best, "epochs": epochs, "history": history,
               "wall_s": history[-1]["wall_s"] if history else 0.0}
    write_text_atomic(out / TRAIN_SUMMARY, strict_json.dumps(summary, indent=1))
    return out / "best.pt"


def finished(out: str | os.PathLike) -> bool:
    """Whether a training run in ``out`` has finished (its summary is written after the last epoch)."""
    return (Path(out) / TRAIN_SUMMARY).is_file()


def read_summary(out: str | os.PathLike) -> dict:
    """A finished run's summary: train_config, data_checksums, best (epoch, val ADE/FDE), epochs, history, wall_s."""
    return json.loads((Path(out) / TRAIN_SUMMARY).read_text())


def train_job(**config) -> None:
    """Grid entry point (``st_sim.apps.grid``): train with ``TrainConfig(**config)``."""
    main(TrainConfig(**config))


def config_for(task: str, scene: str, out: str, **overrides) -> TrainConfig:
    """Default configuration of a task/scene with optional overrides."""
    return replace(TrainConfig(task=task, scene=scene, out=out), **overrides)
