"""Gymnasium environments of STCrowd; importing this package registers every id (no env code is imported).

    import gymnasium as gym, envs
    env = gym.make("STCrowd-Zara1-v0")                      # ZARA1 replayed from the recording
    env = gym.make("STCrowd-SimCrossing-v1")                # pymunk crowd, no data needed
    env = gym.make("STCrowd-SimDoorway-v1")                 # a scripted encounter: someone comes through the door
    env = gym.make("STCrowd-Zara1-v0", ego=False, task="deterministic", predictor="cvm-s")
    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=16)   # native vector env: one forecast call per step
    env = gym.make("STCrowd-Suite-v1", predictor="cvm")     # the suite's train split, a scenario per episode, seen
                                                            # through the fixed-size view (envs.view)

Replay and real-scene simulated ids, and the suite env with its replay scenarios, need the ETH/UCY data root
($STCROWD_DATA or the user cache).
"""

from __future__ import annotations

from gymnasium.envs.registration import register

REPLAY_SCENES: tuple[str, ...] = ("Eth", "Hotel", "Univ", "Zara1", "Zara2")
SIM_LAYOUTS: tuple[str, ...] = ("Crossing", "Corridor", "Bottleneck")
SIM_ENCOUNTERS: dict[str, str] = {"FrontalApproach": "frontal_approach", "Overtaking": "overtaking",
                                  "CrossingAngle": "crossing_angle", "Doorway": "doorway", "Group": "group"}
"""scripted encounters after Francis et al. (2023): id part -> the env's ``encounter=`` (``st_sim.sim.encounters``)"""
MAX_EPISODE_STEPS = 200  # 80 s of 0.4 s steps; a replay also ends with its recording
SIM_VERSION = 1  # v1: calibrated speed-model crowds that see the ego (v0: social force, invisible ego)

# Replays: pedestrians follow an ETH/UCY recording
for _scene in REPLAY_SCENES:
    register(
        id=f"STCrowd-{_scene}-v0",
        entry_point="envs.replay_env:ReplayCrowdEnv",
        vector_entry_point="envs.vector_env:replay_vector_env",
        kwargs={"scene": _scene.lower()},
        max_episode_steps=MAX_EPISODE_STEPS,
    )

# Simulated: pymunk crowds in synthetic layouts (no data needed) or in a real scene's geometry (data root)
for _layout in SIM_LAYOUTS + REPLAY_SCENES:
    register(
        id=f"STCrowd-Sim{_layout}-v{SIM_VERSION}",
        entry_point="envs.sim_env:SimCrowdEnv",
        vector_entry_point="envs.vector_env:sim_vector_env",
        kwargs={"layout": _layout.lower()},
        max_episode_steps=MAX_EPISODE_STEPS,
    )

# Simulated encounters: a few scripted pedestrians meet the ego (no data needed)
for _encounter, _name in SIM_ENCOUNTERS.items():
    register(
        id=f"STCrowd-Sim{_encounter}-v{SIM_VERSION}",
        entry_point="envs.sim_env:SimCrowdEnv",
        vector_entry_point="envs.vector_env:sim_vector_env",
        kwargs={"encounter": _name},
        max_episode_steps=MAX_EPISODE_STEPS,
    )

# The navigation suite as one env: a scenario per episode, every one seen through the fixed-size view (envs.view).
# No time limit of its own: each scenario's env keeps its registered one.
SUITE_ID = "STCrowd-Suite-v1"
register(id=SUITE_ID, entry_point="envs.suite_env:SuiteEnv")

ENCOUNTER_IDS: tuple[str, ...] = tuple(f"STCrowd-Sim{s}-v{SIM_VERSION}" for s in SIM_ENCOUNTERS)
"""the scripted encounters' ids"""
STCROWD_IDS: tuple[str, ...] = (
    *(f"STCrowd-{s}-v0" for s in REPLAY_SCENES),
    *(f"STCrowd-Sim{s}-v{SIM_VERSION}" for s in SIM_LAYOUTS + REPLAY_SCENES),
    *ENCOUNTER_IDS,
)
"""every crowd env's id, replays first (the suite env, ``SUITE_ID``, draws among them)"""
