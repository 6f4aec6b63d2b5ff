"""Turn a predictor name (cvm, cvm-s, linear, singular, a plug-in ``package.module:name`` or a checkpoint path)
into a predictor per task/scene.

Trained SingularTrajectory checkpoints live in ``runs/<task>/<scene>/seed<k>/best.pt``; a run counts once it
has finished (``train.json`` written). Where none has, seed 0 falls back to the shipped checkpoint of that
task and scene, if one ships.
"""

from __future__ import annotations

from pathlib import Path

from predictor.baselines import ConstantVelocity, ConstantVelocitySampler, LinearFit
from predictor.plugins import is_plugin_spec, load_plugin
from predictor.protocol import Predictor
from replays.constants import TASKS
from replays.windows import load_windows

PREDICTOR_NAMES = ("cvm", "cvm-s", "linear", "singular")
RUNS_DIR = "runs"


class MissingCheckpointError(FileNotFoundError):
    """No trained or shipped checkpoint exists for a task, scene and seed (the message says how to train it)."""


def run_dir(runs_dir: str | Path, task: str, scene: str, seed: int) -> Path:
    """Training folder of one model: ``runs_dir/<task>/<scene>/seed<seed>``."""
    return Path(runs_dir) / task / scene / f"seed{seed}"


def resolve_checkpoint(task: str, scene: str, seed: int = 0, runs_dir: str | Path = RUNS_DIR,
                       use_shipped: bool = True) -> str | None:
    """Which checkpoint a singular predictor uses: a finished run's ``best.pt``, else ``"shipped:<task>/<scene>"``
    for seed 0 when one ships (and ``use_shipped``), else None (it must be trained)."""
    from predictor.checkpoint import pretrained_manifest
    from predictor.train import finished

    folder = run_dir(runs_dir, task, scene, seed)
    if finished(folder):
        return str(folder / "best.pt")
    if use_shipped and seed == 0 and f"{task}/{scene}" in pretrained_manifest()["checkpoints"]:
        return f"shipped:{task}/{scene}"
    return None


def load_checkpoint_spec(spec: str, task: str | None = None) -> Predictor:
    """A model from ``resolve_checkpoint``'s answer (a file or ``"shipped:<name>"``)."""
    from predictor.checkpoint import load, load_pretrained

    return load_pretrained(spec.removeprefix("shipped:")) if spec.startswith("shipped:") else load(spec, task=task)


def make_predictor(name: str, task: str, scene: str, root=None, runs_dir: str | Path = RUNS_DIR, seed: int = 0,
                   train_missing: bool = False, progress: bool = True) -> Predictor:
    """The predictor ``name`` prepared for one task and scene (or domain pair).

    ``cvm-s`` fits its heading noise on that task's training split. ``singular`` uses the checkpoint that
    ``resolve_checkpoint`` names; if there is none, ``train_missing`` trains it (resuming an interrupted
    run), otherwise ``MissingCheckpointError`` says how. ``package.module:name`` is a plug-in (``predictor.plugins``:
    the factory gets the task, scene, training and validation windows and data root, and ``seed`` if it takes
    one). Any other value is a checkpoint file, or a folder holding ``<task>/<scene>/seed<seed>/best.pt``.
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
    if name == "singular":
        spec = resolve_checkpoint(task, scene, seed, runs_dir)
        if spec is None and train_missing:
            from predictor.train import TrainConfig, main

            main(TrainConfig(task=task, scene=scene, seed=seed, out=str(run_dir(runs_dir, task, scene, seed)),
                             data_root=None if root is None else str(root), progress=progress))
            spec = resolve_checkpoint(task, scene, seed, runs_dir)
        if spec is None:
            folder = run_dir(runs_dir, task, scene, seed)
            raise MissingCheckpointError(
                f"no checkpoint for {task}/{scene} seed {seed} (none in {folder}, none shipped); train it with "
                f"`python -m predictor train --task {task} --scene {scene} --seed {seed} --out {folder}`, or let "
                "`python -m st_sim evaluate` train it (its default)")
        return load_checkpoint_spec(spec, task)
    if is_plugin_spec(name):
        return load_plugin(name, task, scene, root, seed)
    path = Path(name)
    if path.is_dir():
        path = run_dir(path, task, scene, seed) / "best.pt"
    if not path.is_file():
        raise MissingCheckpointError(
            f"predictor {name!r}: not one of {', '.join(PREDICTOR_NAMES)}, not a plug-in package.module:name "
            f"and no checkpoint at {path}")
    return load_checkpoint_spec(str(path), task)
