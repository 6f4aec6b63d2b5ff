"""Ship a trained checkpoint inside the package: fp16 weights + manifest entry with measured test numbers."""

from __future__ import annotations

import hashlib
import json
import os
from importlib import resources
from pathlib import Path

from predictor.checkpoint import PRETRAINED_DIR, CheckpointError, load, model_state, read_checkpoint, save_atomic
from predictor.train import TRAIN_SUMMARY, finished, read_summary
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.scenes import SCENE_NAMES


def pretrained_dir() -> Path:
    return Path(str(resources.files("predictor").joinpath(PRETRAINED_DIR)))


def export_checkpoint(checkpoint: str | os.PathLike, name: str, root=None) -> dict:
    """Write ``predictor/pretrained/<name>.pt`` (fp16) and its manifest entry; returns the entry.

    The test numbers are measured on the exported (fp16) weights: the scene's own test split for a
    leave-one-out model, every scene's test split for the universal one.
    """
    from st_sim.scoring import evaluate_offline

    state = read_checkpoint(checkpoint)
    cfg = state["train_config"]
    if not finished(Path(checkpoint).parent):
        raise CheckpointError(f"{Path(checkpoint).with_name(TRAIN_SUMMARY)}: missing; export only the best.pt of a "
                              "finished training run")
    summary = read_summary(Path(checkpoint).parent)
    file_name = name.replace("/", "_") + ".pt"
    target = pretrained_dir() / file_name
    shipped = {"model": model_state(load(checkpoint), half=True), "train_config": cfg,
               "data_checksums": state["data_checksums"], "best": state["best"]}
    save_atomic(shipped, target)
    model = load(target)
    scenes = SCENE_NAMES if cfg["scene"] == "all" else (cfg["scene"],)
    test = {}
    for scene in scenes:
        r = evaluate_offline(model, cfg["task"], scene, root=root)
        test[scene] = {"samples": r.samples, "ade": round(r.ade, 4), "fde": round(r.fde, 4),
                       "map_violation": round(r.map_violation, 4)}
    entry = {
        "file": file_name,
        "command": f"python -m predictor train --task {cfg['task']} --scene {cfg['scene']} --seed {cfg['seed']} "
                   "--out OUT",
        "train_config": cfg,
        "train_wall_s": round(summary["wall_s"]),
        "selected_epoch": state["best"]["epoch"],
        "val": {"ade": round(state["best"]["ade"], 4), "fde": round(state["best"]["fde"], 4)},
        "test": test,
        "size_bytes": target.stat().st_size,
        "sha256": hashlib.sha256(target.read_bytes()).hexdigest(),
        "data_checksums": state["data_checksums"],
    }
    manifest_path = pretrained_dir() / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {"checkpoints": {}}
    manifest["checkpoints"][name] = entry
    write_text_atomic(manifest_path, strict_json.dumps(manifest, indent=1, sort_keys=True))
    return entry
