"""Navigation policies by spec: a shipped planner, your own class or factory, or a stable-baselines3 model.

    policy = load_policy("mypkg.policy:MyPolicy", world, "singular")   # or "mpc", "sb3:model.zip"
    policy.reset()                       # at every episode start
    action = policy.act(obs)             # (2,) velocity command [m/s], world frame, checked

A spec is one of:
- a shipped planner name (``planners.PLANNERS``: straight, orca, mpc, ppo, ppo-reactive,
  ppo-suite, ppo-suite-shield, ppo-suite-2) or a peer's
  (``planners.PEERS``: navground-hl, navground-orca, navground-hrvo, navground-sf, pysocialforce; ``peers``);
- ``package.module:name``: a class or factory following the planner protocol (``act(obs) -> (2,)`` velocity,
  optionally ``reset()``), built as ``name(world, use_predictions)`` like the shipped planners when its signature
  takes two arguments, else as ``name()``;
- ``sb3:PATH.zip``: a stable-baselines3 model (the MlpPolicy or MultiInputPolicy of PPO, A2C, SAC, TD3 or DDPG)
  saved after training on an STCrowd env's own observations; it acts with ``predict(obs, deterministic=True)``. A
  model whose observation space is a ``Dict`` holding some of the env's keys (trained behind ``FilterObservation``)
  gets only those; a model trained on the fixed-size view (``envs.view``: ``FixedView`` or ``STCrowd-Suite-v1``) gets
  each observation through ``fixed_view`` and acts in the robot's frame, so it runs in every scenario. The file is
  read without running anything stored in it (``sb3_zip``), so a file from anyone is safe to score;
  ``trust_file=True`` (``--trust-policy-file``) loads it with SB3's own loader instead, which unpickles the objects
  the file holds (running their code) and so reads custom policy classes and extractors.

What is built is wrapped in ``CheckedPolicy``: an action that is not 2 finite numbers, or an exception inside the
policy, becomes a ``PolicyError`` naming the policy.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from envs.view import fixed_view, frames_along_path, to_world, view_sizes, view_space
from predictor.plugins import PluginError, describe_error, resolve_factory
from st_sim.apps.navigation.planners import NAMED, PEERS, PLANNERS, make_planner
from st_sim.apps.navigation.world import NavWorld

SB3_PREFIX = "sb3:"
TRUST_HELP = ("an sb3: policy file: load it with stable-baselines3's own loader, which runs code stored in the file "
              "(custom policy classes and feature extractors need it); only for a file you trust. Without it nothing "
              "in the file runs")
TRUST_HINT = ("--trust-policy-file loads a file you trust with stable-baselines3's own loader, which runs code "
              "stored in it")
SPEC_HELP = (f"a shipped planner ({', '.join(PLANNERS)}), another project's ({', '.join(PEERS)}: pip install -e "
             "\".[peers]\"), package.module:name (a class or factory with act(obs) -> (2,) velocity), or "
             "sb3:PATH.zip (a stable-baselines3 model)")


class PolicyError(ValueError):
    """A policy cannot be loaded, does not fit an env, or acted wrongly; the message names the policy."""


def check_policy_spec(spec: str) -> None:
    """Refuse a spec that cannot name a policy, before any work: an unknown name, a plug-in that does not import or
    names nothing callable, a model file that is missing (``PolicyError``)."""
    if spec in NAMED:
        return
    if spec.startswith(SB3_PREFIX):
        path = Path(spec.removeprefix(SB3_PREFIX)).expanduser()
        if not path.is_file():
            raise PolicyError(f"policy {spec!r}: no such file {path} (sb3:PATH.zip names a saved model)")
        return
    if ":" not in spec:
        raise PolicyError(f"policy {spec!r}: expected {SPEC_HELP}")
    _factory(spec)


def load_policy(spec: str, world: NavWorld, predictor: str = "singular", *, trust_file: bool = False,
                **options: Any) -> CheckedPolicy:
    """The policy ``spec`` names, built for an env's ``world`` whose forecasts come from ``predictor`` ("none": the
    policy is told that no forecasts are there); ``trust_file``: an ``sb3:`` file is loaded by SB3's own loader,
    which runs code stored in it; ``options`` go to a shipped planner (the MPC's ``cfg``, PPO's ``policy`` file).
    Raises ``PolicyError`` if it cannot be built."""
    check_policy_spec(spec)
    if options and spec not in NAMED:
        raise PolicyError(f"policy {spec!r}: options {', '.join(options)} are for the shipped planners only")
    if trust_file and not spec.startswith(SB3_PREFIX):
        raise PolicyError(f"policy {spec!r}: --trust-policy-file is for an sb3:PATH.zip model file (a package."
                          "module:name policy is your own code, run as it is)")
    if spec in NAMED:
        policy = make_planner(spec, world, predictor, **options)
    elif spec.startswith(SB3_PREFIX):
        policy = Sb3Policy(Path(spec.removeprefix(SB3_PREFIX)).expanduser(), world, trust_file)
    else:
        policy = _build(spec, _factory(spec), world, predictor != "none")
    return CheckedPolicy(spec, policy, world)


def _factory(spec: str) -> Callable[..., Any]:
    try:
        return resolve_factory(spec, kind="policy")
    except PluginError as err:
        raise PolicyError(str(err)) from err


def _build(spec: str, factory: Callable[..., Any], world: NavWorld, use_predictions: bool) -> Any:
    """``factory(world, use_predictions)`` if its signature takes two arguments, else ``factory()``; checked to have
    a callable ``act``."""
    try:
        signature = inspect.signature(factory)
        args = (world, use_predictions)
        try:
            signature.bind(*args)
        except TypeError:
            signature.bind()
            args = ()
    except TypeError as err:
        raise PolicyError(f"policy {spec!r}: expected a class or factory called as name(world, use_predictions) "
                          f"or name(), not {signature}") from err
    except ValueError:  # no signature (a builtin): call it bare
        args = ()
    try:
        policy = factory(*args)
    except (Exception, SystemExit) as err:
        raise PolicyError(f"policy {spec!r}: building it raised {describe_error(err)}") from err
    if not callable(getattr(policy, "act", None)):
        raise PolicyError(f"policy {spec!r}: built a {type(policy).__name__} without a callable act(obs)")
    return policy


class CheckedPolicy:
    """A policy behind checks: ``act`` gets copies of the observation's arrays, and what it returns must be a (2,)
    velocity of finite numbers; anything else, or an exception inside it, raises ``PolicyError``. The velocity becomes
    the robot's command (``NavWorld.command_for``: itself for a holonomic robot, a turn and a forward speed for a
    differential drive), unless the policy says it gives the robot's own command (an attribute ``drives_robot =
    True``, as the MPC does).

    Attributes:
        spec: the policy as named.  policy: what was built.  world: the env's facts (its robot among them); None: the
            policy's output goes to the env as it is.
        observation_space: the policy's own observation space, if it declares one (an SB3 model does), else None.
    """

    def __init__(self, spec: str, policy: Any, world: NavWorld | None = None):
        self.spec, self.policy, self.world = spec, policy, world
        self.observation_space: spaces.Space | None = getattr(policy, "observation_space", None)

    def __repr__(self) -> str:
        return f"CheckedPolicy({self.spec})"

    def reset(self) -> None:
        """The policy's ``reset()``, if it has one."""
        reset = getattr(self.policy, "reset", None)
        if reset is None:
            return
        try:
            reset()
        except (Exception, SystemExit) as err:
            raise PolicyError(f"policy {self.spec!r}: reset raised {describe_error(err)}") from err

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) float32 command of the robot (a holonomic robot's velocity [m/s], world frame)."""
        try:
            action = self.policy.act({key: np.array(value) for key, value in obs.items()})
        except (Exception, SystemExit) as err:
            raise PolicyError(f"policy {self.spec!r}: act raised {describe_error(err)}") from err
        try:
            velocity = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise PolicyError(f"policy {self.spec!r}: act returned a {type(action).__name__}, not a (2,) velocity "
                              "[m/s]") from err
        if velocity.shape != (2,):
            raise PolicyError(f"policy {self.spec!r}: act returned shape {velocity.shape}; expected a (2,) velocity "
                              "(vx, vy) [m/s]")
        if not (np.abs(velocity) <= np.finfo(np.float32).max).all():  # NaN, inf, or past float32's range
            raise PolicyError(f"policy {self.spec!r}: act returned {velocity.tolist()}; expected finite numbers "
                              "within float32's range")
        if self.world is not None and getattr(self.policy, "drives_robot", False) is not True:
            velocity = self.world.command_for(obs, velocity)
        return np.asarray(velocity, np.float32)

    def check_fits(self, env_space: spaces.Space, scenario: str) -> None:
        """Refuse a policy whose observation space does not fit a scenario's (``PolicyError`` naming the scenario,
        both spaces and what to do); nothing for a policy that declares no space."""
        own = self.observation_space
        if own is None or observation_fits(own, env_space):
            return
        raise PolicyError(
            f"policy {self.spec!r} does not fit scenario {scenario!r}: it reads observations of {own}, the scenario's "
            f"env gives {env_space}. Run it on the scenarios it was trained for (--scenarios), train it on this "
            f"scenario's env, or {FIXED_VIEW_HINT}")


FIXED_VIEW_HINT = ("train it on the fixed-size view, which fits every scenario (envs.view.FixedView, or the "
                   "STCrowd-Suite-v1 env), or wrap it in a class (package.module:name) that turns any STCrowd "
                   "observation into its input (docs: Benchmark your policy)")


def observation_fits(own: spaces.Space, env_space: spaces.Space) -> bool:
    """True if observations of ``env_space`` can feed a policy reading ``own``: the same space, a Dict of some of
    the env's keys, each with the env's shape and dtype, or the fixed-size view (``envs.view``) of the env's
    observations with the env's observed steps and forecast samples."""
    sizes = view_sizes(own)
    if sizes is not None and isinstance(env_space, spaces.Dict) and {"history", "futures"} <= set(env_space.spaces):
        nearest, rays = sizes[:2]
        env_space = view_space(nearest, rays, env_space["history"].shape[1], env_space["futures"].shape[1])
    if isinstance(own, spaces.Dict) and isinstance(env_space, spaces.Dict):
        return all(key in env_space.spaces and env_space[key].shape == sub.shape and env_space[key].dtype == sub.dtype
                   for key, sub in own.spaces.items())
    return own.shape == env_space.shape and own.dtype == env_space.dtype


class Sb3Policy:
    """A stable-baselines3 model acting deterministically on STCrowd observations (see the module docstring).

    Args:
        path: the model's ``.zip`` (``model.save``).
        world: the env's facts; the model must act in its ``action_space``.
        trust_file: load with SB3's own loader, which runs code stored in the file (else nothing in it runs).
    """

    def __init__(self, path: Path, world: NavWorld, trust_file: bool = False):
        self.path, self.world = path, world
        self.model = _load_with_sb3(path) if trust_file else _load_safely(path, world)
        self.observation_space = self.model.observation_space
        self.view = view_sizes(self.observation_space)
        """(K, R, T_obs, S) if the model reads the fixed-size view (``envs.view``), else None"""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame: the model's deterministic action (given in the robot's frame
        by a model of the fixed-size view)."""
        if self.view is not None:
            terrain, body_m = self.world.terrain, self.world.wall_clearance_m
            frame = frames_along_path(obs["ego"][None], terrain, body_m)[0]
            seen = fixed_view(obs, terrain, body_m, *self.view[:2], frame=frame)
            action, _ = self.model.predict(seen, deterministic=True)
            return to_world(np.asarray(action, np.float64)[None], frame[None])[0]
        if isinstance(self.observation_space, spaces.Dict):
            obs = {key: obs[key] for key in self.observation_space.spaces}
        action, _ = self.model.predict(obs, deterministic=True)
        return action


def _load_safely(path: Path, world: NavWorld) -> Any:
    """The policy saved at ``path``, read without running anything stored in it (``sb3_zip``)."""
    from st_sim.apps.navigation.sb3_zip import Sb3ZipError, load_sb3_zip

    try:
        return load_sb3_zip(path, world.action_space)
    except Sb3ZipError as err:
        raise PolicyError(f"policy {f'{SB3_PREFIX}{path}'!r}: {err.problem}; {TRUST_HINT}") from None


def _load_with_sb3(path: Path) -> Any:
    """The model saved at ``path``, loaded on the CPU by SB3's own ``load`` (it unpickles the objects the file holds)
    of the algorithm whose policies its policy class derives from (PPO for A2C's, TD3 for DDPG's: they act alike)."""
    import stable_baselines3
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.save_util import load_from_zip_file
    from stable_baselines3.sac.policies import SACPolicy
    from stable_baselines3.td3.policies import TD3Policy

    spec = f"{SB3_PREFIX}{path}"
    try:
        data, _, _ = load_from_zip_file(path, device="cpu")
        policy_class = data["policy_class"]
    except Exception as err:  # whatever the file's objects raise as they are unpickled
        raise PolicyError(f"policy {spec!r}: stable-baselines3's loader failed: {describe_error(err)}") from err
    bases = {ActorCriticPolicy: "PPO", SACPolicy: "SAC", TD3Policy: "TD3"}
    names = [name for base, name in bases.items() if isinstance(policy_class, type) and issubclass(policy_class, base)]
    if not names:
        raise PolicyError(f"policy {spec!r}: its policy class {policy_class!r} derives from none of SB3's "
                          "actor-critic, SAC and TD3 policies")
    try:
        return getattr(stable_baselines3, names[0]).load(path, device="cpu")
    except Exception as err:
        raise PolicyError(f"policy {spec!r}: {names[0]}.load failed: {describe_error(err)}") from err
