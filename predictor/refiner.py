"""Conditional denoising diffusion over the S x K anchor residual (all prototypes refined jointly).

The network sees (noisy residual x_m, step m, conditions) and predicts, by the ``sampler`` setting, either the
clean residual x0 ("x0-cosine": cosine noise schedule) or the noise epsilon ("eps-linear": the authors' linear
beta schedule, beta from 1e-4 to 5e-2 over the M steps); the other one follows from it, so one network serves
both training objectives:
  * ``eps``: the paper's epsilon-prediction MSE at a random diffusion step;
  * ``e2e``: unroll the M-step DDIM chain and minimise best-of-S ADE of the final paths.
Conditions: the agent's history features, its anchors, and interaction through transformer layers whose
attention is restricted to agents of the same window (scene moment).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import torch
from torch import nn
from torch.nn import functional

SAMPLERS = ("x0-cosine", "eps-linear")  # what the network predicts, and the noise schedule it is paired with
LINEAR_BETAS = (1e-4, 5e-2)  # first and last beta of the "eps-linear" schedule (the authors' values)


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
    """start the denoiser's output layer at zero: the untrained "x0-cosine" refiner returns the anchors, the
    untrained "eps-linear" one the anchors plus its starting noise x_M / sqrt(alpha_bar_M)"""
    sampler: str = "x0-cosine"
    """"x0-cosine": the network predicts x0, cosine schedule; "eps-linear": it predicts epsilon, linear betas
    (``LINEAR_BETAS``); both sample by deterministic DDIM (eta = 0)"""


def cosine_alpha_bar(steps: int) -> torch.Tensor:
    """(steps + 1,) cumulative signal level, 1 at m = 0 falling to ~0 at m = steps (cosine schedule)."""
    m = torch.arange(steps + 1, dtype=torch.float64) / steps
    f = torch.cos((m + 0.008) / 1.008 * math.pi / 2) ** 2
    return (f / f[0]).clamp(min=1e-4).float()


def linear_alpha_bar(steps: int) -> torch.Tensor:
    """(steps + 1,) cumulative signal level of linearly spaced betas: 1 at m = 0, prod_{j <= m} (1 - beta_j).

    With ``LINEAR_BETAS`` and 10 steps the last level is about 0.78: x_M keeps most of the signal.
    """
    betas = torch.linspace(*LINEAR_BETAS, steps, dtype=torch.float64)
    return torch.cat([torch.ones(1, dtype=torch.float64), torch.cumprod(1 - betas, 0)]).float()


def _rank_within(window: torch.Tensor, sizes: torch.Tensor) -> torch.Tensor:
    """(B,) the place of each of B items among the items of its window (in order), for window ids (B,) in
    [0, W) and the windows' sizes (W,)."""
    order = torch.argsort(window, stable=True)
    rank = torch.empty_like(window)
    rank[order] = torch.arange(len(window), device=window.device) - \
        torch.repeat_interleave(torch.cumsum(sizes, 0) - sizes, sizes)
    return rank


def step_embedding(m: torch.Tensor, dim: int) -> torch.Tensor:
    """(B,) integer steps -> (B, dim) sinusoidal embedding."""
    half = dim // 2
    freqs = torch.exp(-math.log(1000.0) * torch.arange(half, dtype=torch.float32) / half)
    angles = m.float()[:, None] * freqs[None]
    return torch.cat([angles.sin(), angles.cos()], dim=-1)


