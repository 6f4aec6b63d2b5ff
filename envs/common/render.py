"""OpenCV drawing of one observation on the scene photo (or the layout's map): ``render_mode="rgb_array"``."""

from __future__ import annotations

import numpy as np

from replays.scenes import Scene

HISTORY_RGB = (40, 120, 255)  # observed paths
AGENT_RGB = (255, 220, 0)  # current pedestrian positions
FUTURE_RGB = (255, 60, 200)  # predicted futures
EGO_RGB = (230, 30, 30)
GOAL_RGB = (30, 200, 60)
AGENT_RADIUS_PX = 4
MAX_DRAWN_SAMPLES = 20  # futures drawn per agent


def _to_px(scene: Scene, xy_m: np.ndarray) -> np.ndarray:
    """(..., 2) metres -> (..., 2) int32 pixel (column, row), for cv2."""
    return np.rint(scene.world_to_pixel(xy_m)).clip(-1e5, 1e5).astype(np.int32)


def draw_observation(scene: Scene, obs: dict[str, np.ndarray], ego: bool, ego_radius_m: float) -> np.ndarray:
    """Draw histories, futures, agents, and the ego with its goal.

    Args:
        scene: photo and homography to draw on.
        obs: an environment observation (keys ego, history, history_mask, futures, futures_mask).
        ego: draw the ego and its goal (False in spectator mode).
        ego_radius_m: ego body radius [m].

    Returns:
        (H, W, 3) uint8 RGB image of the scene photo's size.
    """
    try:
        import cv2
    except ImportError as err:
        raise ImportError('render_mode="rgb_array" needs `pip install opencv-python-headless`') from err

    image = np.ascontiguousarray(scene.photo, dtype=np.uint8).copy()
    for row in np.flatnonzero(obs["futures_mask"]):
        paths = _to_px(scene, obs["futures"][row, :MAX_DRAWN_SAMPLES])  # (S, 12, 2)
        start = _to_px(scene, obs["history"][row, -1])
        cv2.polylines(image, [np.vstack([start, p]) for p in paths], False, FUTURE_RGB, 1, cv2.LINE_AA)
    for row in np.flatnonzero(obs["history_mask"][:, -1]):
        seen = obs["history_mask"][row]
        path = _to_px(scene, obs["history"][row, seen])
        cv2.polylines(image, [path], False, HISTORY_RGB, 2, cv2.LINE_AA)
        cv2.circle(image, tuple(int(c) for c in path[-1]), AGENT_RADIUS_PX, AGENT_RGB, -1, cv2.LINE_AA)
    if ego:
        position, goal = obs["ego"][:2], obs["ego"][4:6]
        centre = _to_px(scene, position)
        edge = _to_px(scene, position + np.array([ego_radius_m, 0.0]))
        radius_px = max(int(np.hypot(*(edge - centre))), AGENT_RADIUS_PX)
        cv2.drawMarker(image, tuple(int(c) for c in _to_px(scene, goal)), GOAL_RGB, cv2.MARKER_STAR, 18, 2)
        cv2.circle(image, tuple(int(c) for c in centre), radius_px, EGO_RGB, -1, cv2.LINE_AA)
    return image
