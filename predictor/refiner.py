"""Conditional denoising diffusion over the S x K anchor residual (all prototypes refined jointly).

The network predicts the clean residual x0 from (noisy residual x_m, step m, conditions); epsilon
follows from x0, so one network serves both training objectives:
  * ``eps``: the paper's epsilon-prediction MSE at a random diffusion step;
  * ``e2e``: unroll the M-step DDIM chain and minimise best-of-S ADE of the final paths.
Conditions: the agent's history features, its anchors, and interaction through one transformer layer
whose attention is masked to agents of the same window (scene moment).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class RefinerConfig:
    history_dim: int
    """features per agent describing its history (agent frame)"""
    num_samples: int = 20
    """S, anchors refined jointly"""
    k: int = 4
    """Singular-space dimension"""
    dim: int = 256
    """width of the context transformer"""
    denoiser_dim: int = 128
    """width of the denoiser MLP (run M times per prediction, so it dominates inference time)"""
    heads: int = 4
    """attention heads of the interaction layer"""
    layers: int = 1
    """interaction transformer layers"""
    dropout: float = 0.0
    """dropout in the interaction layers while training"""
    steps: int = 10
    """M, DDIM denoising steps"""
    zero_start: bool = True
    """start the denoiser's output layer at zero, so the untrained refiner returns the anchors"""


def cosine_alpha_bar(steps: int) -> torch.Tensor:
    """(steps + 1,) cumulative signal level, 1 at m = 0 falling to ~0 at m = steps (cosine schedule)."""
    m = torch.arange(steps + 1, dtype=torch.float64) / steps
    f = torch.cos((m + 0.008) / 1.008 * math.pi / 2) ** 2
    return (f / f[0]).clamp(min=1e-4).float()


def step_embedding(m: torch.Tensor, dim: int) -> torch.Tensor:
    """(B,) integer steps -> (B, dim) sinusoidal embedding."""
    half = dim // 2
    freqs = torch.exp(-math.log(1000.0) * torch.arange(half, dtype=torch.float32) / half)
    angles = m.float()[:, None] * freqs[None]
    return torch.cat([angles.sin(), angles.cos()], dim=-1)


