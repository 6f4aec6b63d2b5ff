"""Benchmark tables: a predictor on every scene of a task, for one or more training seeds, and several predictors
compared on the same windows.

Each (task, scene, seed) is scored offline on the benchmark windows (``st_sim.scoring``) and, by default,
again by replaying the test recordings through the spectator environment; the two must agree. The cells
run as a grid (``st_sim.apps.grid``): missing SingularTrajectory checkpoints are trained first, then every
cell is evaluated, each writing its own JSON, so an interrupted run resumes where it stopped (a plug-in's
cells are always evaluated afresh: the code or weights behind its spec may have changed).
"""

from __future__ import annotations

import hashlib
import json
import re
import statistics
import time
from dataclasses import asdict, dataclass
from functools import cached_property
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from predictor.plugins import PluginError, is_plugin_spec, resolve_factory, takes_seed
from predictor.protocol import Predictor
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.constants import DOMAIN_TASKS
from replays.scenes import SCENE_NAMES, scene_info
from st_sim.apps.grid import Job, JobReport, raise_on_failure
from st_sim.metrics import format_metric, paired_bootstrap
from st_sim.paper import paper_numbers
from st_sim.scoring import SceneResult, evaluate_offline, target_scene

DOMAIN_PAIRS: tuple[str, ...] = tuple(
    f"{scene_info(a).letter}2{scene_info(b).letter}" for a in SCENE_NAMES for b in SCENE_NAMES if a != b
)
STREAM_TOLERANCE_M = 1e-6  # stream and offline ADE/FDE must agree to this
TRAIN_ESTIMATE_S: dict[bool, float] = {False: 45.0, True: 200.0}
"""one model with one thread on this project's 2-core machine, two jobs at a time, by multi-sample task (16 epochs
since a8ba1f1; single-sample: 6) [s]"""
BOOTSTRAP_RESAMPLES = 2000  # draws of the windows behind a paired comparison's interval
BOOTSTRAP_SEED = 0  # seed of those draws
SAMPLE_KEYS = ("sample_ade", "sample_fde", "window_sizes")  # per-sample fields of a cell, kept out of the tables


class StreamMismatchError(RuntimeError):
    """Evaluation through the environment disagrees with the offline windows."""


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
        if streamed["samples"] != result.samples or (result.samples and (
                abs(streamed["ade"] - result.ade) > STREAM_TOLERANCE_M
                or abs(streamed["fde"] - result.fde) > STREAM_TOLERANCE_M)):
            raise StreamMismatchError(
                f"{task}/{scene}: stream {streamed} disagrees with offline ({result.samples}, {result.ade}, "
                f"{result.fde}); a predictor must give an agent the same futures whether it is called on all windows "
                "at once or one scene moment at a time (no unseeded randomness, no batch effects); --no-stream skips "
                "this check")
        result.wall_s = time.perf_counter() - start
    return result


def task_scenes(task: str) -> list[str]:
    """Every scene of a task's table: the 20 domain pairs, or the five scenes."""
    return list(DOMAIN_PAIRS if task in DOMAIN_TASKS else SCENE_NAMES)


