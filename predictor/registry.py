"""Turn a predictor name (cvm, cvm-s, linear, singular, or a checkpoint path) into a predictor per task/scene."""

from __future__ import annotations

from pathlib import Path

from predictor.baselines import ConstantVelocity, ConstantVelocitySampler, LinearFit
from predictor.protocol import Predictor
from replays.constants import TASKS
from replays.windows import load_windows

PREDICTOR_NAMES = ("cvm", "cvm-s", "linear", "singular")


def make_predictor(name: str, task: str, scene: str, root=None) -> Predictor:
    """The predictor ``name`` prepared for one task and scene (or domain pair).

    ``cvm-s`` fits its heading noise on that task's training split; ``singular`` loads the shipped
    checkpoint for the task and scene; any other value is a checkpoint file, or a folder holding
    ``<task>/<scene>.pt``.
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
    from predictor.checkpoint import load, load_pretrained  # torch is only imported when needed

    if name == "singular":
        return load_pretrained(f"{task}/{scene}")
    path = Path(name)
    if path.is_dir():
        path = path / task / f"{scene}.pt"
    if not path.is_file():
        raise FileNotFoundError(
            f"predictor {name!r}: not one of {', '.join(PREDICTOR_NAMES)} and no checkpoint at {path}"
        )
    return load(path)
