"""The learned planner: a stable-baselines3 PPO actor-critic over ``features``, shipped small with a manifest.

    planner = PpoPlanner(world, use_predictions=True)      # the shipped "ppo-predictions" policy
    policy, cfg = load_policy("ppo-no-predictions")         # or a path to a policy file

A policy file holds the actor-critic's weights and its feature and network settings as plain values, and
loads with ``torch.load(weights_only=True)``. ``train_ppo`` writes it; ``pretrained/manifest.json`` lists the
shipped ones with their training command, budget, checksum and final training figures. ``load_policy`` reads any
file as ``held_weights`` describes: the network it states must be within the caps on width, depth and size, and its
weights exactly that network's tensors, each owning the bytes it holds; anything else is refused before the network
is built.
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
STATE_DICT = "the state dict"  # a policy file's "weights", as its refusals name them
SHIPPED: dict[bool, str] = {True: "ppo-predictions", False: "ppo-no-predictions"}
"""shipped policy name by whether it sees the predictions (trained on the simulated crossing)"""
SHIPPED_REACTIVE: dict[bool, str] = {True: "ppo-reactive-predictions", False: "ppo-reactive-no-predictions"}
"""the same, fine-tuned in the reactive replays of ETH, HOTEL and ZARA2 (ZARA1 and UNIV held out)"""
SHIPPED_SUITE: dict[bool, str] = {True: "ppo-suite-predictions", False: "ppo-suite-no-predictions"}
"""the reactive ones trained on the navigation suite's train split of every scenario but ZARA1's and UNIV's"""
SHIPPED_SUITE_2: dict[bool, str] = {True: "ppo-suite-2"}
"""``ppo-suite-predictions`` trained on as the benchmark scores, where it fails (``train_ppo --recipe benchmark
--sampling failures``), on the robot of benchmark version 4; with forecasts only"""


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


def policy_spaces(cfg: FeatureConfig) -> tuple[Any, Any]:
    """(observations, actions) of the actor-critic: ``cfg``'s (cfg.size,) features and (2,) path-frame actions."""
    from gymnasium import spaces

    return spaces.Box(-np.inf, np.inf, (cfg.size,), np.float32), spaces.Box(-1.0, 1.0, (2,), np.float32)


def build_policy(cfg: FeatureConfig, net_arch: list[int], extractor: str = "flat") -> Any:
    """A fresh stable-baselines3 actor-critic for ``cfg``'s features and path-frame actions (``policy_kwargs``)."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    return ActorCriticPolicy(*policy_spaces(cfg), _no_learning, **policy_kwargs(cfg, net_arch, extractor))


def _no_learning(progress_remaining: float) -> float:
    """Learning-rate schedule of a policy built here, which only acts or holds weights (PPO trains with its own)."""
    return 0.0


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
    """(actor-critic in eval mode, its FeatureConfig) from a shipped name (see ``SHIPPED``) or a file path. Raises
    ``PolicyFileError`` naming the file and the problem, before building a network that is not the file's."""
    import torch

    from st_sim.apps.navigation.held_weights import MAX_WEIGHTS_BYTES, WeightsError, held_weights, read_torch

    path, expected_sha = policy_file(name_or_path)
    manifest = shipped_manifest()["policies"]
    if not path.is_file():
        raise PolicyFileError(f"{path}: no such policy file; shipped policies: {', '.join(manifest)}")
    if path.stat().st_size > MAX_WEIGHTS_BYTES:
        raise PolicyFileError(f"{path}: {path.stat().st_size} bytes, more than the {MAX_WEIGHTS_BYTES} a policy "
                              "file may hold")
    raw = path.read_bytes()
    if expected_sha is not None and hashlib.sha256(raw).hexdigest() != expected_sha:
        raise PolicyFileError(f"{path}: SHA-256 differs from the manifest (corrupt or replaced file)")
    try:
        state = read_torch(raw, "the file")
        if not isinstance(state, dict) or state.get("format") != FORMAT:
            raise WeightsError(f"not an STCrowd navigation policy (expected format {FORMAT})")
        held = held_weights(state.get("weights"), STATE_DICT, len(raw))
        cfg, net_arch, extractor = _settings(state)
        _check_network(cfg, net_arch, extractor, state["weights"], held)
        with torch.random.fork_rng(devices=[]):  # building draws initial weights: keep the caller's random state
            policy = build_policy(cfg, net_arch, extractor)
        policy.load_state_dict(state["weights"])
    except WeightsError as err:
        raise PolicyFileError(f"{path}: {err.problem}") from None
    except (RuntimeError, TypeError, ValueError, KeyError) as err:
        raise PolicyFileError(f"{path}: weights do not fit the recorded network: {err}") from err
    return policy.eval(), cfg


