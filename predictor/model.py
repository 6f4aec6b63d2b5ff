"""The SingularTrajectory predictor: agent frames + Singular space + adaptive anchors + diffusion refiner.

Populations: index 0 = moving agents (speed-normalised), 1 = slow agents (see ``predictor.normalize``);
each has its own Singular space, prototype anchors and coefficient scales. Single-sample models leave
agents that stand (last step under ``SINGLE_SAMPLE_STAND_SPEED_M``) at constant velocity: one path cannot
hedge between staying and leaving, and staying is the better bet (chosen on the validation splits).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np
import torch

from predictor.anchors import BEND_SHAPES, OFF_IMAGE_MODES, adapt_paths, adaptive_anchors, anchor_paths, onto_walkable
from predictor.baselines import constant_velocity
from predictor.config_check import check_config
from predictor.devices import resolve_device
from predictor.normalize import AgentFrame, agent_frames, rotate
from predictor.protocol import check_inputs, empty_prediction, scenes_of_agents
from predictor.refiner import SAMPLERS, Refiner, RefinerConfig
from predictor.singular_space import T_WIN, SingularSpace
from replays.constants import TASKS
from replays.scenes import Scene

BATCH_AGENTS = 4096  # agents per call of the refiner's interaction layer at inference (whole windows; bounds memory)
SINGLE_SAMPLE_STAND_SPEED_M = 0.05  # S = 1: slower agents keep constant velocity [m per 0.4 s step]


@dataclass(frozen=True)
class ModelConfig:
    task: str = "stochastic"
    """benchmark task the model is trained for"""
    obs_len: int = 8
    """observed steps T_obs (8, or 2 for momentary)"""
    num_samples: int = 20
    """S, prototype anchors = predicted futures per agent"""
    k: int = 4
    """Singular-space dimension K"""
    scale_by_speed: bool = True
    """normalise moving agents' paths by their recent speed"""
    world_features: bool = True
    """feed world-frame offset from the window centroid and velocity (False = agent-frame inputs only)"""
    slow_speed_m: float = 0.3
    """agents slower than this [m per 0.4 s step] form the slow population (own space and anchors)"""
    slow_scale_floor_m: float = 0.0
    """0: slow agents are not scaled; > 0: scaled by max(speed, this) [m per step]"""
    adapt_anchors: bool = True
    """bend prototype paths onto walkable pixels (False = fixed prototype anchors)"""
    anchor_off_image: str = "pull"
    """prototype end points off the scene image: "pull" them onto the nearest walkable pixel, or "keep" them"""
    anchor_bend: str = "ramp"
    """how a path is bent onto its target end point: "ramp" (linear offset) or "scale" (per image axis)"""
    adapt_output: bool = True
    """bend the refined futures onto the map the same way at inference (end points on walkable pixels)"""
    output_on_map: bool = True
    """at inference, after the bending, move every predicted point that is still more than on_map_tolerance_m off
    the walkable map onto its nearest walkable pixel (the bending moves whole paths by their end points; the
    refiner's residual can leave single points in a wall)"""
    on_map_tolerance_m: float = 0.1
    """predicted points this close to walkable ground stay where they are (annotated people walk there too) [m],
    [0, 10]"""
    dim: int = 256
    """width of the refiner's context transformer"""
    denoiser_dim: int = 128
    """width of the refiner's denoiser MLP"""
    heads: int = 4
    """attention heads"""
    layers: int = 1
    """interaction transformer layers"""
    dropout: float = 0.0
    """dropout in the interaction layers while training, [0, 0.9]"""
    steps: int = 10
    """M, DDIM steps"""
    sampler: str = "x0-cosine"
    """the refiner's diffusion: "x0-cosine" (the network predicts the clean residual, cosine schedule) or
    "eps-linear" (it predicts the noise, the authors' linear betas from 1e-4 to 5e-2); DDIM with eta = 0"""
    init_noise: float = 1.0
    """scale of the starting noise x_M of the sampler"""
    noise_seed: int = 0
    """seed of the sampler's fixed starting noise: the training run's seed, so inference draws the noise its
    validation saw (checkpoints written before this field drew seed 0)"""
    zero_start: bool = True
    """the refiner's output layer starts at zero (untrained refiner = anchors)"""
    stand_speed_m: float | None = None
    """at inference, agents whose last observed step is shorter than this [m per 0.4 s step] keep their constant
    velocity (people standing stay put); None: 0.05 for single-sample models, 0 (off) otherwise"""

    def __post_init__(self) -> None:
        check_config(self, {"obs_len": (2, 64), "num_samples": (1, 1000), "k": (1, 24), "slow_speed_m": (0.0, 10.0),
                            "stand_speed_m": (0.0, 10.0),
                            "slow_scale_floor_m": (0.0, 10.0), "dim": (4, 4096), "denoiser_dim": (4, 4096),
                            "heads": (1, 64), "layers": (1, 16), "dropout": (0.0, 0.9), "steps": (1, 1000),
                            "init_noise": (0.0, 100.0),
                            "noise_seed": (0, 2**31 - 1), "on_map_tolerance_m": (0.0, 10.0)},
                     choices={"task": tuple(TASKS), "anchor_off_image": OFF_IMAGE_MODES, "anchor_bend": BEND_SHAPES,
                              "sampler": SAMPLERS})
        if self.dim % self.heads:
            raise ValueError(f"ModelConfig.dim={self.dim}, ModelConfig.heads={self.heads}: dim must be a multiple "
                             "of heads")

    def refiner_config(self) -> RefinerConfig:
        """The refiner's architecture for this model."""
        shared = {f.name: getattr(self, f.name) for f in fields(RefinerConfig) if f.name != "history_dim"}
        return RefinerConfig(history_dim=self.history_dim, **shared)

    @property
    def standing_m(self) -> float:
        """The effective ``stand_speed_m`` [m per step] (0 = every agent goes through the refiner)."""
        if self.stand_speed_m is not None:
            return self.stand_speed_m
        return SINGLE_SAMPLE_STAND_SPEED_M if self.num_samples == 1 else 0.0

    @property
    def history_dim(self) -> int:
        return 2 * self.obs_len + self.k + 8  # history, its coefficients, log speed, slow flag, 6 interaction


