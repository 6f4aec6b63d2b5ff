"""Teacher demonstrations for the learned policy: collect them once, then clone them into a PPO actor-critic.

    demos = load_or_collect(DemoSpec("STCrowd-SimCrossing-v1", steps=16_000), "runs/nav/demos.npz")
    behaviour_clone(model.policy, demos, use_predictions=True)   # before model.learn(...)
    # DAgger: the clone drives, the teacher labels the states the clone reaches; clone again on both
    more = load_or_collect(DemoSpec(steps=8_000, seed=70_000, student="runs/nav/clone.pt"), "runs/nav/dagger-1.npz")
    behaviour_clone(model.policy, concatenate([demos, more]), use_predictions=True)

A teacher (the sampling MPC with SingularTrajectory, the table's best planner) drives the ego; every step
keeps the features both policy variants would see (with and without the predicted futures), the teacher's
command as a policy action (path frame, speed limits) and the reward. Both variants clone the same file, so
they start from the same teacher and differ only in their features, as in PPO afterwards. Cloning fits the
actor's mean action to the teacher (mean squared error) and the critic to the discounted returns the teacher
earned, so PPO's first updates refine a walking, avoiding policy instead of discovering one.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from envs.common.config import EnvConfig, RewardWeights
from replays import strict_json
from replays.atomic import atomic_path
from st_sim.apps.navigation.features import FeatureConfig, drop_predictions, encode, path_frame, to_velocity
from st_sim.apps.navigation.ppo import load_policy

FORMAT = "stcrowd-nav-demos/1"
ARRAYS = ("features_with", "features_without", "actions", "rewards", "episode_ends")  # the arrays of ``Demos``


class DemoFileError(ValueError):
    """A demonstrations file is unreadable or was collected with other settings."""


@dataclass(frozen=True)
class DemoSpec:
    """What to collect: ``steps`` teacher steps on ``env_id`` from episodes seeded ``seed``, ``seed + 1``, ..."""

    env_id: str = "STCrowd-SimCrossing-v1"
    """env the teacher drives in (with SingularTrajectory's futures in the observation)"""
    steps: int = 16_000
    """env steps to collect over all workers [-]"""
    seed: int = 20_000
    """first episode seed (kept apart from the evaluation seeds 0..9999) [-]"""
    teacher: str = "mpc"
    """planner that drives (with the "singular" predictor)"""
    workers: int = 2
    """processes that collect in parallel (worker w seeds seed + w * 100000 + episode) [-]"""
    closest_approach: bool = False
    """the features with predictions also hold each pedestrian's predicted closest approach (``FeatureConfig``)"""
    student: str | None = None
    """a policy file (``ppo.save_policy``) that drives instead of the teacher, which then only labels the states
    the student reaches (a DAgger round); None: the teacher drives"""
    reward: dict[str, float] | None = None
    """reward weights of the env the teacher drives in (``RewardWeights`` fields; the returns the critic is cloned
    to are under them, so give PPO's training reward); None: the env's defaults"""


@dataclass(frozen=True, eq=False)
class Demos:
    """Collected teacher steps (T of them, in episode order).

    Attributes:
        features_with: (T, F1) float32 features with the predicted futures.
        features_without: (T, F0) float32 features without them.
        actions: (T, 2) float32 teacher commands as policy actions in [-1, 1] (path frame, speed limits).
        rewards: (T,) float32 env rewards.  episode_ends: (T,) bool, the step ended its episode.
        wall_time_s: how long collecting them took [s].
    """

    features_with: np.ndarray
    features_without: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    episode_ends: np.ndarray
    wall_time_s: float = 0.0

    def features(self, use_predictions: bool) -> np.ndarray:
        """(T, F) features of the variant with or without the predicted futures."""
        return self.features_with if use_predictions else self.features_without

    def returns(self, gamma: float) -> np.ndarray:
        """(T,) discounted return from each step to its episode's end."""
        out, running = np.empty(len(self.rewards), np.float32), 0.0
        for t in range(len(self.rewards) - 1, -1, -1):
            running = self.rewards[t] + (0.0 if self.episode_ends[t] else gamma * running)
            out[t] = running
        return out


def concatenate(parts: list[Demos]) -> Demos:
    """The steps of several collections one after another (their episodes stay whole); wall times add up."""
    return Demos(*(np.concatenate([getattr(part, name) for part in parts]) for name in ARRAYS),
                 wall_time_s=sum(part.wall_time_s for part in parts))


def collect(spec: DemoSpec, progress: bool = True) -> Demos:
    """Run the teacher for ``spec.steps`` env steps (``spec.workers`` processes); unfinished episodes at the end
    of a worker's share are kept, marked as ended."""
    start = time.perf_counter()
    if spec.steps < 1 or spec.workers < 1:
        raise ValueError(f"DemoSpec.steps={spec.steps}, workers={spec.workers}: expected both >= 1")
    shares = [spec.steps // spec.workers + (w < spec.steps % spec.workers) for w in range(spec.workers)]
    jobs = [(spec, w, share) for w, share in enumerate(shares) if share > 0]
    context = get_context("spawn")
    steps_done = context.Value("q", 0)
    with context.Pool(len(jobs), initializer=_share_counter, initargs=(steps_done,)) as pool, \
            tqdm(total=spec.steps, unit="step", desc="teacher", disable=not progress) as bar:
        result = pool.map_async(_collect_share, jobs)
        while not result.ready():
            result.wait(1.0)
            bar.update(steps_done.value - bar.n)
        parts = result.get()
        bar.update(steps_done.value - bar.n)
    return Demos(*(np.concatenate([part[i] for part in parts]) for i in range(5)),
                 wall_time_s=time.perf_counter() - start)


_steps_done: Any = None  # in a collecting worker: the pool's shared step counter


def _share_counter(counter: Any) -> None:
    """Pool initializer: keep the shared step counter the workers add to."""
    global _steps_done
    _steps_done = counter


def _collect_share(job: tuple[DemoSpec, int, int]) -> tuple[np.ndarray, ...]:
    """One worker's share of ``collect``: arrays in the field order of ``Demos``."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ids in the subprocess)
    from st_sim.apps.navigation.planners import make_planner
    from st_sim.apps.navigation.predictors import env_predictor
    from st_sim.apps.navigation.world import world_of

    spec, worker, share = job
    config = None if spec.reward is None else EnvConfig(reward=RewardWeights(**spec.reward))
    env = gym.make(spec.env_id, predictor=env_predictor("singular"), config=config)
    world = world_of(env)
    teacher = make_planner(spec.teacher, world, "singular")
    with_predictions = FeatureConfig(True, closest_approach=spec.closest_approach)
    student, student_cfg = load_student(spec) if spec.student is not None else (None, None)
    rows: list[tuple[np.ndarray, ...]] = []
    episode = 0
    while len(rows) < share:
        obs, _ = env.reset(seed=spec.seed + worker * 100_000 + episode)
        teacher.reset()
        episode += 1
        done = False
        while not done and len(rows) < share:
            velocity, frame = teacher.act(obs), path_frame(obs, world)
            action = np.clip(frame @ velocity / world.max_speed_mps, -1.0, 1.0)
            features_with = encode(obs, world, with_predictions, frame)  # rays and slots once for both variants
            features = (features_with, drop_predictions(features_with, with_predictions))
            if student is not None:
                own, _ = student.predict(features[0 if student_cfg.use_predictions else 1], deterministic=True)
                velocity = to_velocity(own, obs, world, frame)
            obs, reward, terminated, truncated, _ = env.step(velocity)
            done = terminated or truncated
            rows.append((*features, action.astype(np.float32), np.float32(reward), done))
            if _steps_done is not None:
                with _steps_done.get_lock():
                    _steps_done.value += 1
        if rows:
            rows[-1] = (*rows[-1][:4], True)
    env.close()
    return tuple(np.stack([row[i] for row in rows]) for i in range(5))


def load_student(spec: DemoSpec) -> tuple[Any, FeatureConfig]:
    """(actor-critic, its FeatureConfig) of ``spec.student``, checked to read the features collected for ``spec``.

    Raises:
        DemoFileError: the student sees other features (a sensor range, or another closest-approach setting).
    """
    policy, cfg = load_policy(spec.student)
    collected = FeatureConfig(cfg.use_predictions, closest_approach=spec.closest_approach and cfg.use_predictions)
    if cfg != collected:
        raise DemoFileError(f"{spec.student}: the student reads {cfg}, but the demonstrations hold {collected}")
    return policy, cfg


def save(demos: Demos, spec: DemoSpec, path: str | Path) -> None:
    """Write the demonstrations and their spec atomically (.npz)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as file:
        np.savez_compressed(file, spec=strict_json.dumps({"format": FORMAT, **asdict(spec)}),
                            **{name: getattr(demos, name) for name in ARRAYS}, wall_time_s=demos.wall_time_s)


def load_or_collect(spec: DemoSpec, path: str | Path, progress: bool = True) -> Demos:
    """The demonstrations in ``path`` if they were collected with ``spec``; otherwise collect and write them.

    Raises:
        DemoFileError: ``path`` exists but is unreadable or holds another spec.
    """
    path = Path(path)
    if not path.exists():
        demos = collect(spec, progress)
        save(demos, spec, path)
        return demos
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = json.loads(str(data["spec"]))
            demos = Demos(*(data[name] for name in ARRAYS), wall_time_s=float(data["wall_time_s"]))
    except Exception as err:  # zip, key and JSON errors of a damaged or foreign file
        raise DemoFileError(f"{path}: not a readable demonstrations file: {err}") from err
    stored = {**asdict(DemoSpec()), **stored}  # a field added since the file was written has its default there
    if stored != {"format": FORMAT, **asdict(spec)}:
        raise DemoFileError(f"{path}: collected with {stored}, not {asdict(spec)}; remove it or pass another path")
    return demos


def behaviour_clone(policy: Any, demos: Demos, use_predictions: bool, gamma: float, epochs: int = 30,
                    batch_size: int = 256, learning_rate: float = 1e-3, seed: int = 0) -> dict[str, float]:
    """Fit a stable-baselines3 actor-critic's mean action to the teacher and its value to the teacher's returns.

    Returns the final mean squared errors {"action_mse", "value_mse"} on the demonstrations.
    """
    import torch

    features = torch.as_tensor(demos.features(use_predictions))
    actions = torch.as_tensor(demos.actions)
    returns = torch.as_tensor(demos.returns(gamma))[:, None]
    optimiser = torch.optim.Adam(policy.parameters(), lr=learning_rate)
    generator = torch.Generator().manual_seed(seed)
    for _ in range(epochs):
        for batch in torch.randperm(len(features), generator=generator).split(batch_size):
            mean = policy.get_distribution(features[batch]).distribution.mean
            values = policy.predict_values(features[batch])
            loss = ((mean - actions[batch]) ** 2).sum(dim=1).mean() + 0.1 * ((values - returns[batch]) ** 2).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    with torch.no_grad():
        mean = policy.get_distribution(features).distribution.mean
        return {"action_mse": float(((mean - actions) ** 2).sum(dim=1).mean()),
                "value_mse": float(((policy.predict_values(features) - returns) ** 2).mean())}