@dataclass(frozen=True)
class Plan:
    """What one ``evaluate`` command runs: a predictor on tasks x scenes x seeds."""

    predictor: str
    """cvm | cvm-s | linear | singular | a plug-in package.module:name | a checkpoint file or folder"""
    tasks: tuple[str, ...]
    scenes: dict[str, tuple[str, ...]]
    """task -> scenes (or domain pairs)"""
    seeds: tuple[int, ...] = (0,)
    """training seeds of singular models and of plug-ins whose factory takes ``seed`` (one row per scene: mean and
    sd over these)"""
    runs: str = "runs"
    """training folder: ``runs/<task>/<scene>/seed<k>``; evaluations are kept in ``runs/evaluations``"""
    root: str | None = None
    stream: bool = True
    momentary_from_8: bool = False
    rerun: str | None = None
    """FILE.rrd -> one recording per cell and replayed file"""
    use_shipped: bool = True
    """seed 0 falls back to the shipped checkpoint when ``runs`` has none (False: train it)"""

    @property
    def trained(self) -> bool:
        return self.predictor == "singular"

    @property
    def plugin(self) -> bool:
        return is_plugin_spec(self.predictor)

    def __post_init__(self) -> None:  # absolute paths: a cluster's workers do not run in this folder
        for name in ("runs", "root", "rerun"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, str(Path(getattr(self, name)).expanduser().resolve()))

    @cached_property
    def seeded_plugin(self) -> bool:
        """A plug-in whose factory takes ``seed`` (resolving the spec imports it: a bad spec fails here)."""
        return self.plugin and takes_seed(resolve_factory(self.predictor))

    def cells(self) -> list[tuple[str, str, int]]:
        seeds = self.seeds if self.trained or Path(self.predictor).is_dir() or self.seeded_plugin else (0,)
        return [(task, scene, seed) for task in self.tasks for scene in self.scenes[task] for seed in seeds]

    def missing_models(self) -> list[tuple[str, str, int]]:
        """Cells whose SingularTrajectory checkpoint neither exists in ``runs`` nor ships."""
        if not self.trained:
            return []
        from predictor.registry import resolve_checkpoint

        return [cell for cell in self.cells()
                if resolve_checkpoint(*cell, runs_dir=self.runs, use_shipped=self.use_shipped) is None]

    def train_jobs(self) -> list[Job]:
        """One training job per missing model (resumes an interrupted run)."""
        from predictor.registry import run_dir
        from predictor.train import TRAIN_SUMMARY, TrainConfig

        jobs = []
        for task, scene, seed in self.missing_models():
            out = run_dir(self.runs, task, scene, seed)
            cfg = TrainConfig(task=task, scene=scene, seed=seed, out=str(out), data_root=self.root, progress=False)
            jobs.append(Job(f"train/{task}/{scene}/seed{seed}", "predictor.train:train_job", asdict(cfg),
                            str(out / TRAIN_SUMMARY)))
        return jobs

    def evaluation_jobs(self) -> list[Job]:
        """One evaluation job per cell, its JSON named after what it scored (a new checkpoint = a new job)."""
        jobs = []
        for task, scene, seed in self.cells():
            source = self.source(task, scene, seed)
            flags = ("-from8" if self.momentary_from_8 and task == "momentary" else "") + ("" if self.stream else
                                                                                          "-offline")
            label = source_label(source) + (f"-seed{seed}" if self.seeded_plugin else "") + flags
            output = Path(self.runs) / "evaluations" / task / scene / f"{label}.json"
            rerun = None
            if self.rerun is not None:
                base = Path(self.rerun)
                rerun = str(base.with_name(f"{base.stem}_{task}_{scene}_seed{seed}.rrd"))
            # the name says what is scored, so that a crash report names the plug-in or checkpoint
            jobs.append(Job(f"evaluate/{task}/{scene}/seed{seed} ({source})", "st_sim.apps.evaluate:evaluate_job",
                            {"source": source, "task": task, "scene": scene, "seed": seed, "root": self.root,
                             "stream": self.stream,
                             "momentary_from_8": self.momentary_from_8, "rerun_path": rerun, "output": str(output)},
                            str(output)))
        return jobs

    def source(self, task: str, scene: str, seed: int) -> str:
        """What a cell's predictor is made from: a baseline name, a plug-in spec, a checkpoint file, or
        ``shipped:<name>``."""
        if not self.trained:
            path = Path(self.predictor)
            if path.is_dir():
                from predictor.registry import run_dir

                return str(run_dir(path, task, scene, seed) / "best.pt")
            return self.predictor
        from predictor.registry import MissingCheckpointError, resolve_checkpoint

        spec = resolve_checkpoint(task, scene, seed, self.runs, self.use_shipped)
        if spec is None:
            raise MissingCheckpointError(f"no checkpoint for {task}/{scene} seed {seed}; train it first")
        return spec


def source_label(source: str) -> str:
    """File-name-safe label of a predictor source.

    A checkpoint is labelled by the hash of its bytes and of its effective configuration (the stored one with
    today's defaults for newer fields), so a result is not reused once the code would predict differently; a
    plug-in by its spec (``plugin-<spec>``).
    """
    if is_plugin_spec(source):
        return f"plugin-{file_label(source)}"
    if source.startswith("shipped:"):
        from predictor.checkpoint import PRETRAINED_DIR, pretrained_manifest

        entry = pretrained_manifest()["checkpoints"][source.removeprefix("shipped:")]
        path = Path(str(resources.files("predictor").joinpath(PRETRAINED_DIR, entry["file"])))
        prefix = "shipped"
    else:
        path, prefix = Path(source), "checkpoint"
    if not path.is_file():
        return source
    from predictor.checkpoint import read_checkpoint
    from predictor.model import ModelConfig

    config = asdict(ModelConfig(**read_checkpoint(path)["model"]["config"]))
    config_hash = hashlib.sha256(strict_json.dumps(config, sort_keys=True).encode()).hexdigest()[:8]
    return f"{prefix}-{hashlib.sha256(path.read_bytes()).hexdigest()[:12]}-{config_hash}"


