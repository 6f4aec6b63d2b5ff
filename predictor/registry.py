"""Turn a predictor name (cvm, cvm-s, linear, singular, or a checkpoint path) into a predictor per task/scene."""

from __future__ import annotations

from pathlib import Path

from predictor.baselines import ConstantVelocity, ConstantVelocitySampler, LinearFit
from predictor.protocol import Predictor
from replays.constants import TASKS
from replays.windows import load_windows

PREDICTOR_NAMES = ("cvm", "cvm-s", "linear", "singular")
RUNS_DIR = "runs"  # trained checkpoints: runs/<task>/<scene>/best.pt


def make_predictor(name: str, task: str, scene: str, root=None, runs_dir: str = RUNS_DIR,
                   train_missing: bool = False, progress: bool = True) -> Predictor:
    """The predictor ``name`` prepared for one task and scene (or domain pair).

    ``cvm-s`` fits its heading noise on that task's training split. ``singular`` uses
    ``runs_dir/<task>/<scene>/best.pt``. If that is missing, ``train_missing`` trains it (resuming an
    interrupted run); otherwise the shipped checkpoint is used where one exists (stochastic
    leave-one-out). Any other value is a checkpoint file, or a folder holding ``<task>/<scene>/best.pt``.
    """
    if name == "cvm":
        return ConstantVelocity()
    if name == "linear":
        return LinearFit()
    if name == "cvm-s":
        sampler = ConstantVelocitySampler()
        train = load_windows(task, scene, "train", root)
        sampler.fit_sigma(train.obs, train.fut, TASKS[task]["num_samples"])
        return sampler
    from predictor.checkpoint import load, load_pretrained, pretrained_manifest  # torch only when needed

    if name == "singular":
        checkpoint = Path(runs_dir) / task / scene / "best.pt"
        if not checkpoint.is_file() and train_missing:
            from predictor.train import TrainConfig, main

            main(TrainConfig(task=task, scene=scene, out=str(checkpoint.parent), data_root=root, progress=progress))
        if checkpoint.is_file():
            return load(checkpoint, task=task)
        if f"{task}/{scene}" in pretrained_manifest()["checkpoints"]:
            return load_pretrained(f"{task}/{scene}")
        raise FileNotFoundError(f"no checkpoint for {task}/{scene} at {checkpoint}; pass --train-missing to "
                                f"train it, or `python -m predictor train --task {task} --scene {scene} "
                                f"--out {checkpoint.parent}`")
    path = Path(name)
    if path.is_dir():
        path = path / task / scene / "best.pt"
    if not path.is_file():
        raise FileNotFoundError(
            f"predictor {name!r}: not one of {', '.join(PREDICTOR_NAMES)} and no checkpoint at {path}"
        )
    return load(path, task=task)
