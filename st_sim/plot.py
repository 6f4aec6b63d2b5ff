"""Static PNG figures of predictions drawn over a scene photo with OpenCV (charts with axes: ``st_sim.charts``).

One figure shows, per agent: the observed history (solid, agent colour), the S predicted futures
(thin, semi-transparent, agent colour), the prototype anchors before adaptation (grey, dashed), the
anchors after adaptation to the walkability map (orange) and the ground-truth future (green), over
the photo with the non-walkable area tinted red. ``agent_colors`` is shared with ``st_sim.rerun_log``
so an agent has the same colour in the PNGs and in the Rerun viewer.

    plot_prediction(load_scene("zara1"), obs, futures, "zara1.png", gt_m=fut, title="zara1 test")
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from replays.atomic import atomic_path
from replays.scenes import Scene

# Colours are RGB. The agent palette leaves out green, orange and grey, which mark ground truth and anchors.
AGENT_PALETTE = np.array([
    (31, 119, 180), (214, 39, 40), (148, 103, 189), (227, 119, 194), (23, 190, 207),
    (140, 86, 75), (65, 105, 225), (255, 215, 0), (0, 0, 139), (199, 21, 133),
], dtype=np.uint8)
GT_RGB = (40, 220, 60)  # ground-truth future
PROTOTYPE_RGB = (170, 170, 170)  # prototype anchors, before adaptation
ADAPTED_RGB = (255, 140, 0)  # anchors after adaptation to the map
BLOCKED_TINT_RGB = (200, 30, 30)  # tint of non-walkable pixels
BLOCKED_ALPHA = 0.35  # opacity of that tint
FUTURE_ALPHA = 0.45  # opacity of predicted futures
PROTOTYPE_ALPHA = 0.8  # opacity of prototype anchors
ADAPTED_ALPHA = 0.6  # opacity of adapted anchors
MIN_LONG_SIDE_PX = 1200  # smaller photos are upscaled by an integer factor to at least this long side
SHIFT_BITS = 4  # sub-pixel precision of OpenCV drawing (coordinates in 1/16 px)


def agent_colors(ids: np.ndarray) -> np.ndarray:
    """(N,) integer agent ids -> (N, 3) uint8 RGB, the same colour for the same id everywhere."""
    return AGENT_PALETTE[np.asarray(ids, dtype=np.int64) % len(AGENT_PALETTE)]


def plot_prediction(scene: Scene, history_m: np.ndarray, futures_m: np.ndarray, path: str | os.PathLike,
                    gt_m: np.ndarray | None = None, prototype_anchors_m: np.ndarray | None = None,
                    adapted_anchors_m: np.ndarray | None = None, title: str = "") -> Path:
    """Draw predictions of N agents over the scene and write a PNG (atomically).

    Args:
        scene: photo, walkability map and homography (positions go to pixels with ``scene.world_to_pixel``).
        history_m: (N, T_obs, 2) observed positions, metres, world frame.
        futures_m: (N, S, T_pred, 2) predicted positions, metres, world frame.
        path: PNG file to write; its folder must exist.
        gt_m: (N, T_pred, 2) ground-truth future, metres, or None.
        prototype_anchors_m: (N, S_a, T_a, 2) anchors before adaptation, metres, world frame, or None.
        adapted_anchors_m: (N, S_a, T_a, 2) anchors after adaptation, metres, world frame, or None.
        title: text drawn at the top.

    Returns:
        The path written.

    Raises:
        ValueError: an array has the wrong shape, disagrees on N, or holds NaN/inf.
    """
    arrays = _check_inputs(history_m, futures_m, gt_m, prototype_anchors_m, adapted_anchors_m)
    scale = max(1, int(np.ceil(MIN_LONG_SIDE_PX / max(scene.walkable.shape))))
    image = _background(scene, scale)
    thickness = max(1, round(image.shape[1] / 600))
    pixels = {key: None if value is None else (scene.world_to_pixel(value) + 0.5) * scale - 0.5  # upscaled px
              for key, value in arrays.items()}
    image = _draw_paths(image, pixels, thickness)
    sample = tuple(AGENT_PALETTE[0])
    entries = [("history (colour = agent)", sample, False),
               (f"predicted futures (S={arrays['futures'].shape[1]})", sample, False)]
    entries += [(label, color, dashed) for label, key, color, dashed in (
        ("prototype anchors", "prototype", PROTOTYPE_RGB, True), ("adapted anchors", "adapted", ADAPTED_RGB, False),
        ("ground truth", "gt", GT_RGB, False)) if arrays[key] is not None]
    _legend(image, entries, title, thickness)
    return _write_png(image, Path(path))


def _draw_paths(image: np.ndarray, pixels: dict[str, np.ndarray | None], thickness: int) -> np.ndarray:
    """Draw anchors, futures, ground truth and histories (bottom to top) given in image pixels."""
    colors = agent_colors(np.arange(len(pixels["history"])))
    last_px = pixels["history"][:, -1]  # (N, 2) futures and ground truth start here
    for key, color, alpha, dashed in (("prototype", PROTOTYPE_RGB, PROTOTYPE_ALPHA, True),
                                      ("adapted", ADAPTED_RGB, ADAPTED_ALPHA, False)):
        if pixels[key] is not None:
            strips = pixels[key].reshape(-1, pixels[key].shape[2], 2)
            image = _blend_strips(image, strips, np.array([color] * len(strips)), thickness, alpha, dashed)
    futures = pixels["futures"]  # (N, S, T, 2)
    starts = np.broadcast_to(last_px[:, None, None], (*futures.shape[:2], 1, 2))
    strips = np.concatenate([starts, futures], axis=2).reshape(-1, futures.shape[2] + 1, 2)
    image = _blend_strips(image, strips, np.repeat(colors, futures.shape[1], 0), thickness, FUTURE_ALPHA)
    if pixels["gt"] is not None:
        for start, strip in zip(last_px, pixels["gt"], strict=True):
            _polyline(image, np.vstack([start, strip]), GT_RGB, 2 * thickness)
            _disc(image, strip[-1], 2 * thickness, GT_RGB)
    for color, strip in zip(colors, pixels["history"], strict=True):
        _polyline(image, strip, color, 2 * thickness, outline=True)
        _disc(image, strip[-1], 4 * thickness, color)
    return image


def _check_inputs(history_m, futures_m, gt_m, prototype_m, adapted_m) -> dict[str, np.ndarray | None]:
    """Convert to float64 arrays and check the shapes of ``plot_prediction``'s arguments."""
    expected = {"history_m": (history_m, 3), "futures_m": (futures_m, 4), "gt_m": (gt_m, 3),
                "prototype_anchors_m": (prototype_m, 4), "adapted_anchors_m": (adapted_m, 4)}
    arrays: dict[str, np.ndarray | None] = {}
    for name, (value, ndim) in expected.items():
        key = name.removesuffix("_m").removesuffix("_anchors")
        if value is None:
            arrays[key] = None
            continue
        value = np.asarray(value, dtype=np.float64)
        if value.ndim != ndim or value.shape[-1] != 2 or 0 in value.shape[1:]:
            letters = "(N, T, 2)" if ndim == 3 else "(N, S, T, 2)"
            raise ValueError(f"plot_prediction: {name} must be {letters} metres, got shape {value.shape}")
        if len(value) != len(history_m):
            raise ValueError(f"plot_prediction: {name} has {len(value)} agents, history_m has {len(history_m)}")
        if not np.isfinite(value).all():
            raise ValueError(f"plot_prediction: {name} holds NaN or inf")
        arrays[key] = value
    if gt_m is not None and arrays["gt"].shape[1] != arrays["futures"].shape[2]:
        raise ValueError(f"plot_prediction: gt_m has {arrays['gt'].shape[1]} steps, "
                         f"futures_m has {arrays['futures'].shape[2]}")
    return arrays


