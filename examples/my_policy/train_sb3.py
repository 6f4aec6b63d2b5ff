"""Train a stable-baselines3 PPO policy on STCrowd with a few lines of your own, then benchmark it.

    python -m examples.my_policy.train_sb3 --steps 20000 --out runs/my_policy/suite.zip
    python -m st_sim benchmark --policy sb3:runs/my_policy/suite.zip --suite val --episodes 20 \\
        --out runs/bench/suite-val
    python -m examples.my_policy.train_sb3 --raw --steps 20000 --out runs/my_policy/raw.zip
    python -m st_sim benchmark --policy sb3:runs/my_policy/raw.zip --scenarios sim-crossing ...

The default trains on ``STCrowd-Suite-v1``: the suite's train split (seeds that are never val or test ones), a
scenario drawn per episode, every one seen through the same fixed-size view (``envs.view``: the 8 nearest people
with their histories and forecasts, 16 wall readings, in the robot's frame), so the model runs in every scenario of
the benchmark. ``--raw`` trains on one env's own Dict observation (its ego, history and history mask;
``FilterObservation``), which ``--policy sb3:PATH.zip`` feeds as it is: such a model fits only scenarios with as
many pedestrian slots as the env it was trained on. stable-baselines3 steps its own vector env (``make_vec_env``: one
``gym.make`` per copy).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from tqdm import tqdm

import envs  # noqa: F401  (registers STCrowd's ids)


class Progress(BaseCallback):
    """A progress bar over the env steps of ``learn``."""

    def __init__(self, total: int):
        super().__init__()
        self.bar = tqdm(total=total, desc="training", unit="step")

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=None, metavar="NAME",
                        help="suite scenarios to train on (default: all; `python -m st_sim benchmark --list`)")
    parser.add_argument("--raw", action="store_true", help="train on one env's own observation (see above)")
    parser.add_argument("--env", default="STCrowd-SimCrossing-v1", help="--raw: the env id to train on")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps of training")
    parser.add_argument("--predictor", default="cvm", choices=["none", "cvm", "singular"],
                        help="the forecasts the policy trains with (default: cvm, cheap); score it with the same "
                             "--predictor")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/my_policy/suite.zip", help="where the model is saved")
    args = parser.parse_args(argv)

    def make() -> gym.Env:
        if args.raw:
            env = gym.make(args.env, predictor="cvm")  # cheap forecasts; this model does not read them
            return gym.wrappers.FilterObservation(env, ["ego", "history", "history_mask"])
        return gym.make("STCrowd-Suite-v1", scenarios=args.scenarios, predictor=args.predictor)

    vec = make_vec_env(make, n_envs=4, seed=args.seed)
    model = PPO("MultiInputPolicy", vec, n_steps=128, batch_size=128, seed=args.seed, device="cpu", verbose=0)
    model.learn(total_timesteps=args.steps, callback=Progress(args.steps))
    model.save(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
