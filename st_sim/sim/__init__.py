"""pymunk crowd simulator: layouts (synthetic or from real scene maps) and CrowdSim, steered by a calibrated
collision-free speed model (or social forces), with populations fitted to ETH/UCY.

Quick start::

    import numpy as np
    from st_sim.sim import CrowdConfig, CrowdSim, make_layout
    sim = CrowdSim(make_layout("corridor"), CrowdConfig(max_pedestrians=100), np.random.default_rng(0))
    for _ in range(50):
        sim.step()                      # 0.4 s
    sim.positions_m.shape, sim.ids      # (N, 2) metres, (N,) stable ids
    sim.save_recording("corridor.txt")  # replays.read_recording reads it back
"""

from st_sim.sim.checks import LayoutTooLargeError
from st_sim.sim.config import CrowdConfig, EgoConfig, PopulationConfig, SocialForceConfig, SpeedModelConfig
from st_sim.sim.crowd import CrowdSim, population_cap
from st_sim.sim.layout import Layout, Period, Region
from st_sim.sim.layouts import make_layout
from st_sim.sim.map_walls import layout_from_scene
from st_sim.sim.population import PopulationError

__all__ = ["CrowdConfig", "CrowdSim", "EgoConfig", "Layout", "LayoutTooLargeError", "Period", "PopulationConfig",
           "PopulationError", "Region", "SocialForceConfig", "SpeedModelConfig", "layout_from_scene", "make_layout",
           "population_cap"]
