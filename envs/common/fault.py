"""Who is at fault when the robot touches a pedestrian, judged at the moment of impact: the robot, unless it was
(nearly) stopped then or every pedestrian it touched came from behind it (as driving benchmarks count only at-fault
collisions: a stopped ego, or one hit from behind, is not at fault).

The moment of impact is the first instant of the step at which the bodies touch (``st_sim.sim.sweep.Contact``), not
the end of the step: a robot that drove through a pedestrian and ended past it hit it head on.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from st_sim.sim.sweep import Contact

STOPPED_MPS: Final[float] = 0.2  # a robot moving slower than this at the impact is (nearly) stopped [m/s]


def robot_at_fault(contact: Contact) -> bool:
    """True if the robot is at fault for ``contact``: at the impact it moved at ``STOPPED_MPS`` or faster and at
    least one pedestrian it touched was not behind it (its velocity points into the half-plane of that pedestrian's
    centre, bearing within +-90 degrees of its heading)."""
    velocity = np.asarray(contact.robot_velocity_mps, np.float64)
    if np.hypot(*velocity) < STOPPED_MPS:
        return False
    offset = np.asarray(contact.pedestrians_xy_m, np.float64).reshape(-1, 2) - contact.robot_xy_m
    return bool((offset @ velocity >= 0.0).any())
