"""Native vector envs (``envs.vector_env``): the same episodes as gymnasium's ``SyncVectorEnv`` over single envs,
step by step and through autoresets, with one batched forecast per step."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.envs.registration import registry
from gymnasium.vector import AutoresetMode
from hypothesis import given, settings
from hypothesis import strategies as st
from ray_session import OBJECT_STORE_BYTES, connect_kwargs

import envs  # noqa: F401  (registers the ids)
from envs import STCROWD_IDS
from envs.common.errors import EnvInputError, NeedsResetError

CASES = {  # id -> extra env arguments: SingularTrajectory in one (the batched call that matters), CVM-S elsewhere
    "STCrowd-SimCrossing-v1": {},
    "STCrowd-SimZara1-v1": {"predictor": "cvm-s"},  # a real scene's geometry: crowds stepped together there too
    "STCrowd-Zara1-v0": {"predictor": "cvm-s"},
    "STCrowd-Univ-v0": {"pedestrians": "reactive", "predictor": "cvm-s"},
}
SHORT = 12  # steps per episode, so that every run goes through autoresets


def make_pair(env_id: str, num_envs: int, autoreset_mode: AutoresetMode = AutoresetMode.NEXT_STEP, **kwargs):
    vec = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", max_episode_steps=SHORT,
                       autoreset_mode=autoreset_mode, **kwargs)
    sync = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync", max_episode_steps=SHORT,
                        vector_kwargs={"autoreset_mode": autoreset_mode}, **kwargs)
    assert vec.metadata["autoreset_mode"] == sync.metadata["autoreset_mode"] == autoreset_mode
    return vec, sync


def assert_same_step(ours, theirs, where: str) -> None:
    obs, obs_sync = ours[0], theirs[0]
    for key in obs_sync:
        if key == "futures":  # one larger predictor batch: float rounding only
            np.testing.assert_allclose(obs[key], obs_sync[key], rtol=0, atol=1e-4, err_msg=f"{where} {key}")
        else:
            assert np.array_equal(obs[key], obs_sync[key]), f"{where}: {key}"
    for index, name in ((1, "reward"), (2, "terminated"), (3, "truncated"))[:len(ours) - 2]:  # none after a reset
        assert np.array_equal(ours[index], theirs[index]), f"{where}: {name} {ours[index]} vs {theirs[index]}"
    info, info_sync = ours[-1], theirs[-1]
    assert info.keys() == info_sync.keys(), where
    for key in {"agent_ids", "predicted_ids", "termination", "at_fault", "frame"} & info_sync.keys():
        assert same(info[key], info_sync[key]), f"{where}: info[{key!r}] {info[key]} vs {info_sync[key]}"
    if "final_obs" in info_sync:  # SAME_STEP: the last observation and info of the episodes that ended
        assert_same_nested(info["final_obs"], info_sync["final_obs"], f"{where}, final_obs")
        assert_same_nested(info["final_info"], info_sync["final_info"], f"{where}, final_info")


def assert_same_nested(ours, theirs, where: str) -> None:
    """Batched infos (dicts of arrays, nested) equal; predicted futures, and the prediction metrics computed from them,
    up to float rounding."""
    if isinstance(theirs, Mapping):
        assert ours.keys() == theirs.keys(), where
        for key in theirs:
            assert_same_nested(ours[key], theirs[key], f"{where}[{key!r}]")
    elif isinstance(theirs, np.ndarray) and theirs.dtype == object:  # e.g. one observation dict per sub-env
        assert ours.shape == theirs.shape, where
        for i, (mine, other) in enumerate(zip(ours.ravel(), theirs.ravel(), strict=True)):
            assert_same_nested(mine, other, f"{where}[{i}]")
    elif where.endswith("['futures']"):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-4, err_msg=where)
    elif "['metrics']" in where and isinstance(theirs, float):
        assert ours == pytest.approx(theirs, abs=1e-4), where
    else:
        assert same(ours, theirs), where


def same(a, b) -> bool:
    """Equal values, element by element through object arrays (which hold None, text or arrays)."""
    if isinstance(a, np.ndarray) and a.dtype == object:
        return a.shape == b.shape and all(same(x, y) for x, y in zip(a.ravel(), b.ravel(), strict=True))
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else a == b


@pytest.mark.parametrize("autoreset_mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id", CASES)
@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 10_000), num_envs=st.integers(1, 4))
def test_vector_env_equals_sync_vector_env_step_by_step(env_id: str, autoreset_mode: AutoresetMode, seed: int,
                                                        num_envs: int) -> None:
    vec, sync = make_pair(env_id, num_envs, autoreset_mode, **CASES[env_id])
    rng = np.random.default_rng(seed)
    ours, theirs = vec.reset(seed=seed), sync.reset(seed=seed)
    assert_same_step((ours[0], ours[1]), (theirs[0], theirs[1]), "reset")
    ends = 0
    for t in range(2 * SHORT + 3):
        actions = rng.uniform(-1.6, 1.6, (num_envs, 2)).astype(np.float32)
        ours, theirs = vec.step(actions), sync.step(actions)
        assert_same_step(ours, theirs, f"seed {seed}, step {t}")
        ends += int((ours[2] | ours[3]).sum())
    assert ends >= num_envs, "every sub-env ends an episode (the time limit) and is reset"
    vec.close(), sync.close()


def test_a_bad_action_in_one_sub_env_moves_none_of_them() -> None:
    vec, sync = make_pair("STCrowd-SimCrossing-v1", 3)
    vec.reset(seed=1), sync.reset(seed=1)
    bad = np.zeros((3, 2), np.float32)
    bad[2, 0] = np.nan
    with pytest.raises(EnvInputError, match="finite"):
        vec.step(bad)
    with pytest.raises(EnvInputError, match="shape"):
        vec.step(np.zeros((2, 2), np.float32))
    good = np.full((3, 2), 0.5, np.float32)
    assert_same_step(vec.step(good), sync.step(good), "after the refused actions")


@pytest.mark.parametrize("env_id", STCROWD_IDS)
def test_every_id_has_a_native_vector_entry_point(env_id: str) -> None:
    assert registry[env_id].vector_entry_point is not None


@pytest.mark.parametrize("kwargs, match", [({"num_envs": 0}, "num_envs"), ({"num_envs": 2, "rerun": "x.rrd"}, "rerun"),
                                           ({"num_envs": 2, "autoreset_mode": "Disabled"}, "autoreset_mode"),
                                           ({"num_envs": 2, "autoreset_seeds": 7}, "autoreset_seeds"),
                                           ({"num_envs": 2, "shards": 2, "autoreset_seeds": lambda: 0},
                                            "autoreset_seeds")])
def test_vector_env_arguments_are_checked(kwargs: dict, match: str) -> None:
    with pytest.raises(EnvInputError, match=match):
        gym.make_vec("STCrowd-SimCrossing-v1", vectorization_mode="vector_entry_point", predictor="cvm", **kwargs)


def run_both(ours, theirs, steps: int, seed: int, where: str) -> None:
    """Reset both vector envs alike and step them with the same random actions, comparing every step."""
    assert_same_nested(ours.reset(seed=seed)[0], theirs.reset(seed=seed)[0], f"{where}, reset")
    rng = np.random.default_rng(seed)
    for t in range(steps):
        actions = rng.uniform(-1.6, 1.6, ours.action_space.shape).astype(np.float32)
        assert_same_step(ours.step(actions), theirs.step(actions), f"{where}, step {t}")


@pytest.mark.parametrize("failing", [0, 1])
def test_a_step_that_fails_in_one_shard_stops_every_shard_until_reset(failing: int,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """The other shards have moved when one shard's step fails: no shard is stepped again (nothing is sent) until a
    reset, which brings back a fresh vector env's episodes."""
    monkeypatch.undo()  # --perturb patches this process only: both sides must run the same arithmetic (one CPU)
    kwargs = {"num_envs": 3, "max_episode_steps": SHORT, "predictor": "none"}
    sharded = gym.make_vec("STCrowd-SimCrossing-v1", shards=2, **kwargs)
    try:
        sharded.reset(seed=5)
        shard, sent = sharded.unwrapped._shards[failing], []
        receive, send = shard.receive, shard.send
        replies = iter([receive, lambda: (receive(), ("error", RuntimeError("boom")))[1]])  # check, then step
        shard.receive = lambda: next(replies)()  # its step fails, after the others moved
        with pytest.raises(RuntimeError, match="boom"):
            sharded.step(np.zeros((3, 2), np.float32))
        shard.receive = receive
        for other in sharded.unwrapped._shards:
            other.send = lambda *args, other_send=other.send: (sent.append(args), other_send(*args))
        with pytest.raises(NeedsResetError, match=rf"the last step did not finish \(shard {failing}: RuntimeError: "
                                                  r"boom\): some shards had moved"):
            sharded.step(np.zeros((3, 2), np.float32))
        assert sent == [], "no shard was asked to step"
        shard.send = send
        obs, _ = sharded.reset(seed=5)
        fresh = gym.make_vec("STCrowd-SimCrossing-v1", **kwargs)
        expected, _ = fresh.reset(seed=5)
        for key in obs:
            np.testing.assert_array_equal(obs[key], expected[key], err_msg=key)
        fresh.close()
    finally:
        sharded.close()


