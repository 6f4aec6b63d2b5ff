"""The compiled reactive step (``st_sim.reactive.compiled``) against its reference, the plain numpy path: drawn crowds
round robots that cross or stand, in a square with walls or on open ground, round a disc robot or a vehicle, and the
replays UNIV and ZARA1 round a robot that chases their pedestrians, walk the same to the last bit (every field of
the state, every step); the kernels round as numpy does (sums, ties, NaN, ``arange``) and take the arctangent of
``st_sim.sim.exact``, find the same shortest walks as scipy, and drop their cached code when a file they compile in
changes."""

from __future__ import annotations

import ast
from dataclasses import fields

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reactive_draws import FRAMES, ROBOT, chase, robot_paths, scene_with_walls, straight_logs

import envs  # noqa: F401  (registers the ids)
from st_sim.reactive import compiled
from st_sim.reactive.compiled import exact
from st_sim.reactive.compiled.way_round import _shortest_walks
from st_sim.reactive.detour import grid_cells, walking_distance_m
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import Spread, draw_traits
from st_sim.reactive.reactive import ReactiveCrowd, ReactiveState
from st_sim.reactive.routes import OpenGround, Routes
from st_sim.sim import exact as numpy_exact

VEHICLE = Body(length_m=2.5, width_m=1.3, radius_m=0.1)  # a golf cart's box, as CITR's
DRAWS = settings(max_examples=12, deadline=None)
FITTED = Spread()  # every pedestrian the fitted one


def _state_bytes(state: ReactiveState) -> list[bytes]:
    return [np.ascontiguousarray(getattr(state, field.name)).tobytes() for field in fields(ReactiveState)]


def _walk(routes: Routes, robots: np.ndarray, lag: list[int], spread: Spread = FITTED,
          seed: int = 0) -> tuple[list[list[list[bytes]]], int]:
    """Every crowd's state (as bytes, field by field) after every step of crowds on ``routes`` stepped together, crowd
    i ``lag[i]`` frames late, its pedestrians' traits drawn with ``spread`` from ``seed``, and how many times a
    pedestrian took its way round."""
    crowds = [ReactiveCrowd.on(routes) for _ in lag]
    rng = np.random.default_rng(seed)
    for crowd, k in zip(crowds, lag, strict=True):
        crowd.reset(k, draw_traits(rng, routes.present.shape[1], spread))
    states, detours = [], 0
    for t in range(1, FRAMES - max(lag)):
        ReactiveCrowd.step_all(crowds, [k + t for k in lag], list(robots[:, t - 1]), list(robots[:, t]),
                               [None] * len(lag))
        states.append([_state_bytes(crowd.state) for crowd in crowds])
        detours += sum(int(crowd.state.detour.sum()) for crowd in crowds)
    return states, detours


def _first_difference(plain: list, fast: list) -> str:
    for t, (a, b) in enumerate(zip(plain, fast, strict=True)):
        for crowd, (x, y) in enumerate(zip(a, b, strict=True)):
            for field, u, v in zip(fields(ReactiveState), x, y, strict=True):
                if u != v:
                    return f"step {t + 1}, crowd {crowd}, field {field.name}"
    return "none"


@pytest.mark.parametrize("body", [ROBOT, VEHICLE], ids=["disc", "vehicle"])
@pytest.mark.parametrize("walls", [True, False], ids=["walls", "open-ground"])
@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(2, 16), crowds=st.integers(1, 3),
       spread=st.sampled_from([Spread(), Spread.even(0.5), Spread(room=1.0, patience=1.0)]))
def test_drawn_crowds_walk_the_same_compiled_and_plain(body: Body, walls: bool, seed: int, walkers: int,
                                                        crowds: int, spread: Spread) -> None:
    """Everybody the fitted pedestrian, or each with traits of its own: the same walks."""
    log, present = straight_logs(seed, walkers)
    routes = Routes(log, present, scene_with_walls() if walls else OpenGround(), body, 0.25)
    robots, lag = robot_paths(seed, crowds), [int(k) for k in np.random.default_rng(seed).integers(0, 4, crowds)]
    plain, _ = _walk(routes.stepped(False), robots, lag, spread, seed)
    fast, _ = _walk(routes.stepped(True), robots, lag, spread, seed)
    assert plain == fast, f"first difference at {_first_difference(plain, fast)}"


