"""The learned planner: a stable-baselines3 PPO actor-critic over ``features``, shipped small with a manifest.

    planner = PpoPlanner(world, use_predictions=True)      # the shipped "ppo-predictions" policy
    policy, cfg = load_policy("ppo-no-predictions")         # or a path to a policy file

A policy file holds the actor-critic's weights and its feature and network settings as plain values, and
loads with ``torch.load(weights_only=True)``. ``train_ppo`` writes it; ``pretrained/manifest.json`` lists the
shipped ones with their training command, budget, checksum and final training figures.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from st_sim.apps.navigation.features import FeatureConfig, encode, path_frame, to_velocity
from st_sim.apps.navigation.world import NavWorld

FORMAT = "stcrowd-nav-ppo/1"
PRETRAINED_DIR = "pretrained"
SHIPPED: dict[bool, str] = {True: "ppo-predictions", False: "ppo-no-predictions"}
"""shipped policy name by whether it sees the predictions (trained on the simulated crossing)"""
SHIPPED_REACTIVE: dict[bool, str] = {True: "ppo-reactive-predictions", False: "ppo-reactive-no-predictions"}
"""the same, fine-tuned in the reactive replays of ETH, HOTEL and ZARA2 (ZARA1 and UNIV held out)"""
SHIPPED_SUITE: dict[bool, str] = {True: "ppo-suite-predictions", False: "ppo-suite-no-predictions"}
"""the reactive ones trained on the navigation suite's train split of every scenario but ZARA1's and UNIV's"""


class PolicyFileError(ValueError):
    """A policy file is missing, truncated, foreign, or does not match its manifest."""


EXTRACTORS: tuple[str, ...] = ("flat", "attention")
"""how the actor-critic reads the features: the flat vector, or ``attention.PedestrianAttention``"""


def policy_kwargs(cfg: FeatureConfig, net_arch: list[int], extractor: str = "flat") -> dict[str, Any]:
    """stable-baselines3 ``policy_kwargs`` of the actor-critic: tanh layers ``net_arch`` for actor and critic, on the
    flat features or on ``PedestrianAttention`` of them."""
    import torch

    if extractor not in EXTRACTORS:
        raise ValueError(f"extractor={extractor!r}: expected one of {', '.join(EXTRACTORS)}")
    kwargs: dict[str, Any] = {"net_arch": dict(pi=list(net_arch), vf=list(net_arch)), "activation_fn": torch.nn.Tanh}
    if extractor == "attention":
        from st_sim.apps.navigation.attention import PedestrianAttention

        kwargs |= {"features_extractor_class": PedestrianAttention, "features_extractor_kwargs": {"config": cfg}}
    return kwargs


def build_policy(cfg: FeatureConfig, net_arch: list[int], extractor: str = "flat") -> Any:
    """A fresh stable-baselines3 actor-critic for ``cfg``'s features and path-frame actions (``policy_kwargs``)."""
    from gymnasium import spaces
    from stable_baselines3.common.policies import ActorCriticPolicy

    return ActorCriticPolicy(spaces.Box(-np.inf, np.inf, (cfg.size,), np.float32),
                             spaces.Box(-1.0, 1.0, (2,), np.float32), lambda _: 0.0,
                             **policy_kwargs(cfg, net_arch, extractor))


def save_policy(policy: Any, cfg: FeatureConfig, net_arch: list[int], path: str | Path, extractor: str = "flat") -> str:
    """Write the policy's weights and settings atomically; returns the file's SHA-256."""
    import torch

    from replays.atomic import atomic_path

    state = {"format": FORMAT, "features": asdict(cfg), "net_arch": list(net_arch), "extractor": extractor,
             "weights": {k: v.detach().cpu().clone() for k, v in policy.state_dict().items()}}
    with atomic_path(path) as tmp:
        torch.save(state, tmp)
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def shipped_manifest() -> dict:
    """The shipped policies' manifest: name -> file, sha256, training command and figures."""
    return json.loads(resources.files(__package__).joinpath(PRETRAINED_DIR, "manifest.json").read_text())


