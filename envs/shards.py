"""A native vector env split into shards that step in parallel: worker processes on this machine, or Ray actors on a
cluster. Each shard is a ``CrowdVectorEnv`` of its share of the sub-envs (its crowds stepped as one, one forecast
per step); the driver checks every action first, sends each shard its actions, and batches what comes back.

    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=64, shards=2)                  # two worker processes
    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=64, shards=4, executor="ray")  # Ray actors (ray.init first)

Sub-env i is the same env, with the same seed, whichever shard holds it: the observations equal those of one
``CrowdVectorEnv`` of all the sub-envs, except the predicted futures, which differ by the float rounding of a
smaller forecast batch. Every shard runs with one thread.
"""

from __future__ import annotations

import os
import secrets
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from multiprocessing.connection import Client, Listener
from typing import Any, ClassVar

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from envs.batch_step import StepParts
from envs.common.errors import EnvInputError, NeedsResetError
from envs.vector_env import CrowdVectorEnv, batch_infos, sub_env_seeds

EXECUTORS: tuple[str, ...] = ("process", "ray")
SHARD = "envs.shards:Shard"  # what a worker of a ShardedVectorEnv hosts
PARENT_POLL_S = 1.0  # a worker process checks this often whether its driver is still alive [s]


class Shard:
    """The sub-envs of one shard: a ``CrowdVectorEnv`` built by ``env_class_path`` (``module:Class``) with the id's
    keyword arguments, stepped by the driver through these methods."""

    def __init__(self, env_class_path: str, num_envs: int, max_episode_steps: int | None, autoreset_mode: str,
                 kwargs: dict[str, Any]):
        one_thread()
        self.vec = CrowdVectorEnv(hosted_class(env_class_path), num_envs, max_episode_steps, autoreset_mode, **kwargs)

    def spaces(self) -> tuple[Any, Any]:
        return self.vec.single_observation_space, self.vec.single_action_space

    def reset(self, seeds: list[int | None], options: dict | None) -> tuple[list, list]:
        return self.vec.reset_parts(seeds, options)

    def check(self, actions: np.ndarray) -> None:
        self.vec.check_actions(actions)

    def step(self, actions: np.ndarray) -> StepParts:
        return self.vec.step_parts(self.vec.check_actions(actions))

    def close(self) -> None:
        self.vec.close()

    def node_id(self) -> str:
        """The Ray node this shard runs on (Ray actors only)."""
        import ray

        return ray.get_runtime_context().get_node_id()


class ShardedVectorEnv(VectorEnv):
    """``num_envs`` sub-envs of one STCrowd id in ``shards`` parallel shards (see the module docstring).

    Args:
        env_class_path: ``module:Class`` of the id's env (``envs.sim_env:SimCrowdEnv`` ...).
        num_envs: sub-envs in all, >= shards.  shards: >= 1.  executor: "process" (worker processes here) or "ray"
            (Ray actors wherever the connected cluster places them; ``ray.init`` first).
        max_episode_steps, autoreset_mode, kwargs: as ``CrowdVectorEnv``.
    """

    metadata: ClassVar[dict[str, Any]] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, env_class_path: str, num_envs: int, shards: int = 2, executor: str = "process",
                 max_episode_steps: int | None = None, autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 **kwargs: Any):
        if isinstance(shards, bool) or not isinstance(shards, int | np.integer) or not 1 <= shards <= num_envs:
            raise EnvInputError(f"shards={shards!r}: expected an int between 1 and num_envs={num_envs}")
        if executor not in EXECUTORS:
            raise EnvInputError(f"executor={executor!r}: expected one of {', '.join(EXECUTORS)}")
        self.num_envs, self.executor = int(num_envs), executor
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.sizes = [len(part) for part in np.array_split(np.arange(num_envs), shards)]
        self._cuts = np.cumsum(self.sizes)[:-1]
        args = [(env_class_path, size, max_episode_steps, self.autoreset_mode.value, kwargs) for size in self.sizes]
        self._shards = [(RayShard if executor == "ray" else ProcessShard)(SHARD, *a) for a in args]
        self._unfinished: str | None = None
        """why no shard may step until the next reset: a step or reset that failed in some shard (None: they may)"""
        self.single_observation_space, self.single_action_space = self._shards[0].call("spaces")
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        """As ``CrowdVectorEnv.reset``: sub-env i gets seed + i (or the i-th of a list), whichever shard holds it."""
        seeds = sub_env_seeds(seed, self.num_envs)
        for i, env_seed in enumerate(seeds):
            if env_seed is not None and (isinstance(env_seed, bool | np.bool_) or
                                         not isinstance(env_seed, int | np.integer) or env_seed < 0):
                raise EnvInputError(f"sub-env {i}: seed={env_seed!r}: expected None or an int >= 0; no sub-env "
                                    "was reset")
        parts = self._all("reset", [(list(part), options) for part in np.split(np.array(seeds, object), self._cuts)],
                          "reset")
        self._unfinished = None
        observations = [obs for shard_obs, _ in parts for obs in shard_obs]
        infos = [info for _, shard_infos in parts for info in shard_infos]
        return self._batch(observations), batch_infos(self, infos, {})

    def step(self, actions: Any):
        """Check every shard's actions, then step all shards at once (nothing moves if any action is refused). A step
        that fails in one shard has moved the others: then no shard steps again until ``reset`` (``NeedsResetError``
        saying why)."""
        if self._unfinished is not None:
            raise NeedsResetError(f"{self._unfinished}: some shards had moved and others not; call reset() before "
                                  "step()")
        try:
            actions = np.asarray(actions)
        except (ValueError, TypeError) as err:
            raise EnvInputError(f"actions must be an array of shape {self.action_space.shape} (num_envs, 2), got "
                                f"a ragged {type(actions).__name__}") from err
        if actions.shape != self.action_space.shape:
            raise EnvInputError(f"actions must have shape {self.action_space.shape} (num_envs, 2), got {actions.shape}")
        split = [(part,) for part in np.split(actions, self._cuts)]
        self._all("check", split)
        parts: list[StepParts] = self._all("step", split, "step")
        offsets = np.r_[0, np.cumsum(self.sizes)]
        finals = {offset + i: final for offset, p in zip(offsets, parts, strict=False) for i, final in p.finals.items()}
        return (self._batch([obs for p in parts for obs in p.observations]),
                np.concatenate([p.rewards for p in parts]), np.concatenate([p.terminated for p in parts]),
                np.concatenate([p.truncated for p in parts]),
                batch_infos(self, [info for p in parts for info in p.infos], finals))

    def close_extras(self, **kwargs: Any) -> None:
        for shard in self._shards:
            shard.close()

    def _all(self, method: str, args: list[tuple], moves: str | None = None) -> list[Any]:
        """Call ``method`` on every shard at once with its arguments; re-raise the first error a shard raised (for a
        ``method`` that ``moves`` the worlds, "step" or "reset", after refusing further steps until a reset)."""
        for shard, shard_args in zip(self._shards, args, strict=True):
            shard.send(method, *shard_args)
        results = [shard.receive() for shard in self._shards]
        for index, (outcome, value) in enumerate(results):
            if outcome == "error":
                if moves is not None:
                    self._unfinished = (f"the last {moves} did not finish (shard {index}: {type(value).__name__}: "
                                        f"{value})")
                raise value
        return [value for _, value in results]

    def _batch(self, observations: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, observations, out)