def file_label(source: str) -> str:
    """``source`` with every run of characters other than letters, digits, ``.``, ``_`` and ``-`` made one ``-``."""
    return re.sub(r"[^\w.-]+", "-", source).strip("-") or "predictor"


def evaluate_job(source: str, task: str, scene: str, root: str | None, stream: bool, momentary_from_8: bool,
                 rerun_path: str | None, output: str, seed: int = 0) -> None:
    """Grid entry point: score one cell and write its ``SceneResult`` as JSON to ``output`` (compact: it holds the
    per-sample errors); ``seed`` reaches a plug-in factory that takes one."""
    from predictor.registry import PREDICTOR_NAMES, load_checkpoint_spec, make_predictor

    named = source in PREDICTOR_NAMES or is_plugin_spec(source)  # a baseline, singular or a plug-in: not a file
    predictor = make_predictor(source, task, scene, root, seed=seed) if named else load_checkpoint_spec(source, task)
    result = evaluate_scene(predictor, task, scene, None, momentary_from_8, root, stream=stream,
                            rerun_path=rerun_path)
    result.checkpoint = None if named else source
    write_text_atomic(output, strict_json.dumps(asdict(result), separators=(",", ":")))


def forget_stale_results(plan: Plan, jobs: list[Job], need_samples: bool) -> None:
    """Delete the outputs of ``jobs`` that must be evaluated again: all of a plug-in's, and with ``need_samples``
    those written before cells kept their per-sample errors."""
    for job in jobs:
        path = Path(job.output)
        if path.is_file() and (plan.plugin or (need_samples and "sample_fde" not in json.loads(path.read_text()))):
            path.unlink()


def raise_on_job_failure(reports: list[JobReport]) -> None:
    """``grid.raise_on_failure``, except that a plug-in's failure is raised as its own ``PluginError``, one line."""
    prefix = f"{PluginError.__module__}.{PluginError.__qualname__}: "
    failed = [r for r in reports if r.status == "failed" and (r.error or "").startswith(prefix)]
    if failed:
        more = f"; {len(failed) - 1} more jobs failed the same way" if len(failed) > 1 else ""
        raise PluginError(f"{failed[0].error.removeprefix(prefix)} (job {failed[0].name}{more})")
    raise_on_failure(reports)


def _mean_sd(values: list[float]) -> tuple[float, float]:
    return statistics.fmean(values), (statistics.stdev(values) if len(values) > 1 else 0.0)


def aggregate(task: str, predictor: str, per_cell: dict[tuple[str, int], dict[str, Any]]) -> dict:
    """One task's table from its cells' results (``(scene, seed) -> SceneResult dict``).

    Returns:
        ``{"task", "predictor", "seeds", "avg": {"ade", "fde", "ade_sd", "fde_sd", "per_seed", "paper_*"},
        "scenes": {scene: {"ade", "fde", "ade_sd", "fde_sd", means of the other scores, "checkpoints",
        "seeds": {seed: SceneResult dict}}}}``; sd is over seeds (n - 1 in the denominator). Checkpoints and the
        predictor are named by ``portable_source``.
    """
    per_cell = {cell: {**{k: v for k, v in r.items() if k not in SAMPLE_KEYS},
                       "checkpoint": portable_source(r["checkpoint"])} for cell, r in per_cell.items()}
    scenes = list(dict.fromkeys(scene for scene, _ in per_cell))
    seeds = sorted({seed for _, seed in per_cell})
    table: dict[str, Any] = {}
    for scene in scenes:
        runs = {seed: per_cell[(scene, seed)] for seed in seeds}
        row: dict[str, Any] = {"samples": runs[seeds[0]]["samples"], "seeds": {str(k): v for k, v in runs.items()},
                               "paper_ade": runs[seeds[0]]["paper_ade"], "paper_fde": runs[seeds[0]]["paper_fde"],
                               "checkpoints": [r["checkpoint"] for r in runs.values()],
                               "stream_checked": all(r["stream_samples"] is not None for r in runs.values())}
        for metric in ("ade", "fde"):
            row[metric], row[f"{metric}_sd"] = _mean_sd([r[metric] for r in runs.values()])
        for metric in ("map_violation", "path_map_violation", "gt_map_violation", "collision_rate"):
            values = [r[metric] for r in runs.values() if r[metric] is not None]
            row[metric] = statistics.fmean(values) if values else None
        table[scene] = row
    per_seed = {str(seed): {m: statistics.fmean(per_cell[(s, seed)][m] for s in scenes) for m in ("ade", "fde")}
                for seed in seeds}
    avg: dict[str, Any] = {"per_seed": per_seed}
    for metric in ("ade", "fde"):
        avg[metric], avg[f"{metric}_sd"] = _mean_sd([v[metric] for v in per_seed.values()])
    paper_avg = paper_numbers(task, "avg")
    if paper_avg and set(scenes) == set(task_scenes(task)):
        avg.update(paper_ade=paper_avg[0], paper_fde=paper_avg[1])
    return {"task": task, "predictor": portable_source(predictor), "seeds": seeds, "avg": avg, "scenes": table}


