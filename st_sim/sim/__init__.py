"""pymunk crowd simulator: layouts (synthetic or from real scene maps) and the social-force CrowdSim.

Quick start::

    import numpy as np
    from st_sim.sim import CrowdConfig, CrowdSim, make_layout
    sim = CrowdSim(make_layout("corridor"), CrowdConfig(max_pedestrians=100), np.random.default_rng(0))
    for _ in range(50):
        sim.step()                      # 0.4 s
    sim.positions_m.shape, sim.ids      # (N, 2) metres, (N,) stable ids
    sim.save_recording("corridor.txt")  # replays.read_recording reads it back
"""

from st_sim.sim.config import CrowdConfig, EgoConfig
from st_sim.sim.crowd import CrowdSim
from st_sim.sim.layout import Layout, Region
from st_sim.sim.layouts import make_layout
from st_sim.sim.map_walls import layout_from_scene

__all__ = ["CrowdConfig", "CrowdSim", "EgoConfig", "Layout", "Region", "layout_from_scene", "make_layout"]