@pytest.mark.parametrize("autoreset_mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_a_vector_env_in_worker_processes_equals_the_one_process_vector_env(autoreset_mode: AutoresetMode,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.undo()  # --perturb patches this process only: both sides must run the same arithmetic (one CPU)
    kwargs = {"num_envs": 5, "max_episode_steps": SHORT, "autoreset_mode": autoreset_mode}
    local = gym.make_vec("STCrowd-SimCrossing-v1", **kwargs)
    sharded = gym.make_vec("STCrowd-SimCrossing-v1", shards=2, **kwargs)
    try:
        assert sharded.sizes == [3, 2]
        run_both(sharded, local, 2 * SHORT, 4, "2 shards")
        bad = np.zeros((5, 2), np.float32)
        bad[4, 1] = np.inf
        with pytest.raises(EnvInputError, match="finite"):  # refused before any shard moves
            sharded.step(bad)
        good = np.full((5, 2), 0.3, np.float32)
        assert_same_step(sharded.step(good), local.step(good), "after a refused action")
    finally:
        sharded.close(), local.close()


def test_a_vector_env_on_two_ray_nodes_equals_the_one_process_vector_env(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.undo()  # as above: the Ray workers run unpatched code
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "object_store_memory": OBJECT_STORE_BYTES})
    cluster.add_node(num_cpus=1, object_store_memory=OBJECT_STORE_BYTES)
    ray.init(address=cluster.address, **connect_kwargs(Path(__file__).parents[1]))
    try:
        kwargs = {"num_envs": 4, "max_episode_steps": SHORT, "predictor": "cvm-s"}
        local = gym.make_vec("STCrowd-SimCrossing-v1", **kwargs)
        on_ray = gym.make_vec("STCrowd-SimCrossing-v1", shards=2, executor="ray", **kwargs)
        nodes = {ray.get(shard.actor.node_id.remote()) for shard in on_ray._shards}
        assert len(nodes) == 2, "each shard should sit on a node of its own (one CPU each)"
        run_both(on_ray, local, SHORT + 3, 7, "Ray shards")
        on_ray.close(), local.close()
    finally:
        ray.shutdown()
        cluster.shutdown()