def _pair(ade: float, fde: float, ade_sd: float | None = None, fde_sd: float | None = None) -> str:
    if ade_sd is None:
        return f"{ade:.3f} / {fde:.3f}"
    return f"{ade:.3f} ± {ade_sd:.3f} / {fde:.3f} ± {fde_sd:.3f}"


def _delta(row: dict) -> str:
    if row.get("paper_ade") is None:
        return "–"
    return f"{row['ade'] - row['paper_ade']:+.3f} / {row['fde'] - row['paper_fde']:+.3f}"


TASK_TITLES = {"domain": "domain adaptation (paper protocol: validation on the target's val portion)",
               "domain_strict": "domain adaptation, strict (validation on the source's own val portion)"}


def portable_source(source: str | None) -> str | None:
    """A predictor source as results name it, with no folder of the machine that ran it: a run's checkpoint as
    ``<task>/<scene>/seed<k>/best.pt`` (relative to the runs folder), another file relative to the working folder
    where it lies inside it (else its name); baseline names and ``shipped:<name>`` as given."""
    if source is None or not Path(source).is_absolute():
        return source
    path = Path(source)
    if len(path.parts) > 4 and path.parent.name.startswith("seed"):
        return "/".join(path.parts[-4:])
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return path.name


def markdown_table(result: dict) -> str:
    """A markdown table of ``aggregate``'s result with the paper's numbers, the delta and the checkpoints."""
    seeds = result["seeds"]
    several = len(seeds) > 1
    spread = f"mean ± sd over seeds {', '.join(map(str, seeds))}" if several else f"seed {seeds[0]}"
    lines = [
        f"**{TASK_TITLES.get(result['task'], result['task'])}** — predictor `{result['predictor']}`, {spread} "
        "(ADE / FDE in metres)", "",
        "| scene | samples | ADE / FDE | paper | delta | map-viol. pred (paths) | map-viol. GT | collisions "
        "| stream = offline | checkpoint |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in result["scenes"].items():
        paper = _pair(r["paper_ade"], r["paper_fde"]) if r["paper_ade"] is not None else "–"
        scores = _pair(r["ade"], r["fde"], r["ade_sd"], r["fde_sd"]) if several else _pair(r["ade"], r["fde"])
        checkpoint = r["checkpoints"][0] or "–"
        if several and r["checkpoints"][0]:
            checkpoint += f" (+{len(seeds) - 1} seeds)"
        percent = {k: format_metric(r[k], ".1f" if k == "path_map_violation" else ".2f", 100)
                   for k in ("map_violation", "path_map_violation", "gt_map_violation", "collision_rate")}
        lines.append(
            f"| {name} | {r['samples']} | {scores} | {paper} | {_delta(r)} | "
            f"{percent['map_violation']}% ({percent['path_map_violation']}%) | {percent['gt_map_violation']}% | "
            f"{percent['collision_rate']}% | {'yes' if r['stream_checked'] else 'not run'} | {checkpoint} |")
    avg = result["avg"]
    paper = _pair(avg["paper_ade"], avg["paper_fde"]) if "paper_ade" in avg else "–"
    scores = _pair(avg["ade"], avg["fde"], avg["ade_sd"], avg["fde_sd"]) if several else _pair(avg["ade"], avg["fde"])
    lines.append(f"| **AVG** | | **{scores}** | {paper} | {_delta(avg)} | | | | | |")
    return "\n".join(lines)


def compare(task: str, cells: dict[str, dict[tuple[str, int], dict[str, Any]]]) -> dict:
    """Several predictors on the same test windows of one task, each against the first one (the reference).

    Args:
        cells: predictor -> its cells, ``(scene, seed) -> SceneResult dict`` with per-sample errors; a predictor
            with several seeds counts with each sample's mean error over them.

    Returns:
        ``{"task", "predictors", "reference", "bootstrap", "scenes": {scene: row}, "avg": row}`` where a row is
        ``{"samples", "ade": {predictor: m}, "fde": {predictor: m}, "fde_difference": {predictor: {"mean", "low",
        "high"}}}``: the mean per-sample FDE of a predictor minus the reference's, with a 95 % bootstrap interval
        over windows (``st_sim.metrics.paired_bootstrap``; AVG: the mean over scenes, as the tables' AVG).
    """
    names = list(cells)
    reference, shown = names[0], {name: portable_source(name) for name in names}  # shown: as results name it
    scenes = list(dict.fromkeys(scene for scene, _ in cells[reference]))
    errors: dict[str, dict[str, dict[str, np.ndarray]]] = {name: {} for name in names}  # name -> scene -> metric
    windows: dict[str, np.ndarray] = {}
    for scene in scenes:
        for name in names:
            runs = [r for (s, _), r in cells[name].items() if s == scene]
            sizes = runs[0].get("window_sizes")
            if sizes is None or any(r.get("window_sizes") != sizes for r in runs):
                raise ValueError(f"{task}/{scene}: {name} has no per-sample errors, or its cells differ in windows")
            ids = np.repeat(np.arange(len(sizes)), sizes)  # (N,) window of each sample
            if not np.array_equal(windows.setdefault(scene, ids), ids):
                raise ValueError(f"{task}/{scene}: {name} was scored on other windows than {reference}")
            errors[name][scene] = {m: np.mean([r[f"sample_{m}"] for r in runs], axis=0) for m in ("ade", "fde")}
    rows: dict[str, dict[str, Any]] = {scene: {"samples": len(windows[scene]), "ade": {}, "fde": {},
                                               "fde_difference": {}} for scene in scenes}
    avg: dict[str, Any] = {"ade": {}, "fde": {}, "fde_difference": {}}
    for name in names:
        for metric in ("ade", "fde"):
            for scene in scenes:
                rows[scene][metric][shown[name]] = float(errors[name][scene][metric].mean())
            avg[metric][shown[name]] = statistics.fmean(rows[scene][metric][shown[name]] for scene in scenes)
        if name == reference:
            continue
        differences = [errors[name][scene]["fde"] - errors[reference][scene]["fde"] for scene in scenes]
        per_scene, overall = paired_bootstrap(differences, [windows[scene] for scene in scenes],
                                              BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED)
        for scene, interval in zip(scenes, per_scene, strict=True):
            rows[scene]["fde_difference"][shown[name]] = dict(zip(("mean", "low", "high"), interval, strict=True))
        avg["fde_difference"][shown[name]] = dict(zip(("mean", "low", "high"), overall, strict=True))
    return {"task": task, "predictors": list(shown.values()), "reference": shown[reference],
            "bootstrap": {"resamples": BOOTSTRAP_RESAMPLES, "seed": BOOTSTRAP_SEED, "confidence": 0.95,
                          "unit": "window"},
            "scenes": rows, "avg": avg}


def comparison_table(comparison: dict) -> str:
    """A markdown table of ``compare``'s result: rows = scenes + AVG, columns = each predictor's ADE / FDE, then
    each other predictor's FDE difference to the reference with its 95 % interval."""
    names, reference = comparison["predictors"], comparison["reference"]
    others = names[1:]
    lines = [f"**{TASK_TITLES.get(comparison['task'], comparison['task'])}** — predictors on the same windows "
             f"(ADE / FDE in metres); ΔFDE = FDE − FDE of `{reference}` (negative: lower error), mean and 95 % "
             f"bootstrap interval over windows ({comparison['bootstrap']['resamples']} resamples, seed "
             f"{comparison['bootstrap']['seed']})", "",
             "| scene | samples | " + " | ".join(f"`{name}`" for name in names) + "".join(
                 f" | ΔFDE `{name}`" for name in others) + " |",
             "|---|---|" + "---|" * (len(names) + len(others))]
    for label, row in [*comparison["scenes"].items(), ("**AVG**", comparison["avg"])]:
        pairs = [_pair(ade, fde) for ade, fde in zip(row["ade"].values(), row["fde"].values(), strict=True)]
        deltas = [f"{d['mean']:+.3f} [{d['low']:+.3f}, {d['high']:+.3f}]"
                  for d in row["fde_difference"].values()]
        lines.append(f"| {label} | {row.get('samples', '')} | " + " | ".join(pairs + deltas) + " |")
    return "\n".join(lines)