class Refiner(nn.Module):
    """Context encoder (history + interaction) and an x0-predicting denoiser over S x K residuals."""

    def __init__(self, cfg: RefinerConfig):
        super().__init__()
        self.cfg = cfg
        d, h, sk = cfg.dim, cfg.denoiser_dim, cfg.num_samples * cfg.k
        self.encode_history = nn.Sequential(nn.Linear(cfg.history_dim + sk, d), nn.SiLU(), nn.Linear(d, d))
        layer = nn.TransformerEncoderLayer(d, cfg.heads, dim_feedforward=2 * d, dropout=cfg.dropout, batch_first=True,
                                           norm_first=True)
        self.interact = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.embed_context = nn.Linear(d, h, bias=False)
        self.embed_residual = nn.Linear(2 * sk, h)
        self.embed_step = nn.Linear(d, h)
        self.denoise = nn.Sequential(nn.SiLU(), nn.Linear(h, h), nn.SiLU(), nn.Linear(h, h), nn.SiLU(),
                                     nn.Linear(h, sk))
        if cfg.zero_start:  # the untrained refiner predicts a zero residual: the futures are the anchors
            nn.init.zeros_(self.denoise[-1].weight)
            nn.init.zeros_(self.denoise[-1].bias)
        self.register_buffer("alpha_bar", cosine_alpha_bar(cfg.steps), persistent=False)
        self.register_buffer("step_table", step_embedding(torch.arange(cfg.steps + 1), d), persistent=False)

    def context(self, history: torch.Tensor, anchors: torch.Tensor, group: torch.Tensor) -> torch.Tensor:
        """Per-agent condition (B, dim) from history (B, F), anchors (B, S, K) and window ids (B,)."""
        tokens = self.encode_history(torch.cat([history, anchors.flatten(1)], dim=1))
        _, window, sizes = torch.unique(group, return_inverse=True, return_counts=True)
        if len(sizes) <= 1:  # one window: everyone attends to everyone
            return self.interact(tokens[None])[0]
        # one padded row per window (W, longest, dim): attention within each window, not over a masked (B, B)
        order = torch.argsort(window, stable=True)
        slot = torch.arange(len(group)) - torch.repeat_interleave(torch.cumsum(sizes, 0) - sizes, sizes)
        rows = tokens.new_zeros(len(sizes), int(sizes.max()), tokens.shape[1])
        rows = rows.index_put((window[order], slot), tokens[order])
        padding = torch.arange(rows.shape[1]) >= sizes[:, None]  # (W, longest) True = no agent
        out = torch.empty_like(tokens)
        out[order] = self.interact(rows, src_key_padding_mask=padding)[window[order], slot]
        return out

    def predict_x0(self, x_m: torch.Tensor, m: torch.Tensor, anchors: torch.Tensor, ctx: torch.Tensor) -> torch.Tensor:
        """Clean residual (B, S, K) from noisy residual x_m (B, S, K) at steps m (B,)."""
        return self._denoise(x_m, self._step_invariant(anchors, ctx) + self.embed_step(self.step_table[m]))

    def _step_invariant(self, anchors: torch.Tensor, ctx: torch.Tensor) -> torch.Tensor:
        """(B, denoiser_dim): the anchors' share of the residual embedding plus the context (same at every step)."""
        sk = anchors[0].numel()
        weight, bias = self.embed_residual.weight, self.embed_residual.bias
        return torch.nn.functional.linear(anchors.flatten(1), weight[:, sk:], bias) + self.embed_context(ctx)

    def _denoise(self, x_m: torch.Tensor, condition: torch.Tensor) -> torch.Tensor:
        """Clean residual from x_m (B, S, K) and the summed conditions (B or 1, dim)."""
        weight = self.embed_residual.weight[:, :x_m[0].numel()]
        return self.denoise(torch.nn.functional.linear(x_m.flatten(1), weight) + condition).view_as(x_m)

    def sample(self, anchors: torch.Tensor, ctx: torch.Tensor, noise: torch.Tensor, steps: int | None = None
               ) -> torch.Tensor:
        """Deterministic DDIM (eta = 0) from x_M = noise (B, S, K) to the clean residual (B, S, K).

        ``steps`` < M skips evenly through the schedule (M in {1, 5, 10} ablation).
        """
        total = self.cfg.steps
        schedule = torch.linspace(total, 0, (steps or total) + 1).round().long().tolist()
        alpha_bar = self.alpha_bar.tolist()
        x = noise
        invariant = self._step_invariant(anchors, ctx)  # computed once for all M steps
        step_bias = self.embed_step(self.step_table)  # (M + 1, denoiser_dim), one row per step, shared by all agents
        for m, m_next in itertools.pairwise(schedule):
            x0 = self._denoise(x, invariant + step_bias[m])
            if m_next == 0:
                return x0
            # x_next = sqrt(a_next) x0 + sqrt(1 - a_next) eps, with eps = (x - sqrt(a) x0) / sqrt(1 - a)
            a, a_next = alpha_bar[m], alpha_bar[m_next]
            keep = math.sqrt((1 - a_next) / (1 - a))
            x = (math.sqrt(a_next) - keep * math.sqrt(a)) * x0 + keep * x
        return x

    def eps_loss(self, x0: torch.Tensor, anchors: torch.Tensor, ctx: torch.Tensor, generator: torch.Generator
                 ) -> torch.Tensor:
        """Epsilon-prediction MSE at a random step for clean residuals x0 (B, S, K)."""
        m = torch.randint(1, self.cfg.steps + 1, (len(x0),), generator=generator)
        noise = torch.randn(x0.shape, generator=generator)
        a = self.alpha_bar[m][:, None, None]
        x_m = a.sqrt() * x0 + (1 - a).sqrt() * noise
        eps = (x_m - a.sqrt() * self.predict_x0(x_m, m, anchors, ctx)) / (1 - a).sqrt()
        return (eps - noise).pow(2).mean()