@dataclass
class Prediction:
    """Predicted futures with the anchors they were refined from; all (N, S, 12, 2) world metres (the anchors None
    when not asked for)."""

    futures: np.ndarray
    prototype_anchors: np.ndarray | None
    adapted_anchors: np.ndarray | None


@dataclass
class Inputs:
    """Model inputs of N agents (agent frame unless noted)."""

    frames: AgentFrame
    population: np.ndarray  # (N,) int
    history: np.ndarray  # (N, F) float32 features
    anchors: np.ndarray  # (N, S, K) adapted anchor coefficients
    group: np.ndarray  # (N,) int64


class SingularTrajectory:
    """Predictor object; ``predict`` has the same signature as the baselines'."""

    name = "singular"

    def __init__(self, cfg: ModelConfig, spaces: list[SingularSpace], anchors: np.ndarray,
                 coef_scale: np.ndarray, residual_scale: np.ndarray, refiner: Refiner):
        self.cfg = cfg
        self.spaces = spaces
        self.anchors = anchors  # (2, S, K) prototype coefficients per population
        self.coef_scale = coef_scale  # (2,) typical coefficient size per population
        self.residual_scale = residual_scale  # (2,) typical anchor-to-truth residual per population
        self.refiner = refiner.eval()
        self.source: str | None = None  # the checkpoint it was loaded from (set by predictor.checkpoint)
        self.bases = torch.tensor(np.stack([s.basis for s in spaces]), dtype=torch.float32)  # (2, 24, K)
        self.device = torch.device("cpu")
        self._noise: torch.Tensor | None = None

    def to(self, device: str | torch.device) -> SingularTrajectory:
        """Run the refiner on ``device`` (a name as ``predictor.devices.resolve_device`` takes; "auto": a GPU when
        torch sees one); inputs and outputs stay NumPy on the CPU. Returns self."""
        self.device = resolve_device(device)
        self.refiner.to(self.device)
        self.bases = self.bases.to(self.device)
        self._noise = None
        return self

    # ---------------------------------------------------------------- inputs
    def prepare(self, obs: np.ndarray, group: np.ndarray, scenes: list[Scene | None],
                scene_index: np.ndarray) -> Inputs:
        """Features for N agents; agent i lies on ``scenes[scene_index[i]]``."""
        frames = agent_frames(obs, self.cfg.scale_by_speed, self.cfg.slow_speed_m, self.cfg.slow_scale_floor_m)
        population = frames.slow.astype(np.int64)
        history_local = frames.to_agent(obs.astype(np.float64))  # (N, T_obs, 2)
        history_coef = np.zeros((len(obs), self.cfg.k))
        for p, space in enumerate(self.spaces):
            mask = population == p
            history_coef[mask] = space.project(history_local[mask] - history_local[mask][:, :1])
        anchors = np.zeros((len(obs), self.cfg.num_samples, self.cfg.k))
        for i, scene in enumerate(scenes):
            mask = scene_index == i
            anchors[mask] = adaptive_anchors(self.anchors, frames.subset(mask), self.spaces, population[mask],
                                             scene if self.cfg.adapt_anchors else None, self.cfg.anchor_off_image,
                                             self.cfg.anchor_bend)
        n = len(obs)
        history = np.concatenate([
            history_local.reshape(n, -1), history_coef / self.coef_scale[population][:, None],
            np.log(frames.scale_m)[:, None], frames.slow[:, None],
            _interaction_features(obs, group, frames, self.cfg.world_features),
        ], axis=1).astype(np.float32)
        return Inputs(frames, population, history, anchors, group)

    def tensors(self, inputs: Inputs) -> dict[str, torch.Tensor]:
        """Network-ready tensors: scaled anchors, history, group, population, speed scale."""
        pop = inputs.population
        return {
            "history": torch.from_numpy(inputs.history),
            "anchors": torch.from_numpy((inputs.anchors / self.coef_scale[pop][:, None, None]).astype(np.float32)),
            "group": torch.from_numpy(np.asarray(inputs.group, np.int64)),
            "population": torch.from_numpy(pop),
            "scale_m": torch.from_numpy(inputs.frames.scale_m.astype(np.float32)),
        }

    def paths_local(self, anchors_scaled: torch.Tensor, residual: torch.Tensor, population: torch.Tensor
                    ) -> torch.Tensor:
        """Agent-frame paths (B, S, 12, 2) from scaled anchors and refiner residuals (B, S, K)."""
        device = anchors_scaled.device
        coef_scale = torch.as_tensor(self.coef_scale, dtype=torch.float32, device=device)[population][:, None, None]
        res_scale = torch.as_tensor(self.residual_scale, dtype=torch.float32, device=device)[population][:, None, None]
        coefs = anchors_scaled * coef_scale + residual * res_scale
        flat = torch.einsum("bsk,bdk->bsd", coefs, self.bases[population])
        return flat.view(*coefs.shape[:2], T_WIN, 2)

    # ---------------------------------------------------------------- prediction
    @torch.inference_mode()
    def predict_detailed(self, obs: np.ndarray, group: np.ndarray, scene: Scene | Sequence[Scene | None] | None,
                         num_samples: int | None = None, steps: int | None = None, targets: np.ndarray | None = None,
                         anchors: bool = True) -> Prediction:
        """Futures, prototype and adapted anchors, each (T, S, 12, 2) world metres, of the T ``targets``.

        Args:
            obs: (N, T_obs, 2) world metres.  group: (N,) int64 scene moment of each agent.
            scene: the scene of every agent, or one per group value (group g's agents lie on ``scene[g]``: moments of
                several scenes in one call, each adapted to its own map).
            targets: (N,) bool, the agents to forecast; the others are context only: they shape the targets'
                forecasts (interaction layer, window centroid) exactly as if they were forecast too. None: all.
            anchors: also return the anchor paths (False: both None).
        """
        num_samples = num_samples or self.cfg.num_samples
        obs, group = check_inputs(obs, group, num_samples)
        if num_samples > self.cfg.num_samples:
            raise ValueError(f"model trained for S = {self.cfg.num_samples} samples, asked for {num_samples}")
        if obs.shape[1] != self.cfg.obs_len:
            raise ValueError(f"model observes {self.cfg.obs_len} steps, got obs of {obs.shape[1]}")
        targets = np.ones(len(obs), bool) if targets is None else np.asarray(targets, bool)
        if targets.shape != (len(obs),):
            raise ValueError(f"targets: expected a bool array of shape ({len(obs)},), got shape {targets.shape}")
        if not targets.any():
            empty = empty_prediction(num_samples)
            return Prediction(empty, empty if anchors else None, empty if anchors else None)
        scenes, scene_index = scenes_of_agents(scene, group)
        inputs = self.prepare(obs, group, scenes, scene_index)
        t = {name: tensor.to(self.device) for name, tensor in self.tensors(inputs).items()}
        noise = self.sampler_noise().expand_as(t["anchors"])
        if len(obs) <= BATCH_AGENTS:
            chunks = [torch.arange(len(obs), device=self.device)]
        else:
            order = torch.argsort(t["group"], stable=True)  # windows contiguous, so chunks keep them whole
            chunks = [order[chunk] for chunk in window_batches(t["group"][order], BATCH_AGENTS, None)]
        wanted = torch.from_numpy(targets).to(self.device)
        ctx = torch.empty(len(obs), self.refiner.cfg.dim, device=self.device)
        for idx in chunks:  # the interaction layer within whole windows; then every target denoised in one batch
            ctx[idx[wanted[idx]]] = self.refiner.context(t["history"][idx], t["anchors"][idx], t["group"][idx],
                                                         wanted[idx])
        anchors_scaled = t["anchors"][wanted]
        residual = self.refiner.sample(anchors_scaled, ctx[wanted], noise[wanted], steps)
        local = self.paths_local(anchors_scaled, residual, t["population"][wanted])
        frames = inputs.frames.subset(targets)
        futures = frames.to_world(local.double().cpu().numpy())  # (T, S, 12, 2) world metres
        on_scene = [(where, scene) for where, scene in self._targets_by_scene(scenes, scene_index[targets])
                    if scene is not None]
        for where, scene in on_scene if self.cfg.adapt_output and self.cfg.adapt_anchors else ():
            futures[where], _ = adapt_paths(futures[where], scene, frames.origin_m[where], self.cfg.anchor_off_image,
                                            self.cfg.anchor_bend)
        for where, scene in on_scene if self.cfg.output_on_map else ():
            futures[where], _ = onto_walkable(futures[where], scene, self.cfg.on_map_tolerance_m)
        observed = obs[targets]
        standing = np.linalg.norm(observed[:, -1] - observed[:, -2], axis=-1) < self.cfg.standing_m
        futures[standing] = constant_velocity(observed[standing])[:, None]  # (n, 1, 12, 2) onto every sample
        keep = slice(0, num_samples)  # anchors are ordered by cluster size: the first are the likeliest
        futures = futures[:, keep].astype(np.float32)
        if not anchors:
            return Prediction(futures, None, None)
        parts = [(where, anchor_paths(self.anchors, frames.subset(where), self.spaces,
                                      inputs.population[targets][where], scene if self.cfg.adapt_anchors else None,
                                      self.cfg.anchor_off_image, self.cfg.anchor_bend))
                 for where, scene in self._targets_by_scene(scenes, scene_index[targets])]
        prototype, adapted = (np.empty((len(futures), *parts[0][1][k].shape[1:])) for k in (0, 1))
        for where, (prototype_part, adapted_part) in parts:
            prototype[where], adapted[where] = prototype_part, adapted_part
        return Prediction(futures, prototype[:, keep].astype(np.float32), adapted[:, keep].astype(np.float32))

    @staticmethod
    def _targets_by_scene(scenes: list[Scene | None], scene_index: np.ndarray
                          ) -> list[tuple[slice | np.ndarray, Scene | None]]:
        """(which targets, their scene) for each scene with targets: a whole slice when there is one scene."""
        if len(scenes) == 1:
            return [(slice(None), scenes[0])]
        return [(scene_index == i, scene) for i, scene in enumerate(scenes) if (scene_index == i).any()]

    def sampler_noise(self) -> torch.Tensor:
        """(1, S, K) starting noise x_M, one fixed draw per sample shared by every agent.

        Shared, so an agent's futures depend only on its own window, never on which other agents happen to
        be in the same call (the stream and the offline evaluation then agree exactly).
        """
        if self._noise is None:  # drawn on the CPU, so that every device starts from the same noise
            generator = torch.Generator().manual_seed(self.cfg.noise_seed)
            self._noise = (self.cfg.init_noise * torch.randn((1, self.cfg.num_samples, self.cfg.k),
                                                             generator=generator)).to(self.device)
        return self._noise

    def predict(self, obs: np.ndarray, group: np.ndarray, scene: Scene | None = None,
                num_samples: int | None = None) -> np.ndarray:
        """(N, T_obs, 2) world metres -> (N, S, 12, 2) float32 world metres."""
        return self.predict_detailed(obs, group, scene, num_samples).futures