def _background(scene: Scene, scale: int) -> np.ndarray:
    """(H*scale, W*scale, 3) uint8 RGB photo with the non-walkable pixels tinted."""
    photo = scene.photo.astype(np.float32)
    blocked = ~scene.walkable[..., None]
    tinted = np.where(blocked, (1 - BLOCKED_ALPHA) * photo + BLOCKED_ALPHA * np.float32(BLOCKED_TINT_RGB), photo)
    image = np.clip(tinted, 0, 255).astype(np.uint8)
    if scale > 1:
        image = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC)
    return image


def _blend_strips(image: np.ndarray, strips_px: np.ndarray, colors: np.ndarray, thickness: int, alpha: float,
                  dashed: bool = False) -> np.ndarray:
    """Draw (L, T, 2) pixel polylines in (L, 3) colours on a copy of the image; blend it in with ``alpha``."""
    layer = image.copy()
    for strip, color in zip(strips_px, colors, strict=True):
        if dashed:
            _dashed_polyline(layer, strip, color, thickness, dash_px=6 * thickness)
        else:
            _polyline(layer, strip, color, thickness)
    return cv2.addWeighted(layer, alpha, image, 1 - alpha, 0)


def _polyline(image: np.ndarray, points_px: np.ndarray, color, thickness: int, outline: bool = False) -> None:
    """Anti-aliased open polyline through (T, 2) float pixel points; ``outline`` adds a dark border."""
    points = np.rint(points_px * (1 << SHIFT_BITS)).astype(np.int32)[None]
    if outline:
        cv2.polylines(image, points, False, (20, 20, 20), thickness + 2, cv2.LINE_AA, SHIFT_BITS)
    cv2.polylines(image, points, False, tuple(int(c) for c in color), thickness, cv2.LINE_AA, SHIFT_BITS)


