"""Anchors: prototype paths (k-means in Singular space) and their adaptation to a scene's walkable map.

Adaptation: each prototype path is placed at the agent (world frame). Where its end point is not on a
walkable pixel of the scene image, the path is bent so the end lands on the nearest walkable pixel.
End points that leave the image count as not walkable (``off_image="pull"``, the default): the
nearest-walkable-pixel field covers a canvas twice the image's size with the image in its centre, and end
points beyond that canvas are clamped to its edge, so such a prototype is pulled back inside the image.
``off_image="keep"`` leaves them alone (agents may leave view). Two bending shapes (``bend``):
``"ramp"`` adds the end-point correction linearly over time (world metres); ``"scale"`` stretches the
path about the agent's last observed point, per image axis, so its end lands on the target. The field
comes from one Euclidean distance transform per map, cached; everything is vectorised over agents x
prototypes.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.ndimage import distance_transform_edt

from predictor.normalize import AgentFrame, rotate
from predictor.singular_space import T_WIN, SingularSpace
from replays.scenes import Scene

RAMP = np.arange(1, T_WIN + 1) / T_WIN  # (12,) share of the end-point correction applied at each step
OFF_IMAGE_MODES = ("pull", "keep")
BEND_SHAPES = ("ramp", "scale")
MIN_AXIS_SPAN_PX = 1.0  # below this end-to-origin span on an image axis, "scale" bends that axis by a ramp


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


@functools.lru_cache(maxsize=8)
def nearest_walkable_field(scene: Scene) -> np.ndarray:
    """(2, 2H, 2W) int32 row and column (image pixels) of the nearest walkable pixel, over the padded canvas.

    The canvas is the (H, W) map centred in a non-walkable border of H/2 rows and W/2 columns on each
    side; canvas pixel (r, c) is image pixel (r - H//2, c - W//2). Cached for the last 8 scene objects
    (32 bytes per image pixel: 39 MB for a 1280 x 960 map); read-only.
    """
    if not scene.walkable.any():
        raise ValueError(f"{scene}: walkability map has no walkable pixel")
    height, width = scene.walkable.shape
    canvas = np.pad(scene.walkable, ((height // 2, height - height // 2), (width // 2, width - width // 2)))
    _, indices = distance_transform_edt(~canvas, return_indices=True)
    indices[0] -= height // 2
    indices[1] -= width // 2
    field = indices.astype(np.int32)
    field.flags.writeable = False
    return field


def _end_targets(end_px: np.ndarray, scene: Scene, off_image: str) -> tuple[np.ndarray, np.ndarray]:
    """Nearest walkable pixel (..., 2) for end points (..., 2) [px], and which end points must move (...)."""
    height, width = scene.walkable.shape
    uv = np.rint(np.nan_to_num(end_px, nan=-1.0, posinf=4.0 * width, neginf=-4.0 * width))
    inside = (uv[..., 0] >= 0) & (uv[..., 0] < width) & (uv[..., 1] >= 0) & (uv[..., 1] < height)
    u = np.clip(uv[..., 0] + width // 2, 0, 2 * width - 1).astype(np.intp)  # canvas column, clamped
    v = np.clip(uv[..., 1] + height // 2, 0, 2 * height - 1).astype(np.intp)
    field = nearest_walkable_field(scene)
    on_wall = inside & ~scene.walkable[np.where(inside, uv[..., 1], 0).astype(np.intp),
                                       np.where(inside, uv[..., 0], 0).astype(np.intp)]
    moved = on_wall | ~inside if off_image == "pull" else on_wall
    return np.stack([field[1, v, u], field[0, v, u]], axis=-1).astype(np.float64), moved


def adapt_paths(paths_m: np.ndarray, scene: Scene, origin_m: np.ndarray | None = None, off_image: str = "pull",
                bend: str = "ramp") -> tuple[np.ndarray, np.ndarray]:
    """Bend world paths whose end point is not on a walkable pixel of ``scene`` (see module docstring).

    Args:
        paths_m: (N, S, 12, 2) world metres; step 0 is the first future step.
        origin_m: (N, 2) last observed points [m]; needed by ``bend="scale"``.
        off_image: "pull" end points off the image back onto it, or "keep" them.
        bend: "ramp" or "scale".

    Returns:
        adapted: (N, S, 12, 2) world metres.  moved: (N, S) bool, paths that were bent.
    """
    if off_image not in OFF_IMAGE_MODES or bend not in BEND_SHAPES:
        raise ValueError(f"off_image must be one of {OFF_IMAGE_MODES} and bend one of {BEND_SHAPES}, "
                         f"got {off_image!r} and {bend!r}")
    end_px = scene.world_to_pixel(paths_m[:, :, -1])
    target_px, moved = _end_targets(end_px, scene, off_image)
    if bend == "ramp":
        shift = np.where(moved[..., None], scene.pixel_to_world(target_px) - paths_m[:, :, -1], 0.0)  # (N, S, 2)
        return paths_m + RAMP[:, None] * shift[:, :, None, :], moved
    if origin_m is None:
        raise ValueError('bend="scale" needs the agents\' last observed points (origin_m)')
    paths_px = scene.world_to_pixel(paths_m)  # (N, S, 12, 2)
    origin_px = scene.world_to_pixel(origin_m)[:, None, None, :]  # (N, 1, 1, 2)
    span = end_px - origin_px[:, :, 0]  # (N, S, 2)
    wide = np.abs(span) >= MIN_AXIS_SPAN_PX
    ratio = np.where(wide, (target_px - origin_px[:, :, 0]) / np.where(wide, span, 1.0), 1.0)
    offset = np.where(wide, 0.0, target_px - end_px)  # narrow axes: ramp the correction instead
    bent_px = origin_px + (paths_px - origin_px) * ratio[:, :, None] + RAMP[:, None] * offset[:, :, None]
    adapted = np.where(moved[..., None, None], scene.pixel_to_world(bent_px), paths_m)
    return adapted, moved


def onto_walkable(paths_m: np.ndarray, scene: Scene, tolerance_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Move every point of ``paths_m`` (..., 2) world metres that lies more than ``tolerance_m`` from a walkable pixel
    of ``scene`` (on a wall, or off the image) to the centre of its nearest walkable pixel; returns the points and
    which moved (...). A small tolerance leaves alone the band along the walls where annotated people walk too."""
    uv = scene.world_to_pixel(paths_m)
    off_map = ~_on_walkable_pixel(uv, scene)
    out, moved = np.array(paths_m, dtype=np.float64), np.zeros(off_map.shape, bool)
    if off_map.any():  # most points of most forecasts are on the map: look up targets for the others only
        target_m = scene.pixel_to_world(_end_targets(uv[off_map], scene, "pull")[0])
        far = np.linalg.norm(target_m - out[off_map], axis=-1) > tolerance_m
        moved[off_map] = far
        out[moved] = target_m[far]
    return out, moved


def _on_walkable_pixel(uv: np.ndarray, scene: Scene) -> np.ndarray:
    """(...) bool: the pixel (..., 2) (column, row), rounded, is on the image and walkable."""
    height, width = scene.walkable.shape
    uv = np.rint(np.nan_to_num(uv, nan=-1.0, posinf=-1.0, neginf=-1.0))
    inside = (uv[..., 0] >= 0) & (uv[..., 0] < width) & (uv[..., 1] >= 0) & (uv[..., 1] < height)
    return inside & scene.walkable[np.where(inside, uv[..., 1], 0).astype(np.intp),
                                   np.where(inside, uv[..., 0], 0).astype(np.intp)]


def adaptive_anchors(anchors: np.ndarray, frames: AgentFrame, space_of: list[SingularSpace],
                     population: np.ndarray, scene: Scene | None, off_image: str = "pull", bend: str = "ramp"
                     ) -> np.ndarray:
    """Per-agent anchor coefficients adapted to the map.

    With the "ramp" bend only the prototypes' end points are placed in the world: the bend adds the end point's
    correction linearly over the 12 steps, so in Singular space it adds the correction (agent frame) times the
    basis summed with the ramp's weights (``SingularSpace.project`` is linear). "scale" bends whole paths in pixels.

    Args:
        anchors: (P, S, K) prototype coefficients per population (0 = moving, 1 = slow).
        frames: agent frames of the N agents.
        space_of: Singular space per population.
        population: (N,) int population index.
        scene: map to adapt to, or None (prototypes unchanged).
        off_image, bend: see ``adapt_paths``.

    Returns:
        (N, S, K) adapted anchor coefficients.
    """
    coefs = anchors[population].copy()  # (N, S, K)
    if scene is None or len(population) == 0:
        return coefs
    if bend != "ramp":
        _, adapted_m = anchor_paths(anchors, frames, space_of, population, scene, off_image, bend)
        adapted_local = frames.to_agent(adapted_m)
        for p, space in enumerate(space_of):
            mask = population == p
            coefs[mask] = space.project(adapted_local[mask].reshape(-1, T_WIN, 2)).reshape(coefs[mask].shape)
        return coefs
    end_local = np.zeros((len(population), anchors.shape[1], 2))
    for p, space in enumerate(space_of):
        mask = population == p
        end_local[mask] = space.reconstruct(anchors[p])[None, :, -1]
    end_m = frames.to_world(end_local)  # (N, S, 2)
    target_px, moved = _end_targets(scene.world_to_pixel(end_m), scene, off_image)
    if not moved.any():
        return coefs
    shift_m = np.where(moved[..., None], scene.pixel_to_world(target_px) - end_m, 0.0)
    extra = (slice(None), None)
    shift_local = rotate(shift_m, -frames.angle_rad[extra]) / frames.scale_m[extra][..., None]  # (N, S, 2)
    for p, space in enumerate(space_of):
        mask = population == p
        ramp_basis = np.einsum("t,tck->ck", RAMP, space.basis.reshape(T_WIN, 2, space.k))  # (2, K)
        coefs[mask] += shift_local[mask] @ ramp_basis
    return coefs


def anchor_paths(anchors: np.ndarray, frames: AgentFrame, space_of: list[SingularSpace], population: np.ndarray,
                 scene: Scene | None, off_image: str = "pull", bend: str = "ramp") -> tuple[np.ndarray, np.ndarray]:
    """(prototype, adapted) anchor paths of N agents, each (N, S, 12, 2) world metres (arguments as
    ``adaptive_anchors``; the adapted ones are the prototypes where ``scene`` is None)."""
    local = np.zeros((len(population), anchors.shape[1], T_WIN, 2))
    for p, space in enumerate(space_of):
        mask = population == p
        local[mask] = space.reconstruct(anchors[p])[None]
    proto_m = frames.to_world(local)
    if scene is None:
        return proto_m, proto_m
    return proto_m, adapt_paths(proto_m, scene, frames.origin_m, off_image, bend)[0]
