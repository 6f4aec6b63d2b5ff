"""The demo: the simulated crossing with a goal-seeking ego, metrics printed, optional Rerun recording."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from replays.constants import T_PRED
from st_sim.apps.demo import goal_seeking_action, run_demo


def observation(ego_xy: tuple[float, float], goal: tuple[float, float], peds: list[tuple[float, float]],
                velocity: tuple[float, float] = (0.0, 0.0)) -> dict[str, np.ndarray]:
    """A 4-row observation; pedestrians keep ``velocity`` [m per step] in their predicted futures."""
    obs = {"ego": np.array([*ego_xy, 0, 0, *goal], np.float32),
           "history": np.zeros((4, 8, 2), np.float32), "history_mask": np.zeros((4, 8), bool),
           "futures": np.zeros((4, 1, T_PRED, 2), np.float32), "futures_mask": np.zeros(4, bool)}
    steps = np.arange(1, T_PRED + 1)[:, None]
    for row, xy in enumerate(peds):
        obs["history"][row] = xy
        obs["history_mask"][row] = True
        obs["futures"][row, 0] = np.array(xy) + steps * np.array(velocity)
        obs["futures_mask"][row] = True
    return obs


def test_demo_ego_heads_straight_for_a_free_goal() -> None:
    velocity = goal_seeking_action(observation((0, 0), (10, 0), []), 1.5, 0.55)
    assert velocity.tolist() == pytest.approx([1.5, 0.0])


def test_demo_ego_keeps_clear_of_a_pedestrian_coming_at_it() -> None:
    obs = observation((0, 0), (10, 0), [(2.0, 0.0)], velocity=(-0.5, 0.0))  # head-on, 1.25 m/s
    velocity = goal_seeking_action(obs, 1.5, 0.55)
    ego_path = velocity * 0.4 * np.arange(1, 5)[:, None]
    ped_path = obs["futures"][0, 0, :4]
    assert np.linalg.norm(ego_path - ped_path, axis=1).min() >= 0.55, f"chose {velocity}"


def test_demo_runs_prints_metrics_and_writes_a_recording(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = tmp_path / "demo.rrd"
    result = run_demo(steps=20, rerun_path=str(path), seed=1)
    assert path.is_file() and path.stat().st_size > 0
    assert sum(e["steps"] for e in result["episodes"]) == 20
    assert {"ade_m", "fde_m", "map_violation", "min_ego_ped_distance_m", "outcome"} <= set(result["episodes"][0])
    assert "episode 0:" in capsys.readouterr().out
    again = run_demo(steps=20, rerun_path=None, seed=1)
    assert [e["return"] for e in again["episodes"]] == [e["return"] for e in result["episodes"]]