def _dashed_polyline(image: np.ndarray, points_px: np.ndarray, color, thickness: int, dash_px: float) -> None:
    """Polyline through (T, 2) pixel points drawn as dashes of ``dash_px`` separated by equal gaps."""
    steps = np.linalg.norm(np.diff(points_px, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(steps)])  # (T,) pixel distance along the path
    if arc[-1] == 0:
        return
    starts = np.arange(0.0, arc[-1], 2 * dash_px)
    for start in starts:
        along = np.linspace(start, min(start + dash_px, arc[-1]), 4)
        dash = np.stack([np.interp(along, arc, points_px[:, 0]), np.interp(along, arc, points_px[:, 1])], -1)
        _polyline(image, dash, color, thickness)


def _disc(image: np.ndarray, center_px: np.ndarray, radius_px: int, color) -> None:
    """Filled anti-aliased disc with a dark rim."""
    center = tuple(int(v) for v in np.rint(center_px * (1 << SHIFT_BITS)))
    radius = radius_px << SHIFT_BITS
    cv2.circle(image, center, radius + (1 << SHIFT_BITS), (20, 20, 20), -1, cv2.LINE_AA, SHIFT_BITS)
    cv2.circle(image, center, radius, tuple(int(c) for c in color), -1, cv2.LINE_AA, SHIFT_BITS)


def _legend(image: np.ndarray, entries: list[tuple[str, tuple, bool]], title: str, thickness: int) -> None:
    """Draw a title line and a boxed legend (label, colour, dashed) in the top-left corner."""
    font, font_scale = cv2.FONT_HERSHEY_SIMPLEX, image.shape[1] / 2400
    text_px = cv2.getTextSize("Ag", font, font_scale, thickness)[0][1]
    row_px, margin, sample_px = int(2.0 * text_px), int(text_px), int(4 * text_px)
    rows = ([title] if title else []) + [label for label, _, _ in entries]
    width = max(cv2.getTextSize(r, font, font_scale, thickness)[0][0] for r in rows) + sample_px + 3 * margin
    height = row_px * len(rows) + margin
    box = image[margin:margin + height, margin:margin + width]
    box[:] = (0.25 * box + 0.75 * 255).astype(np.uint8)  # light, slightly see-through panel
    cv2.rectangle(image, (margin, margin), (margin + width, margin + height), (60, 60, 60), 1, cv2.LINE_AA)
    y = margin + row_px
    if title:
        cv2.putText(image, title, (2 * margin, y - margin // 2), font, font_scale, (0, 0, 0), thickness, cv2.LINE_AA)
        y += row_px
    for label, color, dashed in entries:
        mid = y - margin // 2 - text_px // 2
        sample = np.array([[2 * margin, mid], [2 * margin + sample_px, mid]], dtype=np.float64)
        if dashed:
            _dashed_polyline(image, sample, color, 2 * thickness, dash_px=sample_px / 5)
        else:
            _polyline(image, sample, color, 2 * thickness)
        cv2.putText(image, label, (3 * margin + sample_px, y - margin // 2), font, font_scale, (0, 0, 0),
                    thickness, cv2.LINE_AA)
        y += row_px


def _write_png(image_rgb: np.ndarray, path: Path) -> Path:
    """Encode to PNG and replace ``path`` atomically (temporary file in the same folder, then os.replace)."""
    ok, data = cv2.imencode(".png", cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"{path}: OpenCV could not encode the figure as PNG")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.tobytes())
    return path