def window_batches(group: torch.Tensor, batch_agents: int, generator: torch.Generator | None) -> list[torch.Tensor]:
    """Indices in batches of about ``batch_agents``, whole windows kept together (shuffled if generator).

    ``group`` (N,) must hold each window's samples contiguously.
    """
    device, group = group.device, group.cpu()
    ids, counts = torch.unique_consecutive(group, return_counts=True)
    starts = torch.cumsum(counts, 0) - counts
    order = torch.randperm(len(ids), generator=generator) if generator is not None else torch.arange(len(ids))
    out, current, size = [], [], 0
    for g in order.tolist():
        current.append(torch.arange(starts[g], starts[g] + counts[g]))
        size += int(counts[g])
        if size >= batch_agents:
            out.append(torch.cat(current))
            current, size = [], 0
    if current:
        out.append(torch.cat(current))
    return [batch.to(device) for batch in out]


def _interaction_features(obs: np.ndarray, group: np.ndarray, frames: AgentFrame, world: bool) -> np.ndarray:
    """(N, 6): position relative to the window's centroid (world, and agent frame) and world velocity.

    With ``world`` False the world-frame columns are zero (inputs invariant to the scene's orientation).
    """
    last = obs[:, -1].astype(np.float64)
    _, inverse, counts = np.unique(group, return_inverse=True, return_counts=True)
    sums = np.zeros((len(counts), 2))
    np.add.at(sums, inverse, last)
    offset = last - (sums / counts[:, None])[inverse]  # metres from the window centroid
    offset_local = rotate(offset, -frames.angle_rad)
    velocity = obs[:, -1] - obs[:, -2]
    if not world:
        offset, velocity = np.zeros_like(offset), np.zeros_like(velocity)
    return np.concatenate([offset, offset_local, velocity], axis=1)