class Refiner(nn.Module):
    """Context encoder (history + interaction) and a denoiser over S x K residuals (x0 or epsilon output)."""

    def __init__(self, cfg: RefinerConfig):
        super().__init__()
        if cfg.sampler not in SAMPLERS:
            raise ValueError(f"RefinerConfig.sampler={cfg.sampler!r}: must be one of {', '.join(SAMPLERS)}")
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
        if cfg.zero_start:  # the untrained network outputs zero (x0 = 0 or epsilon = 0: see RefinerConfig.zero_start)
            nn.init.zeros_(self.denoise[-1].weight)
            nn.init.zeros_(self.denoise[-1].bias)
        alpha_bar = cosine_alpha_bar(cfg.steps) if cfg.sampler == "x0-cosine" else linear_alpha_bar(cfg.steps)
        self.register_buffer("alpha_bar", alpha_bar, persistent=False)
        self.register_buffer("step_table", step_embedding(torch.arange(cfg.steps + 1), d), persistent=False)

    def context(self, history: torch.Tensor, anchors: torch.Tensor, group: torch.Tensor,
                targets: torch.Tensor | None = None) -> torch.Tensor:
        """Per-agent condition (B, dim) from history (B, F), anchors (B, S, K) and window ids (B,); with ``targets``
        (B,) bool, the condition of those agents only (T, dim).

        Each agent attends only to the agents of its own window. The layers' projections and feed-forward run on
        the B agents; only the attention itself sees windows padded to the longest (W, longest, dim), which is
        about four times B in a shuffled training batch. Same weights and result as ``self.interact`` with the
        other windows masked out. With ``targets``, the last layer runs its queries, attention output and
        feed-forward for the targets alone: the other agents only lend their keys and values, as they would anyway.
        """
        tokens = self.encode_history(torch.cat([history, anchors.flatten(1)], dim=1))
        _, window, sizes = torch.unique(group, return_inverse=True, return_counts=True)
        longest = int(sizes.max())
        keys = torch.arange(longest, device=group.device) < sizes[:, None]  # (W, longest) True = an agent
        cell = window * longest + _rank_within(window, sizes)  # (B,) each agent's place in the padded grid
        layers = list(self.interact.layers)
        for layer in layers[:-1]:
            tokens = self._window_layer(layer, tokens, cell, keys)
        return self._window_layer(layers[-1], tokens, cell, keys, targets)

    def _window_layer(self, layer: nn.TransformerEncoderLayer, x: torch.Tensor, cell: torch.Tensor,
                      keys: torch.Tensor, queries: torch.Tensor | None = None) -> torch.Tensor:
        """One pre-norm encoder layer on tokens x (B, dim), agent i at ``cell[i]`` of the flattened (W, longest)
        grid of windows ``keys``; the new tokens of the agents ``queries`` (B,) bool (None: all)."""
        attention = layer.self_attn
        heads, dim = attention.num_heads, x.shape[1]
        weight, bias = attention.in_proj_weight, attention.in_proj_bias
        normed = layer.norm1(x)
        if queries is None:
            qkv = functional.linear(normed, weight, bias)
            grid = qkv.new_zeros(keys.numel(), 3 * dim).index_copy(0, cell, qkv)
            q, k, v = grid.view(*keys.shape, 3, heads, dim // heads).permute(2, 0, 3, 1, 4)  # (W, heads, longest, .)
            queries, asked, width = slice(None), cell, keys.shape[1]
        else:
            kv = functional.linear(normed, weight[dim:], bias[dim:])  # every agent lends its key and value
            grid = kv.new_zeros(keys.numel(), 2 * dim).index_copy(0, cell, kv)
            k, v = grid.view(*keys.shape, 2, heads, dim // heads).permute(2, 0, 3, 1, 4)
            window = torch.div(cell[queries], keys.shape[1], rounding_mode="floor")  # (T,) the targets' windows
            counts = torch.bincount(window, minlength=len(keys))
            width = max(int(counts.max()), 1)  # every window has an agent, so counts is never empty
            asked = window * width + _rank_within(window, counts)
            q = functional.linear(normed[queries], weight[:dim], bias[:dim])
            q = q.new_zeros(len(keys) * width, dim).index_copy(0, asked, q)
            q = q.view(len(keys), width, heads, dim // heads).transpose(1, 2)  # (W, heads, width, .)
        mixed = functional.scaled_dot_product_attention(q, k, v, attn_mask=keys[:, None, None, :],
                                                        dropout_p=attention.dropout if self.training else 0.0)
        mixed = mixed.transpose(1, 2).reshape(len(keys) * width, dim).index_select(0, asked)  # (T, dim)
        x = x[queries] + layer.dropout1(attention.out_proj(mixed))
        return x + layer.dropout2(layer.linear2(layer.dropout(layer.activation(layer.linear1(layer.norm2(x))))))

    def predict_x0(self, x_m: torch.Tensor, m: torch.Tensor, anchors: torch.Tensor, ctx: torch.Tensor) -> torch.Tensor:
        """Clean residual (B, S, K) from noisy residual x_m (B, S, K) at steps m (B,)."""
        out = self._denoise(x_m, self._step_invariant(anchors, ctx) + self.embed_step(self.step_table[m]))
        return self._x0_eps(x_m, out, self.alpha_bar[m][:, None, None])[0]

    def _step_invariant(self, anchors: torch.Tensor, ctx: torch.Tensor) -> torch.Tensor:
        """(B, denoiser_dim): the anchors' share of the residual embedding plus the context (same at every step)."""
        sk = anchors[0].numel()
        weight, bias = self.embed_residual.weight, self.embed_residual.bias
        return functional.linear(anchors.flatten(1), weight[:, sk:], bias) + self.embed_context(ctx)

    def _denoise(self, x_m: torch.Tensor, condition: torch.Tensor) -> torch.Tensor:
        """The network's output (x0 or epsilon, by ``sampler``) from x_m (B, S, K) and the summed conditions."""
        weight = self.embed_residual.weight[:, :x_m[0].numel()]
        return self.denoise(functional.linear(x_m.flatten(1), weight) + condition).view_as(x_m)

    def _x0_eps(self, x_m: torch.Tensor, out: torch.Tensor, a: torch.Tensor | float
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """(x0, epsilon) from the network's output at signal level a, with x_m = sqrt(a) x0 + sqrt(1 - a) eps."""
        a = torch.as_tensor(a)
        if self.cfg.sampler == "x0-cosine":
            return out, (x_m - a.sqrt() * out) / (1 - a).sqrt()
        return (x_m - (1 - a).sqrt() * out) / a.sqrt(), out

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
            x0, eps = self._x0_eps(x, self._denoise(x, invariant + step_bias[m]), alpha_bar[m])
            if m_next == 0:
                return x0
            x = math.sqrt(alpha_bar[m_next]) * x0 + math.sqrt(1 - alpha_bar[m_next]) * eps
        return x

    def eps_loss(self, x0: torch.Tensor, anchors: torch.Tensor, ctx: torch.Tensor, generator: torch.Generator
                 ) -> torch.Tensor:
        """Epsilon-prediction MSE at a random step for clean residuals x0 (B, S, K)."""
        m = torch.randint(1, self.cfg.steps + 1, (len(x0),), generator=generator).to(x0.device)
        noise = torch.randn(x0.shape, generator=generator).to(x0.device)
        a = self.alpha_bar[m][:, None, None]
        x_m = a.sqrt() * x0 + (1 - a).sqrt() * noise
        out = self._denoise(x_m, self._step_invariant(anchors, ctx) + self.embed_step(self.step_table[m]))
        return (self._x0_eps(x_m, out, a)[1] - noise).pow(2).mean()
