"""What the PPO trainer's envs give, kept to compare two commits: the suite recipe's training scenarios stepped with
fixed actions, one SHA-256 line per step.

    git worktree add ../base a68cc14
    (cd ../base && PYTHONPATH=. python "$OLDPWD/benchmarks/training_digest.py" --out "$OLDPWD/runs/train-base")
    python benchmarks/training_digest.py --out runs/train-head
    python benchmarks/training_digest.py --compare runs/train-base runs/train-head

``training_envs.FeatureVecEnv`` over the navigation suite's 14 training scenarios (``train_ppo --scenarios all
--hold-out zara1 univ``'s, every episode from the train split) with ``--num-envs`` sub-envs, in one process, with the
shipped recipe's features (SingularTrajectory forecasts, closest approach), stepped ``--steps`` times with seeded
actions that do not depend on what the envs return (so that both commits drive the same robots). Each line hashes
one step's features without the forecast columns, rewards, dones, and the ended episodes' termination and final
features without forecasts; the forecast columns of every step go to ``forecasts.npz``. ``--compare`` prints how many
lines differ and the largest difference of the forecast features (a larger torch batch rounds otherwise in the last
bits; the worlds must agree bit for bit).
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import numpy as np

from envs.common.config import EnvConfig
from envs.suite import load_suite
from replays.atomic import atomic_path, write_text_atomic
from st_sim.apps.navigation import train_ppo
from st_sim.apps.navigation.features import FeatureConfig, drop_predictions
from st_sim.apps.navigation.training_envs import FeatureVecEnv

LINES, FORECASTS = "steps.txt", "forecasts.npz"  # what --out writes
SUITE_TRAINING = ["--scenarios", "all", "--hold-out", "zara1", "univ", "--sensor-range", "inf", "--closest-approach"]


def run(num_envs: int, steps: int, seed: int) -> tuple[list[str], np.ndarray]:
    """(one digest line per step, (steps + 1, num_envs, forecast columns) float32 forecast features)."""
    cfg = train_ppo.parse_args([*SUITE_TRAINING, "--num-envs", str(num_envs)])
    vec = FeatureVecEnv(cfg.env_ids, num_envs, cfg.features, EnvConfig(reward=cfg.reward), 1, "cpu",
                        load_suite().train)
    vec.seed(seed)
    features = vec.reset()
    forecast_columns = ~np.isin(np.arange(features.shape[1]), _kept_columns(features.shape[1], cfg.features))
    lines, forecasts = [], [features[:, forecast_columns]]
    rng = np.random.default_rng(seed)
    for t in range(steps):
        actions = np.clip(rng.normal([0.8, 0.0], 0.5, (num_envs, 2)), -1.0, 1.0).astype(np.float32)
        vec.step_async(actions)
        features, rewards, dones, infos = vec.step_wait()
        digest = hashlib.sha256()
        for part in (drop_predictions(features, cfg.features), rewards, dones):
            digest.update(np.ascontiguousarray(part).tobytes())
        for i in np.flatnonzero(dones):
            digest.update(f"{i}:{infos[i]['termination']}".encode())
            digest.update(drop_predictions(infos[i]["terminal_observation"][None], cfg.features).tobytes())
        lines.append(f"{t} {int(dones.sum())} {digest.hexdigest()}")
        forecasts.append(features[:, forecast_columns])
    vec.close()
    return lines, np.stack(forecasts)


def _kept_columns(size: int, features: FeatureConfig) -> np.ndarray:
    """The feature columns that are not forecasts (``drop_predictions`` keeps them)."""
    probe = np.arange(size, dtype=np.float64)[None]
    return drop_predictions(probe, features)[0].astype(np.int64)


def compare(base: Path, head: Path) -> None:
    lines = [(folder / LINES).read_text().splitlines() for folder in (base, head)]
    differ = sum(a != b for a, b in zip(*lines, strict=True))
    ended = sum(int(line.split()[1]) for line in lines[0])
    forecasts = [np.load(folder / FORECASTS)["features"] for folder in (base, head)]
    print(f"steps differing: {differ} of {len(lines[0])} ({ended} episodes ended); largest difference of a "
          f"forecast feature: {float(np.abs(forecasts[0] - forecasts[1]).max()):.3g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="folder to write steps.txt and forecasts.npz into")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("BASE", "HEAD"), help="compare two --out folders")
    parser.add_argument("--num-envs", type=int, default=28, help="sub-envs, two per scenario (default: 28)")
    parser.add_argument("--steps", type=int, default=150, help="steps (default: 150)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    if args.compare:
        compare(*args.compare)
        return
    if args.out is None:
        parser.error("give --out or --compare")
    lines, forecasts = run(args.num_envs, args.steps, args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out / LINES, "\n".join(lines) + "\n")
    with atomic_path(args.out / FORECASTS) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(handle, features=forecasts)
    print(f"{len(lines)} steps written to {args.out}")


if __name__ == "__main__":
    main()
