"""Benchmark evaluation: every scene of a task, offline (``st_sim.scoring``) and through the spectator env."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from predictor.protocol import Predictor
from replays.scenes import SCENE_NAMES, scene_info
from st_sim.paper import paper_numbers
from st_sim.scoring import SceneResult, evaluate_offline, target_scene

DOMAIN_PAIRS: tuple[str, ...] = tuple(
    f"{scene_info(a).letter}2{scene_info(b).letter}" for a in SCENE_NAMES for b in SCENE_NAMES if a != b
)


STREAM_TOLERANCE_M = 1e-6  # stream and offline ADE/FDE must agree to this


def evaluate_scene(predictor: Predictor, task: str, scene: str, num_samples: int | None = None,
                   momentary_from_8: bool = False, root=None, steps: int | None = None,
                   stream: bool = False, rerun_path: str | None = None, progress: bool = False) -> SceneResult:
    """Score ``predictor`` on the test split of one scene (or domain pair ``"A2B"``).

    Args:
        momentary_from_8: for the momentary task, score the 8-frame protocol's samples using only their
            last 2 observed frames instead of the loader's own 2-frame windows.
        steps: DDIM steps for predictors that take them (ablation); None = as trained.
        stream: also replay the test recordings in the spectator environment and score the streamed
            predictions; raises if they disagree with the offline windows (count, or ADE/FDE by > 1e-6 m).
        rerun_path: with ``stream``, write the replay to Rerun (see ``evaluate_stream``).
    """
    start = time.perf_counter()
    result = evaluate_offline(predictor, task, scene, num_samples, momentary_from_8, root, steps)
    if stream and not momentary_from_8 and steps is None:
        from st_sim.apps.stream_eval import evaluate_stream

        streamed = evaluate_stream(predictor, task, target_scene(task, scene), root, rerun_path, progress)
        result.stream_samples, result.stream_ade, result.stream_fde = (
            streamed["samples"], streamed["ade"], streamed["fde"])
        if (streamed["samples"] != result.samples or abs(streamed["ade"] - result.ade) > STREAM_TOLERANCE_M
                or abs(streamed["fde"] - result.fde) > STREAM_TOLERANCE_M):
            raise AssertionError(f"{task}/{scene}: stream {streamed} disagrees with offline "
                                 f"({result.samples}, {result.ade}, {result.fde})")
        result.wall_s = time.perf_counter() - start
    return result


def evaluate_task(make_predictor: Callable[[str, str], Predictor], task: str, scenes: list[str] | None = None,
                  momentary_from_8: bool = False, root=None, progress: bool = True, stream: bool = False,
                  rerun_path: str | None = None) -> dict:
    """Evaluate every scene (or domain pair) of a task.

    Args:
        make_predictor: (task, scene) -> predictor for that scene (e.g. a leave-one-out checkpoint).
        scenes: scene names, or domain pairs for ``domain``; default all.

    Returns:
        ``{"task", "avg": {"ade", "fde", "paper_ade", "paper_fde"}, "scenes": {scene: SceneResult dict}}``.
    """
    scenes = scenes or list(DOMAIN_PAIRS if task == "domain" else SCENE_NAMES)
    results = {}
    for scene in tqdm(scenes, desc=f"{task}", unit="scene", disable=not progress):
        rerun = None if rerun_path is None else str(Path(rerun_path).with_name(f"{Path(rerun_path).stem}_{task}"
                                                                                   f"_{scene}.rrd"))
        results[scene] = evaluate_scene(make_predictor(task, scene), task, scene, None, momentary_from_8, root,
                                        stream=stream, rerun_path=rerun, progress=progress)
    avg = {"ade": float(np.mean([r.ade for r in results.values()])),
           "fde": float(np.mean([r.fde for r in results.values()]))}
    paper_avg = paper_numbers(task, "avg")
    if paper_avg and len(scenes) == (20 if task == "domain" else 5):
        avg.update(paper_ade=paper_avg[0], paper_fde=paper_avg[1])
    return {"task": task, "avg": avg, "scenes": {name: asdict(r) for name, r in results.items()}}


def _pair(ade: float, fde: float) -> str:
    return f"{ade:.3f} / {fde:.3f}"


def markdown_table(result: dict, predictor_name: str) -> str:
    """A markdown table of ``evaluate_task``'s result with the paper's numbers and the delta."""
    lines = [
        f"**{result['task']}** — predictor `{predictor_name}` (ADE / FDE in metres)", "",
        "| scene | samples | ADE / FDE | paper | delta | map-viol. pred (paths) | map-viol. GT | collisions "
        "| stream = offline |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in result["scenes"].items():
        paper = _pair(r["paper_ade"], r["paper_fde"]) if r["paper_ade"] is not None else "–"
        delta = (f"{r['ade'] - r['paper_ade']:+.3f} / {r['fde'] - r['paper_fde']:+.3f}"
                 if r["paper_ade"] is not None else "–")
        lines.append(
            f"| {name} | {r['samples']} | {_pair(r['ade'], r['fde'])} | {paper} | {delta} | "
            f"{100 * r['map_violation']:.2f}% ({100 * r['path_map_violation']:.1f}%) | "
            f"{100 * r['gt_map_violation']:.2f}% | {100 * r['collision_rate']:.2f}% | "
            f"{'yes' if r['stream_samples'] is not None else 'not run'} |"
        )
    avg = result["avg"]
    paper = _pair(avg["paper_ade"], avg["paper_fde"]) if "paper_ade" in avg else "–"
    delta = (f"{avg['ade'] - avg['paper_ade']:+.3f} / {avg['fde'] - avg['paper_fde']:+.3f}"
             if "paper_ade" in avg else "–")
    lines.append(f"| **AVG** | | **{_pair(avg['ade'], avg['fde'])}** | {paper} | {delta} | | | | |")
    return "\n".join(lines)
