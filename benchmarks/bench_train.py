"""PPO training throughput against one env, in the same run: env steps per second of ``train_ppo`` (updates included)
and of one env at one thread, with where the training's time goes.

    OMP_NUM_THREADS=1 python benchmarks/bench_train.py --minutes 3 --repeats 2
    python benchmarks/bench_train.py --minutes 3 --shards 1 2 --no-predictions
    python benchmarks/bench_train.py --suite --minutes 5 --shards 1 2     # the suite recipe's training envs

One env is SimCrossing-v1 as the shipped recipe sees it (SingularTrajectory forecasting every pedestrian, no sensor
limit), stepped by a goal-seeking robot with noise (the policy PPO meets early in training) at one torch thread
(``bench_env.single_rate``; CVM for ``--no-predictions``).
Training is ``python -m st_sim.apps.navigation.train_ppo`` with the shipped recipe's features (``--sensor-range inf
--closest-approach --extractor attention``) and its defaults otherwise (64 sub-envs, the given shards), from scratch
(short episodes: the most resets) for ``--minutes`` of wall time; its figure is the env steps it learnt per second,
rollouts and PPO updates included, with their shares of the time (``training.json``). The two alternate, one after
the other, in each repeat.

With ``--suite`` both run on the suite recipe's training envs (``docs/training.md``, "Training on the suite's train
split": the navigation suite's 14 scenarios other than ZARA1's and UNIV's, 56 sub-envs): one env steps
``--single-steps`` in each scenario's env in turn (all steps over all the time), and training is ``train_ppo
--scenarios all --hold-out zara1 univ``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from bench_env import single_rate  # benchmarks/ is the script's folder, first on sys.path

import predictor
from predictor.baselines import ConstantVelocity
from st_sim.apps.navigation import train_ppo
from st_sim.apps.navigation.training_envs import training_env

ENV_ID = "STCrowd-SimCrossing-v1"
SUITE_TRAINING = ["--scenarios", "all", "--hold-out", "zara1", "univ", "--num-envs", "56"]
"""train_ppo's flags for the suite recipe's training envs"""


def training_rate(minutes: float, shards: int, seed: int, use_predictions: bool, out: Path, suite: bool) -> dict:
    """``training.json``'s speed figures of a ``train_ppo`` run of ``minutes`` (the shipped recipe's features; with
    ``suite``, on the suite recipe's training envs)."""
    args = ["--timesteps", "100000000", "--minutes", str(minutes), "--sensor-range", "inf", "--closest-approach",
            "--extractor", "attention", "--shards", str(shards), "--seed", str(seed), "--device", "cpu",
            "--out", str(out), "--quiet"] + ([] if use_predictions else ["--no-predictions"]) + (
            SUITE_TRAINING if suite else [])
    train_ppo.main(train_ppo.parse_args(args))
    record = json.loads((out / "training.json").read_text())
    return {"env_steps_per_s": record["env_steps_per_s"], **record["time_shares"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=3.0, help="wall time of each training run (default: 3)")
    parser.add_argument("--single-steps", type=int, default=600, help="steps of the one-env run (default: 600)")
    parser.add_argument("--shards", type=int, nargs="+", default=[2], help="shards of the training runs (default: 2)")
    parser.add_argument("--repeats", type=int, default=1, help="alternating repeats (default: 1)")
    parser.add_argument("--no-predictions", action="store_true", help="the variant without forecasts")
    parser.add_argument("--suite", action="store_true", help="the suite recipe's 14 training scenarios")
    args = parser.parse_args()
    use_predictions = not args.no_predictions
    cfg = train_ppo.parse_args(SUITE_TRAINING) if args.suite else None
    envs_made = tuple(training_env(spec) for spec in cfg.env_ids) if cfg else ((ENV_ID, {}),)
    where = f"{len(envs_made)} suite scenarios" if args.suite else ENV_ID
    print(f"{where}, {'with' if use_predictions else 'without'} forecasts of every pedestrian; training: the shipped "
          f"recipe's features, {args.minutes:g} min per run from scratch")
    print("| repeat | configuration | env steps/s | ratio to one env | rollouts | PPO updates |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            model = predictor.load_pretrained("universal") if use_predictions else ConstantVelocity()
            single = single_rate(args.single_steps, repeat, model, 1, float("inf"), envs_made)
            print(f"| {repeat + 1} | one env, 1 thread | {single:.0f} | 1.00 | – | – |", flush=True)
            for shards in args.shards:
                figures = training_rate(args.minutes, shards, repeat, use_predictions,
                                        Path(scratch) / f"run{repeat}-{shards}", args.suite)
                rate, sub_envs = figures["env_steps_per_s"], 56 if args.suite else 64
                print(f"| {repeat + 1} | train_ppo, {sub_envs} sub-envs, {shards} shard(s) | {rate:.0f} | "
                      f"{rate / single:.2f} | {100 * figures['rollout']:.0f} % | {100 * figures['update']:.0f} % |",
                      flush=True)


if __name__ == "__main__":
    main()
