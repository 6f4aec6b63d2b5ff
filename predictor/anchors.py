"""Anchors: prototype paths (k-means in Singular space) and their adaptation to a scene's walkable map.

Adaptation: each prototype path is placed at the agent (world frame); where its end point falls on a
non-walkable pixel, the path is bent about the agent's last observed point (offset growing linearly
with time) so the end lands on the nearest walkable pixel. The nearest-walkable-pixel field comes
from one Euclidean distance transform per map, cached. Everything is vectorised over agents x prototypes.
"""

from __future__ import annotations

import weakref

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.ndimage import distance_transform_edt

from predictor.normalize import AgentFrame
from predictor.singular_space import T_WIN, SingularSpace
from replays.scenes import Scene

RAMP = np.arange(1, T_WIN + 1) / T_WIN  # (12,) share of the end-point correction applied at each step


def prototype_anchors(coefficients: np.ndarray, num_anchors: int, seed: int = 0) -> np.ndarray:
    """k-means++ centroids of (L, K) training coefficients -> (S, K), largest cluster first; S = 1 gives the mean."""
    if num_anchors == 1:
        return coefficients.mean(axis=0, keepdims=True)
    if len(coefficients) < num_anchors:
        raise ValueError(f"need at least {num_anchors} training paths for {num_anchors} anchors, "
                         f"got {len(coefficients)}")
    centroids, labels = kmeans2(coefficients.astype(np.float64), num_anchors, iter=50, minit="++",
                                seed=np.random.default_rng(seed))
    sizes = np.bincount(labels, minlength=num_anchors)
    return centroids[np.argsort(-sizes, kind="stable")]


_FIELDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def nearest_walkable_field(scene: Scene) -> np.ndarray:
    """(2, H, W) int row and column of the nearest walkable pixel for every pixel (cached per scene)."""
    if scene not in _FIELDS:
        if not scene.walkable.any():
            raise ValueError(f"{scene}: walkability map has no walkable pixel")
        _, indices = distance_transform_edt(~scene.walkable, return_indices=True)
        _FIELDS[scene] = indices
    return _FIELDS[scene]


def adapt_paths(paths_m: np.ndarray, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Bend world paths whose end point is on a non-walkable pixel of ``scene``.

    Args:
        paths_m: (N, S, 12, 2) world metres; step 0 is the first future step.

    Returns:
        adapted: (N, S, 12, 2) world metres.  moved: (N, S) bool, paths that were bent.
    """
    end_m = paths_m[:, :, -1]
    uv = np.rint(scene.world_to_pixel(end_m))
    height, width = scene.walkable.shape
    inside = (uv[..., 0] >= 0) & (uv[..., 0] < width) & (uv[..., 1] >= 0) & (uv[..., 1] < height)
    u = np.where(inside, uv[..., 0], 0).astype(np.intp)
    v = np.where(inside, uv[..., 1], 0).astype(np.intp)
    moved = inside & ~scene.walkable[v, u]  # off-image end points are left alone (agents may leave view)
    field = nearest_walkable_field(scene)
    target_uv = np.stack([field[1, v, u], field[0, v, u]], axis=-1).astype(np.float64)
    target_m = scene.pixel_to_world(target_uv)
    shift = np.where(moved[..., None], target_m - end_m, 0.0)  # (N, S, 2)
    return paths_m + RAMP[:, None] * shift[:, :, None, :], moved


def adaptive_anchors(anchors: np.ndarray, frames: AgentFrame, space_of: list[SingularSpace],
                     population: np.ndarray, scene: Scene | None) -> tuple[np.ndarray, np.ndarray]:
    """Per-agent anchors adapted to the map, as coefficients and world paths.

    Args:
        anchors: (P, S, K) prototype coefficients per population (0 = moving, 1 = slow).
        frames: agent frames of the N agents.
        space_of: Singular space per population.
        population: (N,) int population index.
        scene: map to adapt to, or None (prototypes unchanged).

    Returns:
        coefficients: (N, S, K) adapted anchors.  paths_m: (N, S, 12, 2) prototype paths in world metres
        (before adaptation) stacked with the adapted ones: shape (2, N, S, 12, 2).
    """
    n, s, k = len(population), anchors.shape[1], anchors.shape[2]
    local = np.zeros((n, s, T_WIN, 2))
    for p, space in enumerate(space_of):
        mask = population == p
        local[mask] = space.reconstruct(anchors[p])[None]
    proto_m = frames.to_world(local)
    if scene is None:
        coefs = np.empty((n, s, k))
        for p in range(len(space_of)):
            coefs[population == p] = anchors[p]
        return coefs, np.stack([proto_m, proto_m])
    adapted_m, _ = adapt_paths(proto_m, scene)
    adapted_local = frames.to_agent(adapted_m)
    coefs = np.empty((n, s, k))
    for p, space in enumerate(space_of):
        mask = population == p
        coefs[mask] = space.project(adapted_local[mask].reshape(-1, T_WIN, 2)).reshape(-1, s, k)
    return coefs, np.stack([proto_m, adapted_m])
