"""Train the PPO navigation policy (stable-baselines3) on vectorised STCrowd envs, with or without predictions.

    python -m st_sim.apps.navigation.train_ppo --timesteps 10000000 --sensor-range inf --closest-approach \
        --extractor attention --out runs/nav/ppo-scratch            # PPO from scratch
    python -m st_sim.apps.navigation.train_ppo --timesteps 0 --demo-steps 40000 ... --out runs/nav/clone-with
    python -m st_sim.apps.navigation.train_ppo --init-policy runs/nav/clone-with/policy.pt --critic-rollouts 5 \
        --learning-rate 1e-4 --target-kl 0.02 --log-std-init -2.5 ... --out runs/nav/ft-with   # PPO from a clone
    python -m st_sim.apps.navigation.train_ppo --scenarios all --hold-out zara1 univ --init-policy ... \
        --out runs/suite/with-s0      # on the navigation suite's train split, two scenes held out

The ``--num-envs`` sub-envs (64) run as native vector envs in ``--shards`` worker processes (2, a core each;
``training_envs.FeatureVecEnv``): one batched SingularTrajectory call per step in each, for the pedestrians the
features read (the nearest six within ``--sensor-range``), conditioned on every sensed one. PPO starts from scratch;
``--demo-steps N`` instead starts from a teacher: N steps of the sampling MPC with SingularTrajectory are collected
once into ``--demos`` (reused by the other variant) and cloned into the actor-critic (``demonstrations``; its features
see every pedestrian, so it needs ``--sensor-range inf``). ``--dagger-rounds K`` then runs K DAgger rounds: the clone
drives ``--dagger-steps`` steps, the teacher labels every state it reaches, and the clone is fitted again on all labels
so far (each round's steps are kept in --out). ``--timesteps 0`` stops there (a clone without PPO); ``--init-policy``
starts PPO (of any seed) from such a clone's ``policy.pt`` (or any policy file), and ``--critic-rollouts R`` fits its
critic to the training reward for R updates before the actor moves (``critic_first.CriticFirstPPO``).
``--scenarios`` trains on scenarios of the shipped navigation suite (``--hold-out`` leaves some out), every episode
from its train split (``training_envs.FeatureVecEnv``'s ``train_seeds``). ``--recipe benchmark`` pays
what the benchmark scores (``RECIPES``: a collision by the fault rule, a timeout) and ``--sampling failures`` shares
the sub-envs among the training envs by their failure rates (``Resampler``, ``failure_sampling``; the rounds in
``sampling.json``); ``--fault-target RATE`` turns the at-fault charge into a constraint with a learned multiplier
(``FaultMultiplier``, ``fault_constraint``; its updates in ``constraint.json``). ``--minutes`` stops the run after that
much wall time (then writes everything as at the end of the budget); ``--device`` puts PPO and the
forecasts on a GPU where torch sees one (``auto``, the default) or where it is told.

Writes into --out: ``policy.pt`` (loadable with ``ppo.load_policy``), ``curve.png`` and ``curve.json`` (the
learning curve: success, collision and return over the last 100 training episodes against env steps) and
``training.json`` (config, wall time, final figures; a resumed run's wall time sums its segments up to each one's
last save, its ``env_steps_per_s`` is of the steps since ``resumed_from``; ``--minutes`` is a budget per
segment; ``init_policy_sha256``, the ``--init-policy`` file's SHA-256 when the run started, kept in
``init_policy.json`` across segments, as the path may later hold another file). ``--ship NAME`` also copies the
policy into the package's ``pretrained/`` folder and records it in the manifest. The two variants differ only in
whether the features hold the predicted futures; same env, seed, budget and hyper-parameters.

Every ``--save-every`` rollouts the whole PPO state goes to ``resume.zip`` (with ``curve.json``); a run started
again with the same --out and settings continues from there up to its --timesteps, so a killed run loses at
most that many rollouts and a finished one can be extended with a larger budget. A resumed run is not
bit-identical to an uninterrupted one (the envs restart their episodes).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from importlib import resources, util
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from envs.common.config import EnvConfig, RewardWeights
from predictor.devices import DEVICE_HELP, DeviceError, resolve_device
from replays import strict_json
from replays.atomic import atomic_path, write_text_atomic
from replays.data_root import sha256_of
from st_sim.apps.navigation.demonstrations import DemoSpec, behaviour_clone, concatenate, load_or_collect
from st_sim.apps.navigation.failure_sampling import FailureTally, allocate
from st_sim.apps.navigation.fault_constraint import FaultConstraint
from st_sim.apps.navigation.features import FeatureConfig
from st_sim.apps.navigation.ppo import (
    EXTRACTORS,
    PRETRAINED_DIR,
    build_policy,
    load_policy,
    policy_file,
    policy_kwargs,
    save_policy,
)

CURVE_WINDOW = 100  # training episodes averaged per learning-curve point [-]
DAGGER_SEED_STRIDE = 10_000  # episode seeds between two DAgger rounds (a worker's share is far fewer episodes) [-]
SAMPLING_SEED_STRIDE = 100_000  # first-episode seeds between two sampling rounds' training envs [-]
RESUMABLE = ("use_predictions", "env_ids", "scenarios", "num_envs", "sensor_range_m", "reward", "timeout_reward",
             "sampling", "resample_every", "fault_target", "fault_step", "seed", "n_steps",
             "batch_size", "n_epochs", "learning_rate", "gamma", "net_arch", "log_std_init", "initial_forward",
             "init_policy", "demo_steps", "demos", "bc_epochs", "dagger_rounds", "dagger_steps", "extractor",
             "closest_approach", "clip_range", "target_kl", "critic_rollouts")
"""settings a run must share with the saved state to continue it (the budget and output options may differ)"""
RECIPES: dict[str, tuple[RewardWeights, float]] = {
    "crowdnav": (RewardWeights(collision=-20.0, discomfort=-4.0), 0.0),
    "benchmark": (RewardWeights(collision=-10.0, at_fault=-20.0, discomfort=-4.0), -10.0),
}
"""training rewards by name: (the env's reward weights, the charge for a timeout). ``crowdnav``: CrowdNav++'s
collision penalty and discomfort factor, every collision alike, a timeout free (how every shipped policy before
``ppo-suite-2`` was trained); ``benchmark``: what the benchmark scores, a collision fails the episode (-10) and one the
fault rule puts on the robot costs 20 more, a timeout fails it too (-10), so standing still is no way out"""
SAMPLINGS = ("uniform", "failures")
"""how a run shares its sub-envs among its training envs: evenly, or by how often the policy fails in each
(``failure_sampling``, again every ``resample_every`` rollouts)"""


@dataclass(frozen=True)
class TrainConfig:
    """One PPO training run."""

    use_predictions: bool = True
    """features hold the predicted futures (the env runs SingularTrajectory); False: positions only"""
    env_ids: tuple[str, ...] = ("STCrowd-SimCrossing-v1",)
    """training envs, ``ID`` or ``ID:MODE`` for a replay's pedestrians (log, reactive); several share the sub-envs
    evenly (``FeatureVecEnv``)"""
    scenarios: tuple[str, ...] = ()
    """the shipped suite's scenarios trained on (``envs.suite``), every episode from its train split; their envs are
    ``env_ids`` (``training_envs.scenario_env``); empty: ``env_ids`` as given, their episodes from the seeds"""
    timesteps: int = 1_000_000
    """env steps over all envs (the training budget)"""
    num_envs: int = 64
    """sub-envs, stepped as native vector envs (one batched forecast per step in each shard)"""
    sensor_range_m: float = 5.0
    """the robot senses, and the env forecasts, the pedestrians within this distance [m] (CrowdNav++'s 5 m)"""
    reward: RewardWeights = field(default_factory=lambda: RECIPES["crowdnav"][0])
    """reward weights of the training env (``RECIPES``; default: CrowdNav++'s collision penalty and discomfort
    factor)"""
    timeout_reward: float = 0.0
    """added on the step an episode times out (``FeatureVecEnv``'s ``timeout_reward``; ``RECIPES``)"""
    sampling: str = "uniform"
    """``SAMPLINGS``: sub-envs shared evenly among the training envs, or by their failure rates"""
    resample_every: int = 20
    """with ``sampling="failures"``: rollouts between two reallocations of the sub-envs"""
    fault_target: float | None = None
    """at-fault collisions per training episode the policy may have: the charge for one is then a multiplier learned
    to hold that rate (``fault_constraint``; starting from ``reward.at_fault``, which the env then leaves out);
    None: the fixed weight ``reward.at_fault``"""
    fault_step: float = 200.0
    """with ``fault_target``: the multiplier's change per unit of rate above the target, per rollout [reward units]"""
    seed: int = 0
    """seed of PPO and of the envs (env i resets with seed + i first)"""
    n_steps: int = 128
    """steps per env per rollout"""
    batch_size: int = 1024
    """minibatch size"""
    n_epochs: int = 5
    """passes over each rollout"""
    clip_range: float = 0.2
    """PPO's clipping of the probability ratio"""
    target_kl: float | None = None
    """stop an update's epochs early once the policy moved this far from the one that collected the rollout (KL);
    None: no limit"""
    critic_rollouts: int = 0
    """first updates that fit only the critic, the actor held (``CriticFirstPPO``; for a cloned policy)"""
    learning_rate: float = 3e-4
    """Adam learning rate"""
    gamma: float = 0.99
    """discount per 0.4 s step"""
    net_arch: tuple[int, ...] = (128, 128)
    """hidden layers of the actor and of the critic"""
    extractor: str = "flat"
    """how the actor-critic reads the features: "flat" (the vector as it is) or "attention" (each pedestrian encoded
    alone, then attended over: ``attention.PedestrianAttention``)"""
    closest_approach: bool = False
    """with predictions, add each pedestrian's predicted closest approach to the robot's course to its features"""
    shards: int = 2
    """worker processes the training envs are split into (``FeatureVecEnv``; 1: this process)"""
    tensorboard: str | None = None
    """also log SB3's training figures to TensorBoard in this folder (the ``tensorboard`` extra)"""
    device: str = "auto"
    """where PPO and the envs' forecasts run: auto (a CUDA GPU when torch sees one, else the CPU), cpu, cuda, cuda:N
    or mps (``predictor.devices``)"""
    log_std_init: float = -0.5
    """initial log standard deviation of the Gaussian actions (std 0.61 of the speed limit), also for a run that
    starts from a policy file"""
    initial_forward: float = 0.7
    """without demonstrations: initial mean action along the path to the goal, in speed limits"""
    init_policy: str | None = None
    """start PPO from this policy file (``train_ppo``'s policy.pt, e.g. a clone; its features, extractor and network
    must be this run's); None: clone the teacher (``demo_steps``) or start from scratch"""
    demo_steps: int = 0
    """teacher steps cloned before PPO (0: none; they count towards the budget's wall time, not its env steps)"""
    demos: str = "runs/nav/demos.npz"
    """demonstrations file, shared by both variants (collected when missing or collected with other settings)"""
    bc_epochs: int = 30
    """passes of behaviour cloning over the demonstrations"""
    dagger_rounds: int = 0
    """after cloning: rounds in which the clone drives and the teacher labels the states it reaches (DAgger)"""
    dagger_steps: int = 8_000
    """env steps the clone drives in each DAgger round"""
    minutes: float = float("inf")
    """wall-time budget: learning stops after this long, and the run is written as if the budget was reached"""
    save_every: int = 10
    """rollouts between two saves of the resumable state (``resume.zip``)"""
    out: str = "runs/nav/ppo"
    """output folder"""
    ship_as: str | None = None
    """also copy the policy into pretrained/ under this name"""
    progress: bool = True
    """show a progress bar"""

    @property
    def features(self) -> FeatureConfig:
        """What the policy sees: derived from ``use_predictions`` and ``sensor_range_m``."""
        return FeatureConfig(self.use_predictions, self.sensor_range_m, self.closest_approach and self.use_predictions)


def outcome(info: dict) -> str:
    """goal / collision / timeout of a finished training episode (from the env's ``info["termination"]``)."""
    termination = info["termination"]
    return "timeout" if termination is None else "goal" if termination == "goal" else "collision"


class Resampler:
    """Where a run's ended training episodes failed, per training env, and (``cfg.sampling == "failures"``) the
    sub-envs shared again by those failure rates every ``cfg.resample_every`` rollouts (``failure_sampling``). A
    keeper of ``curve_callback``: ``add`` each ended episode, ``after_rollout``, its ``history`` saved as ``file``.

    Args:
        make_env: (counts, round) -> the training envs with those sub-envs per training env, seeded for that round.
        history: the rounds so far (``sampling.json``: each one's env steps, counts and tally), extended in place.
    """

    file = "sampling.json"

    def __init__(self, cfg: TrainConfig, make_env: Callable[[list[int] | None, int], Any], history: list[dict]):
        self.cfg, self.make_env, self.history = cfg, make_env, history
        self.tally = FailureTally(cfg.env_ids)  # this round's window
        self.totals = FailureTally(cfg.env_ids)  # this segment's (since the run started or resumed)

    @property
    def counts(self) -> list[int] | None:
        """The sub-envs per training env now (None: evenly, the first round)."""
        return self.history[-1]["counts"] if self.history else None

    def first_env(self) -> Any:
        """The training envs of the current round."""
        vec = self.make_env(self.counts, len(self.history))
        self.env_of = vec.env_of
        return vec

    def add(self, sub_env: int, info: dict[str, Any]) -> None:
        """Count an ended episode of sub-env ``sub_env`` (its last ``info``): failed unless at the goal."""
        failed = outcome(info) != "goal"
        self.tally.add(self.env_of[sub_env], failed)
        self.totals.add(self.env_of[sub_env], failed)

    def after_rollout(self, model: Any, rollouts: int) -> None:
        """Every ``resample_every`` rollouts with failure sampling: the training envs made again with the counts of
        the window's failure rates, the model's next rollout starting from their first episodes."""
        if self.cfg.sampling != "failures" or rollouts % self.cfg.resample_every:
            return
        counts = allocate(self.tally.failure_rates(), self.cfg.num_envs)
        self.history.append({"timesteps": int(model.num_timesteps), "counts": counts, "tally": self.tally.as_dict()})
        model.get_env().close()
        vec = self.first_env()
        model.set_env(vec, force_reset=False)
        model._last_obs = vec.reset()  # SB3's own fields for the next rollout's start
        model._last_episode_starts = np.ones(self.cfg.num_envs, bool)
        self.tally.clear()


class FaultMultiplier:
    """A run's at-fault constraint (``cfg.fault_target``; ``fault_constraint``): its multiplier moved after every
    rollout by the rollout's at-fault rate and sent to the training envs as their charge per at-fault collision. It
    starts from the recipe's ``at_fault`` weight (whose own part the env then leaves out) or, resumed, from where it
    was. A keeper of ``curve_callback``, as ``Resampler``.

    Args:
        history: the updates so far (``constraint.json``: env steps, episodes, at-fault ones, multiplier after).
    """

    file = "constraint.json"

    def __init__(self, cfg: TrainConfig, history: list[dict]):
        self.history = history
        start = history[-1].get("multiplier") if history else max(0.0, -cfg.reward.at_fault)
        try:
            self.constraint = FaultConstraint(cfg.fault_target, cfg.fault_step, start)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{Path(cfg.out) / self.file}: its last multiplier cannot continue the run ({err}); "
                             "delete resume.zip to start afresh") from None
        self.episodes = self.at_fault = 0

    @property
    def charge(self) -> float:
        """The charge per at-fault collision now [reward units]."""
        return self.constraint.multiplier

    def add(self, sub_env: int, info: dict[str, Any]) -> None:
        """Count an ended episode (its last ``info``): at fault or not."""
        self.episodes += 1
        self.at_fault += bool(info["at_fault"])

    def after_rollout(self, model: Any, rollouts: int) -> None:
        """Move the multiplier by this rollout's at-fault rate and send it to the training envs."""
        charge = self.constraint.update(self.episodes, self.at_fault)
        self.history.append({"timesteps": int(model.num_timesteps), "episodes": self.episodes,
                             "at_fault": self.at_fault, "multiplier": charge})
        model.get_env().set_fault_charge(charge)
        self.episodes = self.at_fault = 0


def saved_history(cfg: TrainConfig, name: str) -> list[dict]:
    """The list a keeper saved as ``name`` in ``cfg.out`` (empty if none); ``ValueError`` naming the file when it is
    not a JSON list of objects."""
    path = Path(cfg.out) / name
    if not path.is_file():
        return []
    try:
        history = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: cannot read it ({err}); delete resume.zip to start afresh") from None
    if not isinstance(history, list) or not all(isinstance(entry, dict) for entry in history):
        raise ValueError(f"{path}: expected a JSON list of objects; delete resume.zip to start afresh")
    return history


def curve_callback(cfg: TrainConfig, curve: list[dict], timing: dict[str, float], earlier_s: float = 0.0,
                   keepers: Sequence[Resampler | FaultMultiplier] = ()) -> Any:
    """A stable-baselines3 callback: progress bar, a curve point every rollout, the resumable state every
    ``cfg.save_every`` rollouts, a stop once ``cfg.minutes`` of wall time have passed; adds the wall time of the
    rollouts (envs and the policy acting) and of the updates to ``timing["rollout_s"]`` and ``timing["update_s"]``.
    A point's ``wall_s`` counts from the run's start: ``earlier_s`` [s] is the wall time of the segments before a
    resume. Each of ``keepers`` counts every ended episode (``add``), acts after every rollout (``after_rollout``)
    and is saved with the resumable state."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Curve(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = tqdm(total=cfg.timesteps, initial=self.model.num_timesteps, unit="step",
                            disable=not cfg.progress, desc="ppo")
            self.rollouts, self.started = 0, time.monotonic()
            self.mark = self.started  # when the current rollout (or update) began
            self.deadline = self.started + 60 * cfg.minutes
            self.recent: deque[tuple[str, float]] = deque(maxlen=CURVE_WINDOW)

        def _on_step(self) -> bool:
            self.bar.update(cfg.num_envs)
            for i, (done, info) in enumerate(zip(self.locals["dones"], self.locals["infos"], strict=True)):
                if done:
                    self.recent.append((outcome(info), float(info["episode"]["r"])))
                    for keeper in keepers:
                        keeper.add(i, info)
            return time.monotonic() < self.deadline

        def _on_rollout_start(self) -> None:
            now = time.monotonic()
            timing["update_s"] += now - self.mark if self.rollouts else 0.0  # the update after the last rollout
            self.mark = now

        def _on_rollout_end(self) -> None:
            now = time.monotonic()
            timing["rollout_s"] += now - self.mark
            self.mark = now
            if self.recent:
                kinds = [kind for kind, _ in self.recent]
                wall_s = earlier_s + time.monotonic() - self.started
                curve.append({"timesteps": int(self.num_timesteps), "wall_s": round(wall_s, 1),
                              "episodes": len(kinds),
                              "success": kinds.count("goal") / len(kinds),
                              "collision": kinds.count("collision") / len(kinds),
                              "return": float(np.mean([r for _, r in self.recent]))})
                self.bar.set_postfix(success=f"{curve[-1]['success']:.2f}", collision=f"{curve[-1]['collision']:.2f}")
            self.rollouts += 1
            for keeper in keepers:
                keeper.after_rollout(self.model, self.rollouts)
            if self.rollouts % cfg.save_every == 0:
                save_resumable(self.model, cfg, curve, keepers)

        def _on_training_end(self) -> None:
            timing["update_s"] += time.monotonic() - self.mark if self.rollouts else 0.0
            self.bar.close()

    return Curve()


def save_resumable(model: Any, cfg: TrainConfig, curve: list[dict],
                   keepers: Sequence[Resampler | FaultMultiplier] = ()) -> None:
    """Write the whole PPO state (``resume.zip``), the settings it needs, the curve so far and each keeper's history
    (``sampling.json``, ``constraint.json``), each atomically."""
    out = Path(cfg.out)
    for keeper in keepers:
        write_text_atomic(out / keeper.file, strict_json.dumps(keeper.history, indent=1))
    with atomic_path(out / "resume.zip") as tmp, open(tmp, "wb") as file:
        model.save(file)
    write_text_atomic(out / "resume.json", strict_json.dumps({k: asdict(cfg)[k] for k in RESUMABLE}, default=str))
    write_text_atomic(out / "curve.json", strict_json.dumps(curve, indent=1))


def resumable_state(cfg: TrainConfig) -> tuple[Path, list[dict]] | None:
    """(``resume.zip``, curve so far) of an earlier run with the same settings in ``cfg.out``, or None.

    Raises:
        ValueError: the folder holds the state of a run with other settings (names the differing ones).
    """
    out = Path(cfg.out)
    if not (out / "resume.zip").is_file():
        return None
    try:
        saved = json.loads((out / "resume.json").read_text())
    except FileNotFoundError:
        raise ValueError(f"{out}/resume.zip has no resume.json beside it (the settings it was saved with); use "
                         "another --out, or delete resume.zip to start afresh") from None
    except (OSError, ValueError) as err:
        raise ValueError(f"{out}/resume.json: cannot read the settings of the saved run ({err}); use another --out, "
                         "or delete resume.zip and resume.json to start afresh") from None
    if not isinstance(saved, dict):
        raise ValueError(f"{out}/resume.json: expected the saved run's settings as a JSON object")
    wanted = json.loads(strict_json.dumps({k: asdict(cfg)[k] for k in RESUMABLE}, default=str))
    differing = sorted(k for k in RESUMABLE if saved.get(k) != wanted[k])
    if differing:
        raise ValueError(f"{out}/resume.zip: saved by a run with other settings ({', '.join(differing)}); "
                         "use another --out or delete it to start afresh")
    curve_path = out / "curve.json"
    return out / "resume.zip", json.loads(curve_path.read_text()) if curve_path.exists() else []


def saved_rounds(cfg: TrainConfig) -> list[dict]:
    """The sampling rounds a saved run in ``cfg.out`` went through (``sampling.json``; none if it has none).

    Raises:
        ValueError: the file is not a list of rounds whose counts fit this run (names the file).
    """
    path = Path(cfg.out) / Resampler.file
    rounds = saved_history(cfg, Resampler.file)
    fits = all(
        isinstance(r.get("counts"), list) and len(r["counts"]) == len(cfg.env_ids)
        and all(type(c) is int and c >= 1 for c in r["counts"]) and sum(r["counts"]) == cfg.num_envs
        for r in rounds)
    if not fits:
        raise ValueError(f"{path}: expected a list of rounds, each with 'counts' of {len(cfg.env_ids)} ints >= 1 "
                         f"summing to {cfg.num_envs}; delete resume.zip to start afresh")
    return rounds


def clone_teacher(policy: Any, cfg: TrainConfig, net_arch: list[int]) -> dict[str, Any]:
    """Clone ``cfg.demo_steps`` teacher steps (the file ``cfg.demos``, shared by both variants) into the actor-critic
    ``policy``, then run ``cfg.dagger_rounds`` DAgger rounds; returns the record (fit and steps after each round).

    Round r saves the clone to ``dagger-r.pt`` in ``cfg.out``, lets it drive ``cfg.dagger_steps`` steps from episode
    seeds of its own (``DemoSpec().seed + r * DAGGER_SEED_STRIDE``...) with the teacher labelling (``dagger-r.npz``,
    reused by a run restarted with the same settings), and fits the clone again on every label so far.
    """
    reward = asdict(cfg.reward)  # the critic is cloned to the teacher's returns under the training reward
    demos = load_or_collect(DemoSpec(cfg.env_ids[0], cfg.demo_steps, closest_approach=cfg.closest_approach,
                                     reward=reward), cfg.demos, cfg.progress)
    record: dict[str, Any] = {"demo_collection_s": demos.wall_time_s, "rounds": []}
    for round_ in range(cfg.dagger_rounds + 1):
        if round_ > 0:
            student = Path(cfg.out) / f"dagger-{round_}.pt"
            save_policy(policy, cfg.features, net_arch, student, cfg.extractor)
            spec = DemoSpec(cfg.env_ids[0], cfg.dagger_steps, seed=DemoSpec().seed + round_ * DAGGER_SEED_STRIDE,
                            closest_approach=cfg.closest_approach, student=str(student), reward=reward)
            demos = concatenate([demos, load_or_collect(spec, student.with_suffix(".npz"), cfg.progress)])
        fit = behaviour_clone(policy, demos, cfg.use_predictions, cfg.gamma, cfg.bc_epochs, seed=cfg.seed + round_)
        record["rounds"].append({"labelled_steps": len(demos.actions), "wall_s": round(demos.wall_time_s, 1), **fit})
        print(f"behaviour cloning, round {round_} ({len(demos.actions)} labelled steps): {fit}")
    return record


def start_from(policy: Any, cfg: TrainConfig, net_arch: list[int]) -> str:
    """Load the weights of the policy file ``cfg.init_policy`` into ``policy``, its action noise set to
    ``cfg.log_std_init``; returns the file's SHA-256 (the run's record keeps it: the path may later hold another file).

    Raises:
        ValueError: the file's policy reads other features or has another extractor or network (``PolicyFileError``
            for a missing or damaged file).
    """
    import torch

    saved, features = load_policy(cfg.init_policy)  # a missing or damaged file: PolicyFileError, naming it
    sha256 = sha256_of(policy_file(cfg.init_policy)[0])
    if features != cfg.features:
        raise ValueError(f"--init-policy {cfg.init_policy}: the policy reads {features}, this run {cfg.features}")
    own = policy.state_dict()
    theirs = saved.state_dict()
    if own.keys() != theirs.keys() or any(own[k].shape != theirs[k].shape for k in own):
        raise ValueError(f"--init-policy {cfg.init_policy}: its network differs from this run's (--extractor "
                         f"{cfg.extractor}, net_arch {net_arch})")
    policy.load_state_dict(theirs)
    with torch.no_grad():  # PPO's exploration starts where the run says, whatever the file's policy had
        policy.log_std.fill_(cfg.log_std_init)
    return sha256


def plot_curve(curves: dict[str, list[dict] | list[list[dict]]], path: Path, title: str) -> Path | None:
    """Learning-curve PNG of one or more runs: success rate (top) and mean return (bottom) of the last
    ``CURVE_WINDOW`` training episodes against env steps, one colour per label. A label holds one run's
    ``curve.json`` points (drawn raw and smoothed) or a list of several runs' (seeds: smoothed mean and range band).

    Returns the path, or None (with a note on stderr) when matplotlib is not installed: the curve's data is in
    ``curve.json`` and ``benchmarks/ppo_curves.py`` draws it later.
    """
    from st_sim.charts import learning_curves, save_figure

    runs = {label: [runs] if not runs or isinstance(runs[0], dict) else runs for label, runs in curves.items()}
    runs = {label: [run for run in label_runs if run] for label, label_runs in runs.items()}
    panels = [(f"{name} (last {CURVE_WINDOW} episodes)",
               {label: [(np.array([p["timesteps"] for p in run]), np.array([p[key] for p in run])) for run in
                        label_runs] for label, label_runs in runs.items() if label_runs})
              for key, name in (("success", "success rate"), ("return", "mean return"))]
    try:
        figure = learning_curves("env steps", panels, title=title)
    except ImportError as err:
        print(f"{path} not drawn: {err}", file=sys.stderr)
        return None
    return save_figure(figure, path)


def main(cfg: TrainConfig) -> Path:
    """Train, write the policy, the curve and the run record; returns the policy path."""
    import torch
    from stable_baselines3.common.vec_env import VecMonitor

    from envs.suite import load_suite
    from st_sim.apps.navigation.critic_first import CriticFirstPPO
    from st_sim.apps.navigation.training_envs import FeatureVecEnv

    # seeding: torch, numpy, envs (PPO's own generators through seed=)
    torch.set_num_threads(1)
    torch.manual_seed(cfg.seed)
    out = Path(cfg.out)
    variant = "predictions" if cfg.use_predictions else "no-predictions"
    envs_name = f"suite-train-{len(cfg.scenarios)}-scenarios" if cfg.scenarios else "+".join(cfg.env_ids)
    run_name = f"{envs_name}__ppo-{variant}__seed{cfg.seed}"
    print(f"{run_name}: {strict_json.dumps(asdict(cfg), default=str)}")

    # envs: num_envs sub-envs as native vector envs in cfg.shards processes (one batched forecast per step in each),
    # seen through the features
    device = resolve_device(cfg.device)
    train_seeds = load_suite().train if cfg.scenarios else None

    resuming = (out / "resume.zip").is_file()
    multiplier = None if cfg.fault_target is None else FaultMultiplier(
        cfg, saved_history(cfg, FaultMultiplier.file) if resuming else [])
    reward = cfg.reward if multiplier is None else replace(cfg.reward, at_fault=0.0)  # the constraint charges it

    def make_env(counts: list[int] | None, round_: int) -> VecMonitor:
        vec = VecMonitor(FeatureVecEnv(cfg.env_ids, cfg.num_envs, cfg.features, EnvConfig(reward=reward),
                                       cfg.shards, str(device), train_seeds, counts, cfg.timeout_reward,
                                       0.0 if multiplier is None else multiplier.charge))
        vec.seed(cfg.seed + round_ * SAMPLING_SEED_STRIDE)
        return vec

    history = saved_rounds(cfg) if resuming else []
    resampler = Resampler(cfg, make_env, history)
    keepers = [resampler] if multiplier is None else [resampler, multiplier]
    vec = resampler.first_env()

    # model: PPO with a tanh actor-critic on the flat features or on their attention encoding (same for both variants)
    net_arch = list(cfg.net_arch)
    model = CriticFirstPPO("MlpPolicy", vec, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
                           clip_range=cfg.clip_range, target_kl=cfg.target_kl, critic_rollouts=cfg.critic_rollouts,
                           learning_rate=cfg.learning_rate, gamma=cfg.gamma, seed=cfg.seed, device=device, verbose=0,
                           tensorboard_log=cfg.tensorboard,
                           policy_kwargs={**policy_kwargs(cfg.features, net_arch, cfg.extractor),
                                          "log_std_init": cfg.log_std_init})

    # start: continue a saved run, clone the teacher (same demonstrations for both variants), or walk the path
    start = time.perf_counter()
    cloning, started_from, resumed_from, curve, earlier_s = None, None, 0, [], 0.0
    saved = resumable_state(cfg)
    if saved is not None:
        model = CriticFirstPPO.load(saved[0], env=vec, device=device)
        resumed_from, curve = int(model.num_timesteps), saved[1]
        earlier_s = curve[-1]["wall_s"] if curve else 0.0  # the saved segments' wall time, up to their last save
        rollout = cfg.n_steps * cfg.num_envs  # PPO learns whole rollouts: a budget of T ends within one past T
        if resumed_from >= cfg.timesteps + rollout:
            vec.close()
            raise ValueError(f"{out} holds a run of {resumed_from} env steps; --timesteps {cfg.timesteps} cannot "
                             "shrink it (ask for more to extend it, or use another --out)")
        if resumed_from >= cfg.timesteps and (out / "training.json").is_file() and (out / "policy.pt").is_file():
            vec.close()  # the same command again: the finished run stands as it was (and is shipped if asked)
            if cfg.ship_as:
                ship(out / "policy.pt", cfg.ship_as, json.loads((out / "training.json").read_text()))
            print(f"{out} finished at {resumed_from} env steps; its policy.pt and training.json stand")
            return out / "policy.pt"
        print(f"resuming {saved[0]} at {resumed_from} env steps")
        if (out / "cloning.json").is_file():
            cloning = json.loads((out / "cloning.json").read_text())
        if (out / "init_policy.json").is_file():
            started_from = json.loads((out / "init_policy.json").read_text())
    elif cfg.init_policy is not None:
        started_from = {"path": cfg.init_policy, "sha256": start_from(model.policy, cfg, net_arch)}
        write_text_atomic(out / "init_policy.json", strict_json.dumps(started_from, indent=1))
        save_resumable(model, cfg, curve)
    elif cfg.demo_steps > 0:
        cloning = clone_teacher(model.policy, cfg, net_arch)
        write_text_atomic(out / "cloning.json", strict_json.dumps(cloning, indent=1))
        save_resumable(model, cfg, curve)  # a run killed during PPO restarts from the clone
    else:
        with torch.no_grad():  # exploration then learns when to deviate from the path
            model.policy.action_net.bias.copy_(torch.tensor([cfg.initial_forward, 0.0]))

    # loop: rollouts -> PPO updates, a curve point per rollout, the resumable state every save_every rollouts
    learning, timing = time.perf_counter(), {"rollout_s": 0.0, "update_s": 0.0}
    if cfg.timesteps > resumed_from:
        model.learn(total_timesteps=cfg.timesteps - resumed_from,
                    callback=curve_callback(cfg, curve, timing, earlier_s, keepers),
                    reset_num_timesteps=resumed_from == 0, tb_log_name=run_name)
        vec = model.get_env()  # the last round's
    learnt_s = max(time.perf_counter() - learning, 1e-9)
    steps_per_s = (model.num_timesteps - resumed_from) / learnt_s
    shares = {name.removesuffix("_s"): round(seconds / learnt_s, 3) for name, seconds in timing.items()}
    save_resumable(model, cfg, curve, keepers)
    wall_time_s = earlier_s + time.perf_counter() - start
    vec.close()
    print(f"{model.num_timesteps - resumed_from} env steps learnt at {steps_per_s:.0f} env steps/s "
          f"(rollouts {100 * shares['rollout']:.0f} % of the time, updates {100 * shares['update']:.0f} %)")

    # checkpoint: the actor-critic alone, as plain tensors (atomic write), then the curve and the record
    policy = build_policy(cfg.features, net_arch, cfg.extractor)
    policy.load_state_dict(model.policy.state_dict())
    sha256 = save_policy(policy, cfg.features, net_arch, out / "policy.pt", cfg.extractor)
    write_text_atomic(out / "curve.json", strict_json.dumps(curve, indent=1))
    plot_curve({run_name: curve}, out / "curve.png", run_name)
    record = {"run": run_name, "config": asdict(cfg), "wall_time_s": wall_time_s, "cloning": cloning,
              "init_policy_sha256": None if started_from is None else started_from["sha256"],
              "resumed_from": resumed_from, "sha256": sha256, "env_steps_per_s": steps_per_s, "time_shares": shares,
              "sampling": {"rounds": len(history), "counts": resampler.counts,
                           "episodes_since_start": resampler.totals.as_dict()},
              "fault_constraint": None if multiplier is None else {"multiplier": multiplier.charge,
                                                                   "updates": len(multiplier.history)},
              "final": curve[-1] if curve else None, "command": "python -m st_sim.apps.navigation.train_ppo "
              + " ".join(sys.argv[1:])}
    write_text_atomic(out / "training.json", strict_json.dumps(record, indent=1, default=str))
    if cfg.ship_as:
        ship(out / "policy.pt", cfg.ship_as, record)
    print(f"wrote {out}/policy.pt, curve.png, curve.json, training.json ({wall_time_s / 60:.1f} min)")
    return out / "policy.pt"


def ship(policy_path: Path, name: str, record: dict) -> Path:
    """Copy a trained policy into the package's pretrained/ folder and record it in the manifest: its file and
    SHA-256, the command, the training envs, the wall time, the last curve point (``final_training``: its
    ``timesteps`` within one rollout of the env steps the run learnt, never its budget) and the SHA-256 of the
    policy it started from."""
    folder = Path(str(resources.files(__package__).joinpath(PRETRAINED_DIR)))
    folder.mkdir(exist_ok=True)
    target = folder / f"{name}.pt"
    shutil.copyfile(policy_path, target)
    manifest_path = folder / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {"policies": {}}
    manifest["policies"][name] = {"file": target.name, "sha256": record["sha256"], "command": record["command"],
                                  "env_ids": record["config"]["env_ids"],
                                  "wall_time_s": round(record["wall_time_s"], 1), "final_training": record["final"],
                                  "cloning": record["cloning"], "init_policy_sha256": record.get("init_policy_sha256")}
    write_text_atomic(manifest_path, strict_json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return target


COUNTS: tuple[tuple[str, int, str], ...] = (
    ("timesteps", 0, "PPO env steps, 0: stop after cloning"),
    ("num_envs", 1, "sub-envs"),
    ("shards", 1, "worker processes the sub-envs are split into"),
    ("n_steps", 2, "steps per sub-env per rollout"),
    ("batch_size", 2, "minibatch size"),
    ("n_epochs", 1, "passes over each rollout"),
    ("critic_rollouts", 0, "first updates that fit only the critic, the actor held (for a cloned policy)"),
    ("demo_steps", 0, "teacher steps cloned before PPO, 0 for none"),
    ("bc_epochs", 1, "passes of behaviour cloning over the labels, per round"),
    ("dagger_rounds", 0, "DAgger rounds after cloning, with --demo-steps"),
    ("dagger_steps", 1, "env steps the clone drives per DAgger round"),
    ("save_every", 1, "rollouts between saves of the resumable state"),
    ("resample_every", 1, "with --sampling failures: rollouts between two reallocations of the sub-envs"),
)
"""integer settings with a flag each: TrainConfig field, least value, what it sets"""
RATES: tuple[tuple[str, str], ...] = (
    ("learning_rate", "Adam learning rate"),
    ("clip_range", "PPO's clipping of the probability ratio"),
    ("target_kl", "stop an update's epochs once the policy's KL from the rollout's exceeds this (default: no limit)"),
)
"""settings in (0, 1) with a flag each: TrainConfig field, what it sets"""


def parse_args(argv: list[str] | None = None) -> TrainConfig:
    """TrainConfig from command-line flags (defaults as in the dataclass)."""
    d = TrainConfig()
    parser = argparse.ArgumentParser(prog="python -m st_sim.apps.navigation.train_ppo", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--no-predictions", action="store_true", help="train without the predicted futures")
    parser.add_argument("--scenarios", nargs="+", default=None, metavar="NAME",
                        help="train on these scenarios of the shipped navigation suite ('all': every one), every "
                             "episode from its train split (never a val or test seed); replaces --env-ids")
    parser.add_argument("--hold-out", nargs="+", default=[], metavar="NAME",
                        help="with --scenarios: leave out these scenarios, a scene's name leaving out all of its "
                             "(e.g. zara1 univ: zara1-log, zara1-reactive, univ-log, univ-reactive)")
    parser.add_argument("--env-ids", "--env-id", nargs="+", default=list(d.env_ids), metavar="ID[:MODE]",
                        help="training envs, MODE a replay's pedestrians (log or reactive), e.g. "
                             "STCrowd-Eth-v0:reactive; several share the sub-envs evenly (default: "
                             f"{' '.join(d.env_ids)})")
    for name, _, what in COUNTS:
        parser.add_argument(f"--{name.replace('_', '-')}", type=int, default=getattr(d, name),
                            help=f"{what} (default: {getattr(d, name)})")
    for name, what in RATES:
        parser.add_argument(f"--{name.replace('_', '-')}", type=float, default=getattr(d, name),
                            help=what if getattr(d, name) is None else f"{what} (default: {getattr(d, name)})")
    parser.add_argument("--sensor-range", type=float, default=d.sensor_range_m,
                        help=f"pedestrians sensed and forecast within this distance [m], inf: all (default: "
                        f"{d.sensor_range_m})")
    parser.add_argument("--minutes", type=float, default=d.minutes,
                        help="wall-time budget in minutes; learning stops there (default: none)")
    parser.add_argument("--seed", type=int, default=d.seed, help=f"seed (default: {d.seed})")
    parser.add_argument("--init-policy", default=None, metavar="PATH",
                        help="start PPO from this policy file (a clone's policy.pt) instead of cloning or scratch")
    parser.add_argument("--log-std-init", type=float, default=d.log_std_init,
                        help=f"initial log standard deviation of PPO's actions, in speed limits (default: "
                        f"{d.log_std_init}; lower keeps a cloned policy closer to its teacher)")
    parser.add_argument("--demos", default=d.demos, help=f"demonstrations file, shared by both variants "
                        f"(default: {d.demos})")
    parser.add_argument("--out", default=d.out, help=f"output folder (default: {d.out})")
    parser.add_argument("--ship", default=None, help="also copy the policy into pretrained/ under this name")
    parser.add_argument("--extractor", choices=EXTRACTORS, default=d.extractor,
                        help=f"how the policy reads the features (default: {d.extractor})")
    parser.add_argument("--closest-approach", action="store_true",
                        help="add each pedestrian's predicted closest approach to the robot's course to its features")
    parser.add_argument("--recipe", choices=sorted(RECIPES), default="crowdnav",
                        help="the training reward: crowdnav (every collision -20, a timeout free; the shipped "
                             "policies') or benchmark (a collision -10, 20 more when the fault rule puts it on the "
                             "robot, a timeout -10) (default: crowdnav)")
    parser.add_argument("--sampling", choices=SAMPLINGS, default=d.sampling,
                        help="share the sub-envs among the training envs evenly, or by how often the policy fails in "
                             f"each, again every --resample-every rollouts (default: {d.sampling})")
    parser.add_argument("--fault-target", type=float, default=None, metavar="RATE",
                        help="hold the at-fault collisions per training episode at RATE with a learned charge "
                             "(a Lagrangian multiplier starting from the recipe's at-fault weight) instead of a fixed "
                             "one (default: fixed)")
    parser.add_argument("--fault-step", type=float, default=d.fault_step, metavar="W",
                        help=f"with --fault-target: the charge's change per unit of rate above it, per rollout "
                             f"(default: {d.fault_step})")
    parser.add_argument("--prediction-reward", type=float, default=0.0, metavar="W",
                        help="weight of the prediction-aware reward part predicted_collision (default: 0, off)")
    parser.add_argument("--device", default=d.device, help=f"where PPO and the envs' forecasts run: {DEVICE_HELP} "
                        f"(default: {d.device})")
    parser.add_argument("--tensorboard", default=None, metavar="DIR",
                        help="also log training figures to TensorBoard in DIR (pip install -e '.[tensorboard]')")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    for name, least, _ in COUNTS:
        if getattr(args, name) < least:
            parser.error(f"--{name.replace('_', '-')}={getattr(args, name)}: expected an integer >= {least}")
    for name, _ in RATES:
        if getattr(args, name) is not None and not 0 < getattr(args, name) < 1:  # also refuses NaN
            parser.error(f"--{name.replace('_', '-')}={getattr(args, name)}: expected a number in (0, 1)")
    if not args.sensor_range > 0:  # also refuses NaN
        parser.error(f"--sensor-range={args.sensor_range}: expected a distance > 0 (or inf)")
    if not args.minutes > 0:
        parser.error(f"--minutes={args.minutes}: expected a duration > 0")
    if args.init_policy is not None and args.demo_steps > 0:
        parser.error("--init-policy: the run starts from that policy; drop --demo-steps (or --init-policy)")
    if args.dagger_rounds > 0 and args.demo_steps == 0:
        parser.error("--dagger-rounds: DAgger refines a clone; add --demo-steps N")
    if not np.isfinite(args.log_std_init):
        parser.error(f"--log-std-init={args.log_std_init}: expected a finite number")
    if args.demo_steps > 0 and len(args.env_ids) > 1:
        parser.error("--demo-steps: the teacher's demonstrations come from one env; give one --env-ids (or start from "
                     "a policy trained there with --init-policy)")
    if args.demo_steps > 0 and args.sensor_range != float("inf"):
        parser.error("--demo-steps: the teacher's demonstrations see every pedestrian; add --sensor-range inf")
    if args.tensorboard is not None and util.find_spec("tensorboard") is None:
        parser.error("--tensorboard: TensorBoard is not installed; pip install -e '.[tensorboard]'")
    try:
        resolve_device(args.device)
    except DeviceError as err:
        parser.error(f"--device: {err}")
    if not np.isfinite(args.prediction_reward):
        parser.error(f"--prediction-reward={args.prediction_reward}: expected a finite weight")
    scenarios, env_ids = training_scenarios(parser, args)
    if args.sampling == "failures" and len(env_ids) < 2:
        parser.error("--sampling failures: it shares the sub-envs among several training envs; give --scenarios or "
                     "several --env-ids")
    if args.sampling == "failures" and args.num_envs < len(env_ids):
        parser.error(f"--sampling failures: --num-envs {args.num_envs} leaves some of the {len(env_ids)} training "
                     "envs without a sub-env")
    if args.fault_target is not None and not 0 <= args.fault_target < 1:  # also refuses NaN
        parser.error(f"--fault-target={args.fault_target}: expected a rate in [0, 1)")
    if not 0 < args.fault_step < np.inf:
        parser.error(f"--fault-step={args.fault_step}: expected a finite number > 0")
    weights, timeout_reward = RECIPES[args.recipe]
    return TrainConfig(use_predictions=not args.no_predictions, env_ids=env_ids, scenarios=scenarios,
                       sensor_range_m=args.sensor_range, timeout_reward=timeout_reward, sampling=args.sampling,
                       fault_target=args.fault_target, fault_step=args.fault_step,
                       seed=args.seed, reward=replace(weights, prediction=args.prediction_reward),
                       extractor=args.extractor, closest_approach=args.closest_approach, tensorboard=args.tensorboard,
                       demos=args.demos, minutes=args.minutes, log_std_init=args.log_std_init, device=args.device,
                       init_policy=args.init_policy, out=args.out, ship_as=args.ship, progress=not args.quiet,
                       **{name: getattr(args, name) for name, *_ in (*COUNTS, *RATES)})


def training_scenarios(parser: argparse.ArgumentParser, args: argparse.Namespace
                       ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(suite scenarios, training envs) of the flags: --scenarios less --hold-out and their envs, or () and
    --env-ids; a parser error for an unknown name or a hold-out that leaves nothing."""
    from envs.suite import SuiteError, load_suite
    from st_sim.apps.navigation.training_envs import scenario_env

    if args.scenarios is None:
        if args.hold_out:
            parser.error("--hold-out: it leaves scenarios out of --scenarios; add --scenarios all (or names)")
        return (), tuple(args.env_ids)
    if args.demo_steps > 0:
        parser.error("--demo-steps: the teacher's demonstrations come from one env; start from a policy with "
                     "--init-policy to train on --scenarios")
    suite = load_suite()
    try:
        chosen = suite.select(None if args.scenarios == ["all"] else args.scenarios)
    except SuiteError as err:
        parser.error(f"--scenarios: {err}")
    names = {scenario.name for scenario in suite.scenarios}
    for name in args.hold_out:
        if name not in names and not any(other.startswith(f"{name}-") for other in names):
            parser.error(f"--hold-out {name}: neither a scenario nor a scene of suite {suite.name} {suite.version}")
    kept = [s for s in chosen if not any(s.name == h or s.name.startswith(f"{h}-") for h in args.hold_out)]
    if not kept:
        parser.error("--hold-out leaves no scenario to train on")
    if suite.train is None:
        parser.error(f"--scenarios: suite {suite.name} {suite.version} states no train split")
    return tuple(s.name for s in kept), tuple(scenario_env(s) for s in kept)


def cli(argv: list[str] | None = None) -> int:
    """The command: train, or print one ``error: ...`` line and return 1 for a run it cannot start or resume."""
    cfg = parse_args(argv)
    try:
        main(cfg)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(cli())
