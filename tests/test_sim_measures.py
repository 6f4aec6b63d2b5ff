"""Crowd measures and recording statistics: Weidmann's curve, lane order, flows, standing spells, groups, halves."""

from __future__ import annotations

import numpy as np
import pytest

from replays.constants import FRAME_STRIDE
from replays.recording import Recording
from st_sim.sim import Period
from st_sim.sim.crowd_stats import Steps, halves, standing_steps, walker_speeds_mps, walking_groups
from st_sim.sim.measures import lane_index, steady_flow_per_s, weidmann_speed_mps


def test_weidmann_speed_matches_the_published_curve() -> None:
    speeds = weidmann_speed_mps(np.array([0.5, 1.0, 2.0, 3.0, 5.4, 6.0]))
    np.testing.assert_allclose(speeds[:4], [1.30, 1.06, 0.61, 0.33], atol=0.01)
    assert speeds[4] == pytest.approx(0.0, abs=1e-9) and speeds[5] == 0.0


def test_lane_index_is_one_for_lanes_and_low_for_a_mixed_flow() -> None:
    x = np.arange(0.0, 20.0, 0.8)
    lanes = np.concatenate([np.stack([x, np.full_like(x, y)], axis=-1) for y in (1.0, 2.0, 3.0, 4.0)])
    sign = np.repeat([1, -1, 1, -1], len(x))
    assert lane_index(lanes, sign, 0.3, 3.0) == pytest.approx(1.0)
    alternating = np.where(np.arange(len(lanes)) % 2 == 0, 1, -1)
    assert lane_index(lanes, alternating, 0.3, 3.0) < 0.2


def test_lane_index_sees_lanes_across_a_periodic_seam() -> None:
    xy = np.array([[0.2, 1.0], [19.8, 1.0], [10.0, 3.0]])
    sign = np.array([1, 1, -1])
    assert lane_index(xy, sign, 0.3, 1.0, Period(0.0, 20.0)) == pytest.approx(2 / 3)
    assert lane_index(xy, sign, 0.3, 1.0) == 0.0


def test_steady_flow_counts_passages_between_the_skipped_ends() -> None:
    times = np.r_[0.0, 0.1, np.arange(10.0, 20.0, 0.5), 50.0, 60.0]
    assert steady_flow_per_s(times, 2) == pytest.approx(19 / 9.5)
    assert steady_flow_per_s(times[:3], 2) == 0.0


def _recording(tracks: dict[int, np.ndarray]) -> Recording:
    """Agent id -> (T, 2) positions [m], one per frame from frame 0."""
    frame = np.concatenate([FRAME_STRIDE * np.arange(len(xy)) for xy in tracks.values()])
    agent = np.concatenate([np.full(len(xy), a) for a, xy in tracks.items()])
    return Recording("toy", frame, agent, np.concatenate(list(tracks.values())))


def test_standing_spells_need_three_slow_steps_in_a_row() -> None:
    walk = np.cumsum(np.full((12, 2), [0.5, 0.0]), axis=0)  # 1.25 m/s
    stop = np.r_[walk[:4], np.repeat(walk[3:4], 4, axis=0), walk[4:] + 0.0]  # stands for 4 steps
    blip = np.r_[walk[:4], walk[3:4], walk[4:]]  # one slow step only
    steps = Steps.of(_recording({0: stop, 1: blip}))
    standing, spells = standing_steps(steps)
    assert spells.tolist() == [4]
    assert standing[steps.agent == 0].sum() == 4 and not standing[steps.agent == 1].any()
    np.testing.assert_allclose(walker_speeds_mps(steps, standing), [1.25, 1.25])


def test_walking_groups_finds_a_pair_but_not_strangers_passing() -> None:
    t = np.arange(10)[:, None]
    along = np.c_[0.5 * t, np.zeros_like(t, dtype=float)]
    beside, back = np.array([0.0, 0.7]), np.array([0.0, 1.0])
    tracks = {0: along, 1: along + beside, 2: along[::-1] + back}  # a pair, and one walking the other way
    steps = Steps.of(_recording(tracks))
    share, triples = walking_groups(steps, standing_steps(steps)[0])
    assert share == pytest.approx(2 / 3) and triples == 0.0


def test_halves_split_at_the_middle_frame() -> None:
    rec = _recording({0: np.zeros((10, 2)), 1: np.ones((4, 2))})
    first, second = halves(rec)
    assert len(first.frame) + len(second.frame) == len(rec.frame)
    assert first.frame.max() < second.frame.min()
