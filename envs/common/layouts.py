"""Simulator layouts of the envs: synthetic ones, and the real scenes' geometry traced once per process."""

from __future__ import annotations

import os
from functools import cache

from replays.data_root import data_root
from replays.scenes import SCENES, load_scene
from st_sim.sim import Layout, layout_from_scene, make_layout

SYNTHETIC_LAYOUTS: tuple[str, ...] = ("crossing", "corridor", "bottleneck", "plaza", "doorway")


@cache
def _synthetic_layout(name: str) -> Layout:
    """A synthetic layout, built once per process: every env of it shares one object (and its navigation fields),
    which is what lets a vector env step their crowds together."""
    return make_layout(name)


@cache
def _scene_layout(name: str, root: os.PathLike) -> Layout:
    """A real scene's layout, built once per process (contour tracing is the slow part)."""
    return layout_from_scene(load_scene(name, root))


def build_layout(name: str, root: str | os.PathLike | None = None) -> Layout:
    """Simulator layout by name: a synthetic one (no data needed) or an ETH/UCY scene's geometry."""
    if name in SYNTHETIC_LAYOUTS:
        return _synthetic_layout(name)
    if name in SCENES:
        return _scene_layout(name, data_root(root))
    raise ValueError(f"layout={name!r}: expected one of {', '.join(SYNTHETIC_LAYOUTS + tuple(SCENES))}")
