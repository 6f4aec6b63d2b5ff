"""How deep a point lies in a scene's non-walkable area: metres to the nearest walkable pixel (0 on the map)."""

from __future__ import annotations

import cv2
import numpy as np

from replays.scenes import Scene


class MapDepth:
    """Distance of every pixel of ``scene``'s map from its walkable area, looked up at world points.

    Pixels become metres by the homography's scale at the image centre (ETH/UCY's maps are close to a uniform
    scale; a depth is a tolerance, not a measurement).
    """

    def __init__(self, scene: Scene):
        self.scene = scene
        pixels = cv2.distanceTransform((~scene.walkable).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        centre = np.array(scene.walkable.shape[::-1], np.float64) / 2
        step = scene.pixel_to_world(centre + np.array([1.0, 0.0])) - scene.pixel_to_world(centre)
        self.depth_m = pixels * float(np.linalg.norm(step))
        """(H, W) float64 metres"""

    def at(self, xy_m: np.ndarray) -> np.ndarray:
        """(...) depth [m] of world points (..., 2) in the non-walkable area: 0 on walkable pixels, inf off the
        image or for non-finite points."""
        xy_m = np.asarray(xy_m, np.float64)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            uv = np.rint(self.scene.world_to_pixel(xy_m))
        height, width = self.depth_m.shape
        inside = (np.isfinite(uv).all(-1) & (uv[..., 0] >= 0) & (uv[..., 0] < width) & (uv[..., 1] >= 0)
                  & (uv[..., 1] < height))
        u = np.where(inside, uv[..., 0], 0).astype(np.intp)
        v = np.where(inside, uv[..., 1], 0).astype(np.intp)
        return np.where(inside, self.depth_m[v, u], np.inf)