class ShardHandle:
    """The driver's end of a shard: ``send`` a call, ``receive`` its ("ok" | "error", value); ``call`` does both."""

    def send(self, method: str, *args: Any) -> None:
        raise NotImplementedError

    def receive(self) -> tuple[str, Any]:
        raise NotImplementedError

    def call(self, method: str, *args: Any) -> Any:
        self.send(method, *args)
        outcome, value = self.receive()
        if outcome == "error":
            raise value
        return value


def hosted_class(target: str) -> type:
    """The class ``module:Class`` that a worker hosts (imported there)."""
    module, _, name = target.partition(":")
    return getattr(__import__(module, fromlist=[name]), name)


class ProcessShard(ShardHandle):
    """An object of class ``target`` (``module:Class``, built with ``args``; ``Shard`` for a ``ShardedVectorEnv``) in a
    worker process of this machine (a fresh interpreter: no forked thread pools, and the caller's script needs no
    ``if __name__ == "__main__"`` guard), spoken to through a local socket."""

    def __init__(self, target: str, *args: Any):
        key = secrets.token_bytes(16)
        with Listener(family="AF_UNIX", authkey=key) as listener:
            env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p and os.path.isdir(p))}
            self.process = subprocess.Popen([sys.executable, "-c", "import sys, envs.shards as s; "
                                             "s.serve(sys.argv[1], bytes.fromhex(sys.argv[2]))",
                                             listener.address, key.hex()], env=env)
            self._conn = listener.accept()
        self._conn.send((target, args))
        outcome, value = self._conn.recv()  # the object was built, or why not
        if outcome == "error":
            raise value

    def send(self, method: str, *args: Any) -> None:
        self._conn.send((method, args))

    def receive(self) -> tuple[str, Any]:
        try:
            return self._conn.recv()
        except EOFError:
            return "error", RuntimeError(f"a shard's worker process (pid {self.process.pid}) died "
                                         f"(exit code {self.process.poll()})")

    def close(self) -> None:
        if self.process.poll() is None:
            self.send("close")
            self.receive()
            self.process.wait(timeout=10)
        self._conn.close()


def serve(address: str, key: bytes) -> None:
    """A worker process: build the object the driver describes, then run its calls until "close" (or until the driver
    is gone)."""
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()
    conn = Client(address, family="AF_UNIX", authkey=key)
    try:
        target, args = conn.recv()
        hosted = hosted_class(target)(*args)
    except Exception as err:  # reported to the driver, which raises it
        conn.send(("error", err))
        return
    conn.send(("ok", None))
    while True:
        try:
            method, call_args = conn.recv()
        except EOFError:  # the driver is gone without a "close"
            return
        try:
            conn.send(("ok", getattr(hosted, method)(*call_args)))
        except Exception as err:
            conn.send(("error", err))
        if method == "close":
            return


def _exit_with_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


class RayShard(ShardHandle):
    """An object of class ``target`` (as ``ProcessShard``) as a Ray actor (one CPU), wherever the connected cluster
    places it."""

    def __init__(self, target: str, *args: Any):
        import ray

        self._ray = ray
        self.actor = ray.remote(num_cpus=1)(hosted_class(target)).remote(*args)
        self._pending: Any = None

    def send(self, method: str, *args: Any) -> None:
        self._pending = getattr(self.actor, method).remote(*args)

    def receive(self) -> tuple[str, Any]:
        try:
            return "ok", self._ray.get(self._pending)
        except self._ray.exceptions.RayTaskError as err:
            return "error", err.as_instanceof_cause()
        except self._ray.exceptions.RayActorError as err:
            return "error", RuntimeError(f"a shard's Ray actor died: {err}")

    def close(self) -> None:
        self.send("close")
        self.receive()
        self._ray.kill(self.actor)


def one_thread() -> None:
    """One thread per shard: shards are the parallelism (every class a worker hosts calls this first)."""
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"
    import torch

    torch.set_num_threads(1)