def test_a_crowd_round_a_parked_robot_takes_its_ways_round_the_same() -> None:
    """The way round, a grid search of its own in the kernels: a crowd crossing a robot parked by a wall."""
    log, present = straight_logs(7, 16)
    robots = np.zeros((2, FRAMES, 2))
    robots[1] = [-1.0, 1.5]  # in the corner of the block
    routes = Routes(log, present, scene_with_walls(), ROBOT, 0.25)
    plain, detours = _walk(routes.stepped(False), robots, [0, 2])
    fast, _ = _walk(routes.stepped(True), robots, [0, 2])
    assert detours > 0, "nobody took its way round: the test saw no grid search"
    assert plain == fast, f"first difference at {_first_difference(plain, fast)}"


@pytest.mark.parametrize("env_id", ["STCrowd-Univ-v0", "STCrowd-Zara1-v0"])
def test_replays_walk_the_same_compiled_and_plain(env_id: str) -> None:
    """A robot chasing the recorded pedestrians (many off their logs, some round it), episodes of three seeds: the
    compiled replay and the plain one, given the same actions, hold the same crowd after every step."""
    fast = gym.make(env_id, predictor="none", pedestrians="reactive", max_episode_steps=40)
    plain = gym.make(env_id, predictor="none", pedestrians="reactive", max_episode_steps=40)
    plain.unwrapped.reactive = ReactiveCrowd.on(fast.unwrapped.reactive.routes.stepped(False))
    assert fast.unwrapped.reactive.routes.compiled
    off_log = 0
    for seed in range(3):
        obs, _ = fast.reset(seed=seed)
        plain.reset(seed=seed)
        rng, done, t = np.random.default_rng(seed), False, 0
        while not done:
            action = chase({key: value[None] for key, value in obs.items()}, rng)[0]
            obs, reward, terminated, truncated, info = fast.step(action)
            _, reward_plain, *_ = plain.step(action)
            t += 1
            assert _state_bytes(fast.unwrapped.reactive.state) == _state_bytes(plain.unwrapped.reactive.state), \
                f"[seed {seed}, step {t}] the crowds differ"
            assert reward == reward_plain, f"[seed {seed}, step {t}]"
            off_log += info["off_log"]
            done = terminated or truncated
    assert off_log > 0, "nobody left its log: the test compared nothing compiled"


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), width=st.integers(1, 700), fill=st.floats(0.0, 1.0))
def test_sums_round_as_numpy_sums(seed: int, width: int, fill: float) -> None:
    rng = np.random.default_rng(seed)
    row = np.where(rng.random(width) < fill, rng.normal(size=width) * 10.0 ** rng.integers(-8, 4, width), 0.0)
    dense = np.stack([row, -row, np.abs(row)])
    for values, expected in zip(dense, dense.sum(axis=1), strict=True):
        assert exact.total(np.ascontiguousarray(values), width) == expected


def test_ties_nan_and_signed_zeros_as_numpy() -> None:
    values = [-0.0, 0.0, 1.0, -1.0, np.nan, np.inf, -np.inf]
    for a in values:
        for b in values:
            for ours, theirs in ((exact.maximum, np.maximum), (exact.minimum, np.minimum)):
                same = np.array(ours(a, b)).tobytes() == theirs(np.array([a]), np.array([b])).tobytes()
                assert same or (np.isnan(ours(a, b)) and np.isnan(theirs(a, b))), f"{theirs.__name__}({a}, {b})"
            for c in values:
                if np.isnan(b) or np.isnan(c):
                    continue
                ours, theirs = exact.clip(a, b, c), np.clip(np.array([a]), b, c)[0]
                same = np.array(ours).tobytes() == np.array(theirs).tobytes()
                assert same or (np.isnan(ours) and np.isnan(theirs)), f"clip({a}, {b}, {c})"


@settings(max_examples=200, deadline=None)
@given(start=st.floats(-50.0, 50.0), span=st.floats(0.0, 20.0), step=st.sampled_from([0.05, 0.1, 0.2, 1.0]))
def test_arange_as_numpy(start: float, span: float, step: float) -> None:
    assert exact.arange(start, start + span, step).tobytes() == np.arange(start, start + span, step).tobytes()


