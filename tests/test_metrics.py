from __future__ import annotations

import numpy as np
import pytest

from st_sim.metrics import ade_fde, collision_rate, map_violation, path_map_violation, same_group_pairs


def test_ade_fde_hand_computed_and_minimised_independently():
    gt = np.zeros((1, 2, 2))
    pred = np.array([[[[3.0, 4.0], [0.0, 0.0]],     # errors 5, 0 -> ADE 2.5, FDE 0
                      [[1.0, 0.0], [1.0, 0.0]]]])   # errors 1, 1 -> ADE 1.0, FDE 1
    ade, fde = ade_fde(pred, gt)
    assert ade.tolist() == [1.0] and fde.tolist() == [0.0]


def test_ade_fde_rejects_bad_shapes_and_nan():
    with pytest.raises(ValueError, match="pred must be"):
        ade_fde(np.zeros((2, 12, 2)), np.zeros((2, 12, 2)))
    with pytest.raises(ValueError, match="gt must be"):
        ade_fde(np.zeros((2, 3, 12, 2)), np.zeros((2, 11, 2)))
    with pytest.raises(ValueError, match="NaN"):
        ade_fde(np.full((1, 1, 12, 2), np.nan), np.zeros((1, 12, 2)))


def test_map_violation_counts_points_and_paths(toy_scene):
    paths = np.array([[[1.0, 1.0], [2.0, 1.0], [6.0, 1.0], [7.0, 1.0]],   # 2 of 4 points off
                      [[1.0, 1.0], [1.0, 2.0], [1.0, 3.0], [1.0, 4.0]]])  # all on
    assert map_violation(paths, toy_scene) == pytest.approx(0.25)
    assert path_map_violation(paths, toy_scene) == pytest.approx(0.5)


def test_same_group_pairs_lists_each_pair_once():
    first, second = same_group_pairs(np.array([0, 1, 0, 2, 1, 0]))
    pairs = sorted(tuple(sorted(p)) for p in zip(first.tolist(), second.tolist(), strict=False))
    assert pairs == [(0, 2), (0, 5), (1, 4), (2, 5)]


def test_collision_rate_hand_case():
    t = np.arange(3, dtype=float)
    walk = np.stack([t, np.zeros(3)], -1)
    pred = np.stack([
        np.stack([walk, walk]),                         # agent 0, two samples
        np.stack([walk + np.array([0, 0.1]), walk + np.array([0, 5.0])]),   # agent 1: sample 0 collides, sample 1 not
        np.stack([walk, walk]),                         # agent 2, alone in its window
    ])
    assert collision_rate(pred, np.array([0, 0, 1])) == pytest.approx(0.5)
    assert collision_rate(pred, np.array([0, 1, 2])) is None, "no window holds two agents: n/a, not 0"
