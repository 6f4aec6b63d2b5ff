"""What the robot senses of the crowd: a people sensor (range, field of view, occlusion, noise, misses, ghosts,
latency) and a tracker between it and the predictor, with the truth beside them for evaluation.

    from st_sim.perception import SENSING_LEVELS, Perception, sensing_spec
    perception = Perception(sensing_spec("realistic"), capacity=40, scene=scene, radius_m=0.25, robot_radius_m=0.3)
    perception.reset(np.random.default_rng(0))
    tracks = perception.sense(ids, xy_m, robot_xy, heading)     # tracks.ids, tracks.xy_m: what the robot reports
"""

from st_sim.perception.mot import MotAccumulator
from st_sim.perception.perception import Perception
from st_sim.perception.sensor import Detections, detect, in_field, occluded
from st_sim.perception.spec import SENSING_LEVELS, SensingSpec, SensingSpecError, sensing_spec
from st_sim.perception.tracker import Tracker, Tracks

__all__ = ["SENSING_LEVELS", "Detections", "MotAccumulator", "Perception", "SensingSpec", "SensingSpecError",
           "Tracker", "Tracks", "detect", "in_field", "occluded", "sensing_spec"]
