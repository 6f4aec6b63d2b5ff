"""How likely each of a SingularTrajectory checkpoint's S samples is, for planners that weigh the samples.

    python -m st_sim.apps.navigation.sample_prior          # writes pretrained/sample_prior.json

The S samples of a shipped checkpoint come from its S anchors, which are ordered by k-means cluster size
(largest first), so sample i has the same meaning for every agent. Its prior is the share of training
windows in which sample i is the closest to the ground truth (ADE over the planner's 3.2 s horizon), with
one pseudo-count per sample so that no sample gets zero weight. The windows are the checkpoint's own
training split (leave-one-out: the other four scenes; universal: all five), never a test split. The table
records each checkpoint's SHA-256; a re-shipped checkpoint has no prior until the table is rebuilt.
"""

from __future__ import annotations

import argparse
import json
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from replays import strict_json
from replays.atomic import write_text_atomic
from replays.constants import TASKS

PRIOR_FILE = "sample_prior.json"  # in the package's pretrained/ folder
HORIZON_STEPS = 8  # ADE over the MPC's 3.2 s horizon picks each window's best sample [steps of 0.4 s]
PSEUDO_COUNT = 1.0  # added to every sample's count [windows]
MAX_WINDOWS = 3000  # scene moments (groups) drawn from a training split [-]
SHIPPED_SOURCE = "shipped:"  # prefix of ``model.source`` for a shipped checkpoint


def estimate_prior(name: str, max_windows: int = MAX_WINDOWS, seed: int = 0) -> dict:
    """{sha256, task, scene, windows, agents, weights (S,)} of shipped checkpoint ``name`` on its training split."""
    import torch

    from predictor.checkpoint import load_pretrained, pretrained_manifest
    from replays import load_scene, load_windows, scene_of_recording
    from replays.windows import ALL_SCENES

    torch.set_num_threads(1)
    entry = pretrained_manifest()["checkpoints"][name]
    task, scene = name.split("/") if "/" in name else ("stochastic", ALL_SCENES)
    scene = ALL_SCENES if scene == "universal" else scene
    model = load_pretrained(name)
    windows = load_windows(task=task, scene=scene, split="train")
    groups = np.unique(windows.group)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(groups, size=min(max_windows, len(groups)), replace=False)
    counts = np.zeros(model.cfg.num_samples)
    for group in np.sort(chosen):
        rows = np.flatnonzero(windows.group == group)
        where = load_scene(scene_of_recording(str(windows.recording[rows[0]])).name)
        futures = model.predict(windows.obs[rows], windows.group[rows], where)[:, :, :HORIZON_STEPS]
        error_m = np.linalg.norm(futures - windows.fut[rows][:, None, :HORIZON_STEPS], axis=-1).mean(axis=-1)
        np.add.at(counts, error_m.argmin(axis=1), 1)
    weights = (counts + PSEUDO_COUNT) / (counts.sum() + PSEUDO_COUNT * len(counts))
    return {"sha256": entry["sha256"], "task": task, "scene": scene, "windows": len(chosen),
            "agents": int(counts.sum()), "weights": [round(float(w), 6) for w in weights]}


@cache
def _table() -> dict:
    path = resources.files(__package__).joinpath("pretrained", PRIOR_FILE)
    return json.loads(path.read_text()) if path.is_file() else {"checkpoints": {}}


def sample_prior(source: str | None, num_samples: int) -> np.ndarray | None:
    """(S,) prior of the samples of the predictor loaded from ``source`` (``model.source``), summing to 1.

    None (samples equally likely) for anything but a shipped checkpoint in the table whose SHA-256 still
    matches the predictor's manifest, or when the env asks for another number of samples.
    """
    if source is None or not source.startswith(SHIPPED_SOURCE):
        return None
    from predictor.checkpoint import pretrained_manifest

    name = source[len(SHIPPED_SOURCE):]
    entry = _table()["checkpoints"].get(name)
    shipped = pretrained_manifest()["checkpoints"].get(name, {})
    if entry is None or entry["sha256"] != shipped.get("sha256") or len(entry["weights"]) < num_samples:
        return None
    weights = np.asarray(entry["weights"][:num_samples], np.float64)
    return weights / weights.sum()


def main(argv: list[str] | None = None) -> int:
    """Estimate the prior of every shipped checkpoint with S > 1 and write the table; exit code 0."""
    from predictor.checkpoint import pretrained_manifest

    parser = argparse.ArgumentParser(prog="python -m st_sim.apps.navigation.sample_prior", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--max-windows", type=int, default=MAX_WINDOWS,
                        help=f"scene moments per training split (default: {MAX_WINDOWS})")
    parser.add_argument("--out", default=None, help="table path (default: the package's pretrained/ folder)")
    args = parser.parse_args(argv)
    table = {"horizon_steps": HORIZON_STEPS, "pseudo_count": PSEUDO_COUNT, "checkpoints": {}}
    for name, entry in pretrained_manifest()["checkpoints"].items():
        if TASKS[entry["train_config"]["task"]]["num_samples"] == 1:
            continue  # a single-sample model has nothing to weigh
        table["checkpoints"][name] = prior = estimate_prior(name, args.max_windows)
        top = np.cumsum(prior["weights"])
        print(f"{name}: {prior['agents']} agents in {prior['windows']} windows; sample 0 {prior['weights'][0]:.3f}, "
              f"top 5 {top[4]:.3f}, top 10 {top[9]:.3f}", flush=True)
    out = Path(args.out) if args.out else Path(str(resources.files(__package__).joinpath("pretrained", PRIOR_FILE)))
    write_text_atomic(out, strict_json.dumps(table, indent=1, sort_keys=True) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
