"""The batched reactive step (``st_sim.reactive.reactive``, ``st_sim.reactive.choosing``): crowds stepped together walk
as each alone, its shortcuts (bounded scoring, only the pairs within reach) change no walk, its sums round as numpy's
(``st_sim.reactive.ragged``), and a native vector env of reactive replays is N single envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reactive_draws import FRAMES, ROBOT, chase, robot_paths, scene_with_walls, straight_logs

import envs  # noqa: F401  (registers the ids)
from st_sim.reactive import choosing
from st_sim.reactive.detour import grid_cells, walking_distance_m, walking_distances_m
from st_sim.reactive.ragged import exact_row_sums
from st_sim.reactive.reactive import ReactiveCrowd
from st_sim.reactive.routes import Routes

DRAWS = settings(max_examples=10, deadline=None)


def _walk(crowds: list[ReactiveCrowd], robots: np.ndarray, lag: list[int], together: bool) -> np.ndarray:
    """(N, F, A, 2) every crowd's positions; crowd i starts ``lag[i]`` frames late (the crowds at other frames); with
    ``together`` all step in one ``step_all`` call, else each alone."""
    paths = [[crowd.reset(k).copy()] for crowd, k in zip(crowds, lag, strict=True)]
    for t in range(1, FRAMES - max(lag)):
        index = [k + t for k in lag]
        if together:
            out = ReactiveCrowd.step_all(crowds, index, list(robots[:, t - 1]), list(robots[:, t]), [None] * len(lag))
        else:
            out = [crowd.step(i, robot[t - 1], robot[t]) for crowd, i, robot in zip(crowds, index, robots, strict=True)]
        for path, xy in zip(paths, out, strict=True):
            path.append(xy.copy())
    return np.array(paths)


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "plain"])
@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(2, 14), crowds=st.integers(2, 4))
def test_crowds_stepped_together_walk_as_each_alone(compiled: bool, seed: int, walkers: int, crowds: int) -> None:
    log, present = straight_logs(seed, walkers)
    routes = Routes(log, present, scene_with_walls(), ROBOT, 0.25, compiled=compiled)
    robots, lag = robot_paths(seed, crowds), [int(k) for k in np.random.default_rng(seed).integers(0, 4, crowds)]
    alone = _walk([ReactiveCrowd.on(routes) for _ in range(crowds)], robots, lag, together=False)
    together = _walk([ReactiveCrowd.on(routes) for _ in range(crowds)], robots, lag, together=True)
    assert np.array_equal(alone, together, equal_nan=True), \
        f"first difference at (crowd, frame, agent) {np.argwhere(~((alone == together) | np.isnan(alone)))[0][:3]}"


@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(2, 14))
def test_scoring_every_candidate_against_everybody_changes_no_walk(seed: int, walkers: int) -> None:
    """The shortcuts: a pedestrian scores in full only the candidates that could still be chosen, and the others
    only where they are within reach; scoring everything against everybody chooses the same places (the plain path,
    whose shortcuts the compiled one takes too, ``tests/test_reactive_compiled.py``)."""
    log, present = straight_logs(seed, walkers)
    robots = robot_paths(seed, 1)
    shortcut = _walk([ReactiveCrowd(log, present, scene_with_walls(), ROBOT, 0.25, compiled=False)], robots, [0],
                     together=True)

    def everybody(step, rows, agents, c):
        near = step.present[rows] & (np.arange(step.present.shape[1]) != agents[:, None])
        return np.nonzero(near)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(choosing, "FIRST_LOOK", 10**9)
        patch.setattr(choosing, "_near_pairs", everybody)
        full = _walk([ReactiveCrowd(log, present, scene_with_walls(), ROBOT, 0.25, compiled=False)], robots, [0],
                     together=True)
    assert np.array_equal(shortcut, full, equal_nan=True), \
        f"first difference at (frame, agent) {np.argwhere(~((shortcut == full) | np.isnan(full)))[0][1:3]}"


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**31), rows=st.integers(1, 30), width=st.integers(1, 200), fill=st.floats(0.0, 1.0))
def test_sparse_row_sums_round_as_numpy_sums_the_dense_rows(seed: int, rows: int, width: int, fill: float) -> None:
    rng = np.random.default_rng(seed)
    dense = np.where(rng.random((rows, width)) < fill, rng.random((rows, width)) * 10.0 ** rng.integers(-8, 3), 0.0)
    row, column = np.nonzero(rng.random((rows, width)) < 2)  # every entry, zeros too, in a shuffled order
    order = rng.permutation(len(row))
    sums = exact_row_sums(row[order], column[order], dense[row, column][order], np.full(rows, width), rows)
    assert np.array_equal(sums, dense.sum(axis=1)), f"{np.flatnonzero(sums != dense.sum(axis=1))[:5]} differ"


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31), grids=st.integers(1, 5))
def test_ways_round_of_several_grids_in_one_search_equal_each_grid_alone(seed: int, grids: int) -> None:
    rng = np.random.default_rng(seed)
    cells, free, goals, points = [], [], [], []
    for _ in range(grids):
        low = rng.uniform(-5, 5, 2)
        grid = grid_cells(low, low + rng.uniform(0.5, 4.0, 2))
        cells.append(grid)
        free.append(rng.random(grid.shape[:2]) < 0.8)
        goals.append(grid[rng.integers(grid.shape[0]), rng.integers(grid.shape[1])])
        points.append(grid.reshape(-1, 2)[rng.integers(grid.shape[0] * grid.shape[1], size=6)] + 0.01)
    together = walking_distances_m(cells, free, np.array(goals), points)
    for g in range(grids):
        alone = walking_distance_m(cells[g], free[g], goals[g], points[g])
        assert np.array_equal(together[g], alone), f"grid {g}: {together[g]} vs {alone}"


@pytest.mark.parametrize("env_id", ["STCrowd-Univ-v0", "STCrowd-Zara1-v0"])
@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 10_000), num_envs=st.integers(2, 5))
def test_a_reactive_vector_env_equals_single_envs(env_id: str, seed: int, num_envs: int) -> None:
    """Sub-env i of ``make_vec`` (its crowds stepped in one batched call) and ``gym.make`` reset with seed + i, given
    the same actions: the same observations, rewards, ends and infos, and pedestrians in the same places."""
    kwargs = {"pedestrians": "reactive", "predictor": "cvm", "max_episode_steps": 60}
    vec = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    singles = [gym.make(env_id, **kwargs) for _ in range(num_envs)]
    obs, _ = vec.reset(seed=seed)
    alone = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    rng = np.random.default_rng(seed)
    off_log, ended = 0, np.zeros(num_envs, bool)
    for t in range(25):
        actions = chase(obs, rng)
        obs, reward, terminated, truncated, info = vec.step(actions)
        for i, env in enumerate(singles):
            if ended[i]:  # the vector env resets it this step (NEXT_STEP autoreset)
                alone[i], _ = env.reset()
                continue
            alone[i], r, term, trunc, single_info = env.step(actions[i])
            where = f"[sub-env {i}, step {t}]"
            for key in ("ego", "history", "history_mask", "futures_mask"):
                assert np.array_equal(obs[key][i], alone[i][key]), f"{where} {key}"
            np.testing.assert_allclose(obs["futures"][i], alone[i]["futures"], rtol=0, atol=1e-5, err_msg=where)
            assert (reward[i], terminated[i], truncated[i]) == (r, term, trunc), where
            assert info["off_log"][i] == single_info["off_log"], where
            assert info["log_deviation_m"][i] == single_info["log_deviation_m"], where
            assert np.array_equal(vec.envs[i].reactive.state.xy_m, env.unwrapped.reactive.state.xy_m,
                                  equal_nan=True), f"{where} pedestrians differ"
            off_log += single_info["off_log"]
        ended = terminated | truncated
    assert off_log > 0, "no pedestrian ever left its log: the test saw nothing batched"
    vec.close()