def test_arctangent_is_the_exact_one_to_the_bit() -> None:
    rng = np.random.default_rng(7)
    y, x = (rng.normal(size=20_000) * 10.0 ** rng.integers(-8, 8, 20_000) for _ in range(2))
    special = [0.0, -0.0, 1.0, -1.0, 0.5, 2.4375, 1e-300, 1e300, np.inf, -np.inf, np.nan]
    y = np.concatenate([y, x, np.repeat(special, len(special))])  # ... with x, equal magnitudes
    x = np.concatenate([x, x, np.tile(special, len(special))])
    theirs = numpy_exact.atan2(y, x)
    for i, (b, a) in enumerate(zip(y.tolist(), x.tolist(), strict=True)):
        ours = exact.atan2(b, a)
        assert np.array(ours).tobytes() == theirs[i].tobytes() or (np.isnan(ours) and np.isnan(theirs[i])), \
            f"atan2({b}, {a}): {ours} against {theirs[i]}"


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), open_share=st.floats(0.3, 1.0))
def test_shortest_walks_equal_scipys(seed: int, open_share: float) -> None:
    """Every cell of a grid with walls (a maze where few are free), from the bucket search of the kernels and from
    scipy's Dijkstra (``detour.walking_distance_m``)."""
    rng = np.random.default_rng(seed)
    low = rng.uniform(-5, 5, 2)
    grid = grid_cells(low, low + rng.uniform(0.3, 6.0, 2))
    free = rng.random(grid.shape[:2]) < open_share
    row, col = rng.integers(grid.shape[0]), rng.integers(grid.shape[1])
    free[row, col] = True
    ours = _shortest_walks(free, row, col, np.ones(free.shape, bool))
    theirs = walking_distance_m(grid, free, grid[row, col], grid.reshape(-1, 2)).reshape(free.shape)
    assert ours.tobytes() == theirs.tobytes(), f"{int((ours != theirs).sum())} cells differ"


def test_every_module_the_kernels_import_from_is_a_source_of_their_cache() -> None:
    """``compiled.SOURCES`` lists every file of this repository the kernels take code or constants from, so that a
    change to any of them drops the cached kernels."""
    kernels = set(compiled.PACKAGE.glob("*.py")) - {compiled.PACKAGE / "__init__.py"}  # (its imports compile nothing)
    for path in kernels:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in ("replays", "st_sim"):
                source = node.module.replace(".", "/") + ".py"
                assert source in compiled.SOURCES or node.module == "st_sim.reactive.compiled", \
                    f"{path.name} imports {node.module}, not in compiled.SOURCES"


def test_cached_kernels_are_dropped_when_a_source_changes(tmp_path) -> None:
    package, cache = tmp_path / "kernels", tmp_path / "kernels" / "__pycache__"
    cache.mkdir(parents=True)
    (tmp_path / "constants.py").write_text("STEP_S = 0.4\n")
    sources = ("constants.py",)
    compiled.drop_stale_caches(package, tmp_path, sources)  # the first stamp
    for name in ("choose._best-1.py311.nbi", "choose._best-1.py311.1.nbc"):
        (cache / name).write_text("machine code")
    compiled.drop_stale_caches(package, tmp_path, sources)
    assert len(list(cache.glob("*.nb?"))) == 2, "kernels dropped although nothing changed"
    (tmp_path / "constants.py").write_text("STEP_S = 0.5\n")
    compiled.drop_stale_caches(package, tmp_path, sources)
    assert not list(cache.glob("*.nb?")), "kernels compiled with the old constant kept"



def test_a_fresh_install_is_told_once_that_the_kernels_compile(tmp_path, monkeypatch, capsys) -> None:
    package = tmp_path / "kernels"
    (package / "__pycache__").mkdir(parents=True)
    monkeypatch.setattr(compiled, "_announced", False)
    assert compiled.announce_compiling(package) and "compiling" in capsys.readouterr().err
    assert not compiled.announce_compiling(package) and not capsys.readouterr().err  # once per process
    monkeypatch.setattr(compiled, "_announced", False)
    (package / "__pycache__" / "choose._best-1.py311.nbi").write_text("index")
    assert not compiled.announce_compiling(package) and not capsys.readouterr().err  # cached: nothing to say
