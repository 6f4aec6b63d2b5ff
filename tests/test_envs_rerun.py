"""An environment with rerun= writes one recording with agents, predictions, both anchor sets and metrics."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from rrd_files import read_rrd

import envs  # noqa: F401


def test_replay_env_rerun_recording_holds_predictions_and_anchors(tmp_path):
    out = tmp_path / "zara1.rrd"
    env = gym.make("STCrowd-Zara1-v0", ego=False, rerun=str(out))
    env.reset(seed=0, options={"start_index": 20})
    for _ in range(15):  # predictions of the first step mature after 12 more
        env.step(np.zeros(2, np.float32))
    env.close()
    paths = set(read_rrd(out))
    for expected in ("/world/agents", "/world/trails", "/world/anchors/prototype", "/world/anchors/adapted",
                     "/world/scene/photo", "/metrics/metres/ade_m",
                     "/metrics/reward/reward", "/metrics/share/map_violation", "/metrics/count/matured"):
        assert expected in paths, (expected, sorted(paths))
    assert any(p.startswith("/world/predictions/") for p in paths)
