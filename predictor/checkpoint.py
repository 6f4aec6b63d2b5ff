"""Checkpoints: weights + config + Singular bases + anchors + data checksums, loadable with weights_only=True."""

from __future__ import annotations

import hashlib
import io
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
from replays import strict_json
from replays.atomic import atomic_path

FORMAT = "stcrowd-singular-trajectory/1"
PRETRAINED_DIR = "pretrained"


class CheckpointError(ValueError):
    """A checkpoint file is truncated, foreign or does not match what was asked for."""


def content_hash(state: dict) -> str:
    """SHA-256 over a model state's config and every tensor (name, dtype, shape, bytes), in a fixed order."""
    digest = hashlib.sha256(strict_json.dumps(state["config"], sort_keys=True).encode())
    tensors = {f"weights.{k}": v for k, v in state["weights"].items()}
    tensors.update({k: v for k, v in state.items() if isinstance(v, torch.Tensor)})
    for name in sorted(tensors):
        tensor = tensors[name].detach().cpu().contiguous()
        digest.update(f"{name}|{tensor.dtype}|{tuple(tensor.shape)}|".encode())
        digest.update(tensor.view(torch.uint8).numpy().tobytes() if tensor.numel() else b"")
    return digest.hexdigest()


def model_state(model: SingularTrajectory, half: bool = False) -> dict:
    """Everything needed to rebuild ``model``, as tensors and plain values, with its content hash."""
    weights = {k: (v.half() if half and v.is_floating_point() else v).detach().cpu().clone()
               for k, v in model.refiner.state_dict().items()}
    state = {
        "format": FORMAT,
        "config": asdict(model.cfg),
        "weights": weights,
        "bases": torch.tensor(np.stack([s.basis for s in model.spaces])),
        "singular_values": torch.tensor(np.stack([s.singular_values for s in model.spaces])),
        "anchors": torch.tensor(model.anchors),
        "coef_scale": torch.tensor(model.coef_scale),
        "residual_scale": torch.tensor(model.residual_scale),
    }
    state["content_sha256"] = content_hash(state)
    return state


def check_state(state: dict, path: str | os.PathLike) -> None:
    """Refuse a model state whose content hash does not match, or that holds non-finite numbers."""
    stored = state.get("content_sha256")
    if stored is None:
        raise CheckpointError(f"{path}: checkpoint has no content hash (written by an older STCrowd); retrain or "
                              "re-export it")
    if content_hash(state) != stored:
        raise CheckpointError(f"{path}: content hash mismatch: the checkpoint was damaged or edited after it was "
                              "written; retrain it or restore the original file")
    tensors = {f"weights.{k}": v for k, v in state["weights"].items()}
    tensors.update({k: v for k, v in state.items() if isinstance(v, torch.Tensor)})
    bad = [name for name, t in tensors.items() if t.is_floating_point() and not torch.isfinite(t).all()]
    if bad:
        raise CheckpointError(f"{path}: non-finite values (NaN or inf) in {', '.join(sorted(bad))}")


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
    """torch.save through a temp file in the same folder and a rename (never a half-written file).

    Serialised in memory first, so the bytes depend only on ``obj`` (not on the temporary file's name).
    """
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buffer.getvalue())
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
        check_state(state["model"], path)
        model = model_from_state(state["model"])
    except CheckpointError:
        raise
    except (KeyError, RuntimeError, TypeError, ValueError, AttributeError) as err:
        raise CheckpointError(f"{path}: checkpoint content does not match this version of the model: {err}") from err
    if task is not None and model.cfg.task != task:
        raise CheckpointError(f"{path}: trained for task {model.cfg.task!r}, not {task!r}")
    model.source = str(path)
    return model


def pretrained_manifest() -> dict:
    """The shipped checkpoints' manifest (name -> training command, data checksums, test numbers)."""
    return json.loads(resources.files("predictor").joinpath(PRETRAINED_DIR, "manifest.json").read_text())


def load_pretrained(name: str = "universal") -> SingularTrajectory:
    """A shipped checkpoint by name: ``"stochastic/eth"`` ... ``"stochastic/zara2"``, the single-sample
    ``"deterministic/eth"`` ... ``"deterministic/zara2"``, ``"universal"``, and the 2-frame counterparts
    ``"momentary/eth"`` ... ``"momentary/zara2"``, ``"momentary/universal"``."""
    manifest = pretrained_manifest()
    if name not in manifest["checkpoints"]:
        raise CheckpointError(f"no shipped checkpoint {name!r}; available: {', '.join(manifest['checkpoints'])}")
    entry = manifest["checkpoints"][name]
    path = Path(str(resources.files("predictor").joinpath(PRETRAINED_DIR, entry["file"])))
    if not path.is_file() or hashlib.sha256(path.read_bytes()).hexdigest() != entry["sha256"]:
        raise CheckpointError(f"{path}: shipped checkpoint {name!r} is missing or differs from its manifest's SHA-256; "
                              "reinstall STCrowd (pip install -e .) or restore the file with git")
    model = load(path)
    model.source = f"shipped:{name}"
    return model
