"""Checkpoints: weights + config + Singular bases + anchors + data checksums, loadable with weights_only=True."""

from __future__ import annotations

import json
import os
from dataclasses import asdict
from importlib import resources
from pathlib import Path

import numpy as np
import torch

from predictor.model import ModelConfig, SingularTrajectory
from predictor.refiner import Refiner
from predictor.singular_space import SingularSpace
from replays.atomic import atomic_path

FORMAT = "stcrowd-singular-trajectory/1"
PRETRAINED_DIR = "pretrained"


class CheckpointError(ValueError):
    """A checkpoint file is truncated, foreign or does not match what was asked for."""


def model_state(model: SingularTrajectory, half: bool = False) -> dict:
    """Everything needed to rebuild ``model``, as tensors and plain values."""
    weights = {k: (v.half() if half and v.is_floating_point() else v.clone())
               for k, v in model.refiner.state_dict().items()}
    return {
        "format": FORMAT,
        "config": asdict(model.cfg),
        "weights": weights,
        "bases": torch.tensor(np.stack([s.basis for s in model.spaces])),
        "singular_values": torch.tensor(np.stack([s.singular_values for s in model.spaces])),
        "anchors": torch.tensor(model.anchors),
        "coef_scale": torch.tensor(model.coef_scale),
        "residual_scale": torch.tensor(model.residual_scale),
    }


def model_from_state(state: dict) -> SingularTrajectory:
    """Rebuild a predictor from ``model_state``'s output."""
    cfg = ModelConfig(**state["config"])
    refiner = Refiner(cfg.refiner_config())
    refiner.load_state_dict({k: v.float() for k, v in state["weights"].items()})
    spaces = [SingularSpace(b.double().numpy(), sv.double().numpy())
              for b, sv in zip(state["bases"], state["singular_values"], strict=True)]
    return SingularTrajectory(cfg, spaces, state["anchors"].double().numpy(), state["coef_scale"].double().numpy(),
                              state["residual_scale"].double().numpy(), refiner)


def save_atomic(obj: dict, path: Path) -> Path:
    """torch.save through a temp file in the same folder and a rename (never a half-written file)."""
    with atomic_path(path) as tmp:
        torch.save(obj, tmp)
    return Path(path)


def read_checkpoint(path: str | os.PathLike) -> dict:
    """Load a checkpoint dict safely (weights_only=True) and check its format."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such checkpoint file")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises several types for truncated or foreign files
        raise CheckpointError(f"{path}: not a readable checkpoint (truncated or not a torch file): {err}") from err
    model = state.get("model") if isinstance(state, dict) else None
    if not isinstance(model, dict) or model.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not an STCrowd SingularTrajectory checkpoint (expected format {FORMAT})")
    return state


def load(path: str | os.PathLike, task: str | None = None) -> SingularTrajectory:
    """Predictor from a checkpoint file; with ``task``, refuse a checkpoint trained for another task."""
    state = read_checkpoint(path)
    try:
        model = model_from_state(state["model"])
    except (KeyError, RuntimeError, TypeError) as err:
        raise CheckpointError(f"{path}: checkpoint content does not match this version of the model: {err}") from err
    if task is not None and model.cfg.task != task:
        raise CheckpointError(f"{path}: trained for task {model.cfg.task!r}, not {task!r}")
    return model


def pretrained_manifest() -> dict:
    """The shipped checkpoints' manifest (name -> training command, data checksums, test numbers)."""
    return json.loads(resources.files("predictor").joinpath(PRETRAINED_DIR, "manifest.json").read_text())


def load_pretrained(name: str = "universal") -> SingularTrajectory:
    """A shipped checkpoint by name: ``"stochastic/eth"`` ... ``"stochastic/zara2"``, ``"universal"``, and their
    2-frame counterparts ``"momentary/eth"`` ... ``"momentary/zara2"``, ``"momentary/universal"``."""
    manifest = pretrained_manifest()
    if name not in manifest["checkpoints"]:
        raise KeyError(f"no shipped checkpoint {name!r}; available: {', '.join(manifest['checkpoints'])}")
    entry = manifest["checkpoints"][name]
    return load(resources.files("predictor").joinpath(PRETRAINED_DIR, entry["file"]))
