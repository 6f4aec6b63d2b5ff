"""Evaluation through the environment: replay a scene's test recordings in the spectator env and score
each prediction once its 12-step ground truth has unfolded. It must agree with the offline windows.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

from predictor.protocol import Predictor
from replays.constants import TASKS
from replays.scenes import scene_info

ENV_TASK = {"stochastic": "stochastic", "deterministic": "deterministic", "momentary": "momentary",  # the env
            "fewshot": "stochastic", "domain": "deterministic", "domain_strict": "deterministic"}  # task, same T_obs, S


def evaluate_stream(predictor: Predictor, task: str, test_scene: str, root=None,
                    rerun_path: str | None = None, progress: bool = False) -> dict[str, float | int]:
    """Best-of-S ADE/FDE of ``predictor`` over every benchmark window of the scene's test recordings.

    Args:
        test_scene: the scene whose recordings are replayed (for a domain pair, its target).
        rerun_path: ``run.rrd`` -> one recording per replayed file, ``run_<recording>.rrd``.
        progress: show a progress bar over the replayed steps.

    Returns:
        {"samples", "ade", "fde"}: matured predictions and their mean errors in metres.
    """
    import envs  # noqa: F401  (registers the environments)

    info = scene_info(test_scene)
    t_obs = TASKS[task]["obs_len"]
    samples, ade_sum, fde_sum = 0, 0.0, 0.0
    for recording in info.recordings:
        rerun = None
        if rerun_path is not None:
            base = Path(rerun_path)
            rerun = str(base.with_name(f"{base.stem}_{recording}{base.suffix or '.rrd'}"))
        env = gym.make(f"STCrowd-{info.name.capitalize()}-v0", recording=recording, predictor=predictor,
                       task=ENV_TASK[task], ego=False, benchmark_windows=True, root=root, rerun=rerun,
                       max_episode_steps=10**7, disable_env_checker=True)
        env.reset(seed=0, options={"start_index": t_obs - 1})
        action = np.zeros(2, np.float32)
        total = len(env.unwrapped.replay.frames) - t_obs
        for _ in tqdm(range(total), desc=f"stream {recording}", unit="step", leave=False, disable=not progress):
            _, _, terminated, truncated, info_step = env.step(action)
            if terminated or truncated:
                break
        metrics = info_step["metrics"]
        if metrics["matured"]:  # ade_m / fde_m are None until a prediction matures
            samples += metrics["matured"]
            ade_sum += metrics["ade_m"] * metrics["matured"]
            fde_sum += metrics["fde_m"] * metrics["matured"]
        env.close()
    return {"samples": samples, "ade": ade_sum / samples if samples else None,
            "fde": fde_sum / samples if samples else None}