def policy_file(name_or_path: str | Path) -> tuple[Path, str | None]:
    """(the file, the SHA-256 the manifest expects of it or None) of a shipped name (see ``SHIPPED``) or a path."""
    manifest = shipped_manifest()["policies"]
    if str(name_or_path) in manifest:
        entry = manifest[str(name_or_path)]
        return Path(str(resources.files(__package__).joinpath(PRETRAINED_DIR, entry["file"]))), entry["sha256"]
    return Path(name_or_path), None


def load_policy(name_or_path: str | Path) -> tuple[Any, FeatureConfig]:
    """(actor-critic in eval mode, its FeatureConfig) from a shipped name (see ``SHIPPED``) or a file path."""
    import torch

    path, expected_sha = policy_file(name_or_path)
    manifest = shipped_manifest()["policies"]
    if not path.is_file():
        raise PolicyFileError(f"{path}: no such policy file; shipped policies: {', '.join(manifest)}")
    if expected_sha is not None and hashlib.sha256(path.read_bytes()).hexdigest() != expected_sha:
        raise PolicyFileError(f"{path}: SHA-256 differs from the manifest (corrupt or replaced file)")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # torch raises several types for truncated or foreign files
        raise PolicyFileError(f"{path}: not a readable policy file (truncated or not a torch file): {err}") from err
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        raise PolicyFileError(f"{path}: not an STCrowd navigation policy (expected format {FORMAT})")
    try:
        cfg = FeatureConfig(**state["features"])
        policy = build_policy(cfg, state["net_arch"], state.get("extractor", "flat"))  # files before 2026-11-26: flat
        policy.load_state_dict(state["weights"])
    except (RuntimeError, TypeError, ValueError, KeyError) as err:
        raise PolicyFileError(f"{path}: weights do not fit the recorded network: {err}") from err
    return policy.eval(), cfg


class PpoPlanner:
    """The shipped PPO policy that matches ``use_predictions`` (deterministic: the Gaussian's mean action).

    Args:
        world: the env's facts (limits, radii, map).
        use_predictions: True = "ppo-predictions" (trained with the predicted futures in its features),
            False = "ppo-no-predictions".
        policy: a shipped name or file to use instead.
    """

    shipped: dict[bool, str] = SHIPPED
    """the shipped policy by ``use_predictions``"""

    def __init__(self, world: NavWorld, use_predictions: bool = True, policy: str | Path | None = None):
        self.world = world
        self.source = policy or self.shipped[use_predictions]
        self.policy, self.features = load_policy(self.source)

    def fingerprint(self) -> str:
        """The policy file this planner acts with and its SHA-256 (``benchmark`` run identity)."""
        path = policy_file(self.source)[0]
        return f"{path.name} sha256 {hashlib.sha256(path.read_bytes()).hexdigest()}"

    def reset(self) -> None:
        """Nothing to forget: the policy is a function of the current observation."""

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(2,) velocity command [m/s], world frame."""
        frame = path_frame(obs, self.world)
        action, _ = self.policy.predict(encode(obs, self.world, self.features, frame), deterministic=True)
        return to_velocity(action, obs, self.world, frame)


class ReactivePpoPlanner(PpoPlanner):
    """``PpoPlanner`` with the policies fine-tuned in reactive replays (``SHIPPED_REACTIVE``): "ppo-reactive"."""

    shipped = SHIPPED_REACTIVE


class SuitePpoPlanner(PpoPlanner):
    """``PpoPlanner`` with the policies trained on the suite's train split (``SHIPPED_SUITE``): "ppo-suite"."""

    shipped = SHIPPED_SUITE


def shielded_suite_ppo(world: NavWorld, use_predictions: bool = True) -> Any:
    """"ppo-suite-shield": ``SuitePpoPlanner`` behind ``shield.ShieldedPlanner``."""
    from st_sim.apps.navigation.shield import ShieldedPlanner

    return ShieldedPlanner(world, use_predictions, SuitePpoPlanner(world, use_predictions))
