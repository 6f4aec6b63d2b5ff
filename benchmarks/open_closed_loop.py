"""Open loop against closed loop: do ADE/FDE rank predictors the way the MPC's safety with them does?

    export OMP_NUM_THREADS=1 STCROWD_DATA=$PWD/../shared/datasets/eth_ucy
    python benchmarks/open_closed_loop.py --episodes 300 --out runs/study          # the RESULTS figures
    python benchmarks/open_closed_loop.py --episodes 20 --envs zara1 --out runs/study-quick
    python benchmarks/open_closed_loop.py --envs zara1 --plugin mine=mypackage.model:make --out runs/study  # + yours

For each environment (ZARA1 and UNIV replays with reactive pedestrians, and the simulated crossing) and each
predictor (CVM, CVM-S, the least-squares line, SingularTrajectory as the envs ship it, its stochastic, deterministic,
momentary, few-shot and universal models and its 5 likeliest samples as plug-ins from ``study_models.py``, and the
k-nearest-neighbour example): the open-loop ADE/FDE (best of 20) on the scene's test windows (the simulated crossing:
on the stream of a spectator env, seeds 0..19, 200 steps each) beside the MPC's success and collision rates with that
predictor over the same seeded episodes. Kendall's tau between the open-loop FDE and the closed-loop at-fault
collision rate (positive: the lower the FDE, the safer the robot) and between FDE and the failure rate (1 - success),
each with a paired bootstrap 95 % interval (2000 resamples of windows or stream seeds, and of episodes, the same for
every predictor). The few-shot models are trained first (every 10th training window, seed 0). Everything runs through
the grid runner (resumable, ``--executor ray``). Writes ``OUT/study.json`` and the scatter plot ``OUT/study.png``
(matplotlib: FDE with its bootstrap interval against the at-fault rate with its Wilson interval);
``--replot OUT/study.json`` redraws the plot alone.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # `examples` imports from the repository root

from predictor.train import TRAIN_SUMMARY, TrainConfig
from replays import strict_json
from replays.atomic import write_text_atomic
from st_sim.apps.grid import Job, raise_on_failure, run_jobs
from st_sim.apps.navigation.episodes import NavRun, grid_job
from st_sim.apps.navigation.metrics import RATES, rate_interval
from st_sim.charts import ScatterPoint, interval_scatter, save_figure
from st_sim.command_line import add_grid_arguments

PREDICTORS = {  # label -> spec (in envs and on windows); "singular" is the envs' own, its samples weighed by prior
    "cvm": "cvm", "cvm-s": "cvm-s", "linear": "linear", "singular": "singular",
    "stochastic": "study_models:stochastic", "deterministic": "study_models:deterministic",
    "momentary": "study_models:momentary", "fewshot": "study_models:fewshot", "universal": "study_models:universal",
    "singular5": "study_models:singular5", "knn": "examples.knn_predictor:make",
}
ENVS = {"zara1": ("STCrowd-Zara1-v0", "reactive"), "univ": ("STCrowd-Univ-v0", "reactive"),
        "sim": ("STCrowd-SimCrossing-v1", None)}
PER_SCENE_ONLY = {"fewshot"}  # no simulated-env version
STREAM_SEEDS, STREAM_STEPS = 20, 200  # open loop in the simulated crossing
RESAMPLES = 2000


def stream_job(spec: str, seeds: int, steps: int, output: str) -> None:
    """Grid job: best-of-20 ADE/FDE of ``spec`` on the simulated crossing's stream (spectator), per seed."""
    import gymnasium as gym

    import envs  # noqa: F401

    env = gym.make("STCrowd-SimCrossing-v1", ego=False, predictor=spec, max_episode_steps=steps + 1)
    per_seed = []
    for seed in range(seeds):
        env.reset(seed=seed)
        for _ in range(steps):
            *_, info = env.step(np.zeros(2))
        metrics = info["metrics"]
        per_seed.append({"ade": metrics["ade_m"], "fde": metrics["fde_m"], "matured": metrics["matured"]})
    write_text_atomic(output, strict_json.dumps({"spec": spec, "per_seed": per_seed}))


def cell_key(label: str) -> str:
    """A predictor's name in the cells' file names: its label and a digest of its spec, so that a label given to
    another spec (``--plugin mine=...`` changed) makes new cells instead of reusing the old spec's results."""
    return f"{label}-{hashlib.sha256(PREDICTORS[label].encode()).hexdigest()[:10]}"