def _settings(state: dict[str, Any]) -> tuple[FeatureConfig, list[int], str]:
    """(features, net_arch, extractor) a policy file states, refused (``WeightsError``) if its network's layers are
    not within ``held_weights``' caps or its extractor is unknown."""
    from st_sim.apps.navigation.held_weights import MAX_HIDDEN_LAYERS, MAX_WIDTH, WeightsError, is_layers

    net_arch, extractor = state.get("net_arch"), state.get("extractor", "flat")  # files before 2026-11-26: flat
    if not is_layers(net_arch):
        raise WeightsError(f"net_arch {' '.join(str(net_arch).split())[:80]} is not a list of at most "
                           f"{MAX_HIDDEN_LAYERS} layer widths from 1 to {MAX_WIDTH}")
    if extractor not in EXTRACTORS:
        raise WeightsError(f"extractor {str(extractor)[:40]!r} is not one of {', '.join(EXTRACTORS)}")
    features = state.get("features")
    if not isinstance(features, dict):
        raise WeightsError(f"features are a {type(features).__name__}, not the settings of a FeatureConfig")
    return FeatureConfig(**features), net_arch, extractor


def _check_network(cfg: FeatureConfig, net_arch: list[int], extractor: str, weights: dict[str, Any],
                   held: int) -> None:
    """Refuse the network a policy file states unless it holds exactly its ``held`` weights, before building it: the
    weights its layers imply (actor and critic from the extractor's features to the (2,) action and the value: fewer
    than the whole network's) within the caps and those held; then, built on the meta device, as many weights, with
    the names, shapes and dtypes of ``weights``."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    from st_sim.apps.navigation.attention import EMBED
    from st_sim.apps.navigation.held_weights import check_fits, check_implied, mlp_weights, network_state

    features = 2 * EMBED if extractor == "attention" else cfg.size  # what the layers read
    observations, actions = policy_spaces(cfg)
    check_implied(mlp_weights(features, [*net_arch, *actions.shape]) + mlp_weights(features, [*net_arch, 1]), held,
                  net_arch, STATE_DICT)
    network = network_state(ActorCriticPolicy, observations, actions, _no_learning,
                            **policy_kwargs(cfg, net_arch, extractor))
    check_fits(weights, network, STATE_DICT, f"the network the file states (net_arch {net_arch}, {extractor} "
               "extractor)")


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


class Suite2PpoPlanner(PpoPlanner):
    """``PpoPlanner`` with ``SHIPPED_SUITE_2``: "ppo-suite-2". It reads the predicted futures and has no variant
    without them: with predictor ``none`` it is refused (a ``ValueError`` naming what to give), unless ``policy``
    names a file of one's own."""

    shipped = SHIPPED_SUITE_2

    def __init__(self, world: NavWorld, use_predictions: bool = True, policy: str | Path | None = None):
        if not use_predictions and policy is None:
            raise ValueError("ppo-suite-2 was trained with forecasts and has no variant without them: give it a "
                             "predictor (singular, cvm, ...), or use ppo-suite with --predictor none")
        super().__init__(world, use_predictions, policy)


def shielded_suite_ppo(world: NavWorld, use_predictions: bool = True) -> Any:
    """"ppo-suite-shield": ``SuitePpoPlanner`` behind ``shield.ShieldedPlanner``."""
    from st_sim.apps.navigation.shield import ShieldedPlanner

    return ShieldedPlanner(world, use_predictions, SuitePpoPlanner(world, use_predictions))