def open_loop_of(env: str, label: str, out: Path) -> tuple[Job, Path]:
    """The job scoring a predictor open loop in an env, and its output."""
    spec = PREDICTORS[label]
    if env == "sim":
        output = out / "open" / f"sim__{cell_key(label)}.json"
        return Job(f"open/sim/{label}", "open_closed_loop:stream_job",
                   {"spec": spec, "seeds": STREAM_SEEDS, "steps": STREAM_STEPS, "output": str(output)},
                   str(output)), output
    source = f"shipped:stochastic/{env}" if spec == "singular" else spec
    output = out / "open" / f"{env}__{cell_key(label)}.json"
    return Job(f"open/{env}/{label}", "st_sim.apps.evaluate:evaluate_job",
               {"source": source, "task": "stochastic", "scene": env, "root": None, "stream": False,
                "momentary_from_8": False, "rerun_path": None, "output": str(output)}, str(output)), output


def open_loop_samples(env: str, result: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-unit FDE and ADE, and the unit of each (a window's samples, or a stream seed) for the bootstrap."""
    if env == "sim":
        rows = result["per_seed"]
        return (np.array([r["fde"] for r in rows], float), np.array([r["ade"] for r in rows], float),
                np.arange(len(rows)))
    sizes = np.asarray(result["window_sizes"])
    return (np.asarray(result["sample_fde"], float), np.asarray(result["sample_ade"], float),
            np.repeat(np.arange(len(sizes)), sizes))


def kendall(x: np.ndarray, y: np.ndarray) -> float:
    tau = stats.kendalltau(x, y).statistic
    return float(tau) if np.isfinite(tau) else 0.0


def study_env(env: str, labels: list[str], open_results: dict, closed_results: dict, seed: int = 0) -> dict:
    """Table rows and tau with bootstrap intervals for one env."""
    samples = {label: open_loop_samples(env, open_results[label]) for label in labels}
    units = samples[labels[0]][2]
    episodes = {label: closed_results[label]["episodes"] for label in labels}
    at_fault = np.array([[RATES["collision_at_fault"](e) for e in episodes[label]] for label in labels], float)
    failed = np.array([[e["outcome"] != "goal" for e in episodes[label]] for label in labels], float)
    fde = np.array([samples[label][0] for label in labels])  # (P, U) per sample/seed
    ade = np.array([samples[label][1] for label in labels])
    rng = np.random.default_rng(seed)
    n_units, n_episodes = units.max() + 1, at_fault.shape[1]
    point = {"fault": kendall(fde.mean(1), at_fault.mean(1)), "failure": kendall(fde.mean(1), failed.mean(1))}
    boot = {"fault": [], "failure": []}
    boot_fde = []  # (RESAMPLES, P) each predictor's mean FDE over the resampled units
    for _ in range(RESAMPLES):
        picked_units = rng.integers(0, n_units, n_units)
        rows = np.concatenate([np.flatnonzero(units == u) for u in picked_units])
        picked_episodes = rng.integers(0, n_episodes, n_episodes)
        open_fde = fde[:, rows].mean(1)
        boot_fde.append(open_fde)
        boot["fault"].append(kendall(open_fde, at_fault[:, picked_episodes].mean(1)))
        boot["failure"].append(kendall(open_fde, failed[:, picked_episodes].mean(1)))
    taus = {kind: {"tau": point[kind], "low": float(np.percentile(boot[kind], 2.5)),
                   "high": float(np.percentile(boot[kind], 97.5))} for kind in point}
    fde_low, fde_high = np.percentile(np.array(boot_fde), [2.5, 97.5], axis=0)
    rows = []
    for i, label in enumerate(labels):
        summary = closed_results[label]["summary"]
        rows.append({"predictor": label, "ade": float(ade[i].mean()), "fde": float(fde[i].mean()),
                     "fde_low": float(fde_low[i]), "fde_high": float(fde_high[i]),
                     **{name: summary[name]["value"] for name in ("success", "collision", "collision_at_fault",
                                                                  "timeout")},
                     "collision_at_fault_low": summary["collision_at_fault"]["low"],
                     "collision_at_fault_high": summary["collision_at_fault"]["high"]})
    return {"env": env, "rows": rows, "tau": taus}


def plot(study: list[dict], episodes: int, path: Path) -> Path:
    """One scatter panel per env: open-loop FDE (x, with its bootstrap interval) against the at-fault collision
    rate (y, with its Wilson interval), every point labelled with its predictor.

    Studies written before the intervals were kept have no FDE interval (drawn without one) and no collision
    interval (computed here from the rate and ``episodes``)."""
    panels = {}
    for part in study:
        env_id, mode = ENVS[part["env"]]
        tau = part["tau"]["fault"]
        title = (f"{env_id}{f' ({mode})' if mode else ''}\nKendall tau {tau['tau']:+.2f} "
                 f"[{tau['low']:+.2f}, {tau['high']:+.2f}]")
        points = []
        for row in part["rows"]:
            rate = row["collision_at_fault"]
            low, high = row.get("collision_at_fault_low"), row.get("collision_at_fault_high")
            if low is None:
                low, high = rate_interval(round(rate * episodes), episodes)
            x_interval = (row["fde_low"], row["fde_high"]) if "fde_low" in row else None
            points.append(ScatterPoint(row["predictor"], row["fde"], 100 * rate, x_interval, (100 * low, 100 * high)))
        panels[title] = points
    figure = interval_scatter("open-loop FDE, best of 20 [m]", f"at-fault collisions [% of {episodes} episodes]",
                              panels, title="MPC with each predictor: open-loop accuracy against closed-loop safety")
    return save_figure(figure, path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=list(ENVS), choices=list(ENVS), help="default: all three")
    parser.add_argument("--predictors", nargs="+", default=list(PREDICTORS), choices=list(PREDICTORS),
                        help="default: all eleven")
    parser.add_argument("--episodes", type=int, default=300, help="closed-loop episodes per cell (default: 300)")
    parser.add_argument("--out", default="runs/study", help="study folder (default: runs/study)")
    parser.add_argument("--plugin", action="append", default=[], metavar="LABEL=SPEC",
                        help="add a plug-in predictor package.module:name under LABEL (repeatable)")
    parser.add_argument("--replot", type=Path, default=None, metavar="STUDY_JSON",
                        help="only redraw the scatter plot of a study.json (written beside it as study.png)")
    add_grid_arguments(parser)
    args = parser.parse_args()
    if args.replot is not None:
        saved = json.loads(args.replot.read_text())
        print(f"wrote {plot(saved['study'], saved['episodes'], args.replot.with_name('study.png'))}")
        return
    for item in args.plugin:
        label, _, spec = item.partition("=")
        if not label or ":" not in spec or label in PREDICTORS:
            parser.error(f"--plugin {item!r}: expected a new LABEL=package.module:name")
        PREDICTORS[label] = spec  # jobs are made here, in the main process, with the spec itself
        args.predictors.append(label)
    out = Path(args.out).resolve()
    os.environ["STCROWD_STUDY_RUNS"] = str(out)  # where study_models finds the few-shot checkpoints (workers inherit)
    grid = {"executor": args.executor, "workers": args.workers, "address": args.ray_address}

    scenes = [env for env in args.envs if env != "sim"]
    if "fewshot" in args.predictors and scenes:
        training = []
        for scene in scenes:
            cfg = TrainConfig(task="fewshot", scene=scene, out=str(out / "fewshot" / scene / "seed0"), progress=False)
            training.append(Job(f"train/fewshot/{scene}", "predictor.train:train_job", asdict(cfg),
                                str(Path(cfg.out) / TRAIN_SUMMARY)))
        raise_on_failure(run_jobs(training, desc="train", **grid))
    cells = {(env, label) for env in args.envs for label in args.predictors
             if not (env == "sim" and label in PER_SCENE_ONLY)}
    open_jobs = {cell: open_loop_of(*cell, out) for cell in cells}
    closed_jobs = {}
    for env, label in cells:
        env_id, mode = ENVS[env]
        run = NavRun(env_id, "mpc", PREDICTORS[label], args.episodes, 0, pedestrians=mode)
        output = out / "closed" / f"{env}__{cell_key(label)}__{args.episodes}ep.json"
        closed_jobs[env, label] = grid_job(f"closed/{env}/{label}", run, output)
    jobs = [job for job, _ in open_jobs.values()] + list(closed_jobs.values())
    raise_on_failure(run_jobs(jobs, desc="cells", **grid))

    study = []
    for env in args.envs:
        labels = [label for label in args.predictors if (env, label) in cells]
        open_results = {label: json.loads(open_jobs[env, label][1].read_text()) for label in labels}
        closed_results = {label: json.loads(Path(closed_jobs[env, label].output).read_text()) for label in labels}
        part = study_env(env, labels, open_results, closed_results)
        study.append(part)
        env_id, mode = ENVS[env]
        print(f"\n### {env_id}{f', {mode} pedestrians' if mode else ''} (MPC, seeds 0..{args.episodes - 1})\n")
        print("| predictor | open-loop ADE / FDE [m] | success | collision (any) | at fault | timeout |")
        print("|---|---|---|---|---|---|")
        for row in sorted(part["rows"], key=lambda r: r["fde"]):
            print(f"| {row['predictor']} | {row['ade']:.3f} / {row['fde']:.3f} | {row['success']:.3f} | "
                  f"{row['collision']:.3f} | {row['collision_at_fault']:.3f} | {row['timeout']:.3f} |")
        for kind, text in (("fault", "at-fault collision rate"), ("failure", "failure rate (1 - success)")):
            tau = part["tau"][kind]
            print(f"\nKendall tau, FDE vs {text}: {tau['tau']:+.3f} (95 % bootstrap interval {tau['low']:+.3f} .. "
                  f"{tau['high']:+.3f})")
    write_text_atomic(out / "study.json", strict_json.dumps({"episodes": args.episodes, "study": study}, indent=1))
    print(f"\nwrote {out / 'study.json'} and {plot(study, args.episodes, out / 'study.png')}")


if __name__ == "__main__":
    main()
