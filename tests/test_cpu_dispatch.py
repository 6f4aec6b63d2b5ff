"""The same episodes on every CPU: the simulated crowds, the log and reactive replays and the scripted encounters,
stepped in fresh processes under the default dispatch and under emulated older CPUs, move every body to the same bits.

numpy, OpenBLAS, glibc's libm, torch and numba each pick their kernels for the CPU at run time; the variables below
make them pick those of an older CPU (they are read at import, so each variant is a child process):

- ``NPY_DISABLE_CPU_FEATURES``: numpy without AVX-512, and numpy at its baseline (no AVX2 either on x86-64); only
  the dispatched features that numpy found on this machine are named (numpy refuses a baseline one);
- ``GLIBC_TUNABLES`` and ``OPENBLAS_CORETYPE`` (x86-64): libm's and OpenBLAS's kernels without AVX2 and FMA;
- ``ATEN_CPU_CAPABILITY`` (avx2, default) and ``NUMBA_CPU_NAME=generic``.

A child (this file run as a script) steps the simulated envs with a fixed drive to the goal, a few bare crowds (the
other layouts, the social-force model) and short navigation episodes with the ORCA planner; then, for each robot kind,
a log replay, a reactive replay with drawn traits and a scripted encounter driven by commands beyond the robot's
limits, and a few steps of the MPC planner (CVM forecasts) in the reactive replay and the encounter; and the
holonomic robot through the same three worlds seeing with the ``realistic`` sensor and tracker. It prints one
SHA-256 digest per case (every body's position and velocity as float64 bytes; for the worlds of a robot also the
observation, the reward, how the episode ended and the reactive pedestrians' whole state; with a sensor also its
detections and tracks).

Two positive controls keep the check from passing on nothing. Each child reports the dispatch it ran under
(``dispatch``: numpy's enabled targets, OpenBLAS's core, a digest of libm's sines, cosines and exponentials, torch's
capability, numba's target CPU), and the test asserts that at least one variant changed one of them; which variants
did is printed and kept as the test's ``dispatch`` property (a variant that changes nothing on this CPU, say numpy
without AVX-512 on a CPU without it, compares the default with itself). And the default child counts what the
drives exercised: every over-limit drive's commands went beyond the robot's limits, the reactive pedestrians
stepped off their logs, and every sensing drive's tracker held tracks. Under ``--perturb`` the children run
unperturbed: the test compares runs with each other, not with stored digests.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import math
import os
import platform
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import fields
from pathlib import Path

import numpy as np

STEPS = 100  # env steps per simulated env, crowd steps per bare crowd
SEED = 11
EPISODES = {"STCrowd-SimCrossing-v1": 1863924143, "STCrowd-SimBottleneck-v1": 1102676120,
            "STCrowd-SimGroup-v1": 1667152401}
"""the navigation episodes: env id -> reset seed (the suite's first val seeds)"""
ROBOT_WORLDS = {"log/zara1": ("STCrowd-Zara1-v0", {}),
                "reactive/eth": ("STCrowd-Eth-v0", {"pedestrians": "reactive", "reaction_traits": "drawn"}),
                "encounter/frontal": ("STCrowd-SimFrontalApproach-v1", {})}
"""the worlds each robot kind drives through: name -> (env id, keywords)"""
MPC_WORLDS = ("reactive/eth", "encounter/frontal")  # where the MPC planner drives each robot kind
ROBOT_STEPS = 40  # env steps of each world of ROBOT_WORLDS under over-limit commands
MPC_STEPS = 8  # env steps of each MPC drive
OVER_LIMIT = 2.5  # the over-limit drive's commands: this many times what the robot may take [-]
X86_AVX512 = ("X86_V4", "AVX512_ICL", "AVX512_SPR")  # numpy's dispatch targets that need AVX-512
ROOT = Path(__file__).resolve().parents[1]


def _digest(*arrays: np.ndarray) -> bytes:
    return b"".join(np.ascontiguousarray(a, np.float64).tobytes() for a in arrays)


def _drive(obs: dict[str, np.ndarray]) -> np.ndarray:
    """1 m/s toward the goal (+, *, sqrt: the action itself is the same everywhere)."""
    x, y = (float(v) for v in obs["ego"][4:6] - obs["ego"][0:2])
    return np.array([x, y], np.float32) / np.float32(max(math.sqrt(x * x + y * y), 1e-9))


def _over_limit(env, obs: dict[str, np.ndarray]) -> np.ndarray:
    """OVER_LIMIT times the robot's command toward the goal at its top speed: faster (and, for a differential drive,
    turning faster) than it may go, so the robot's limits scale or clip every command."""
    from st_sim.sim.robot import command_toward

    spec = env.unwrapped.robot
    toward = _drive(obs).astype(np.float64) * spec.max_speed_mps
    return (OVER_LIMIT * command_toward(spec, obs["ego"][6:8], toward)[0]).astype(np.float32)


def _bodies(sim) -> bytes:
    """Every body's state: pedestrians' ids, positions and velocities, then the ego's."""
    ego = [] if sim.ego_position_m is None else [sim.ego_position_m, sim.ego_velocity_mps]
    return _digest(sim.ids, sim.positions_m, sim.velocities_mps, *ego)


def _world(env, obs: dict[str, np.ndarray], reward: float, info: dict) -> bytes:
    """A robot's world after a step: the observation, the reward and the episode's end, and its bodies (a replay's
    ego, and its reactive pedestrians' whole state)."""
    from st_sim.reactive.reactive import ReactiveState

    world = env.unwrapped
    seen = _digest(*(obs[key] for key in sorted(obs)), [reward]) + str(info["termination"]).encode()
    if hasattr(world, "sim"):
        return seen + _bodies(world.sim)
    state = [] if world.reactive is None else [getattr(world.reactive.state, f.name) for f in fields(ReactiveState)]
    return seen + _digest(world.ego_xy_m, world.ego_velocity_mps, world.robot_model.heading, *state)


def env_digests() -> dict[str, str]:
    """Each simulated env driven STEPS steps toward its goal (a new episode, seed + 1, after each end)."""
    import gymnasium as gym

    import envs

    out = {}
    for env_id in (*(f"STCrowd-Sim{s}-v{envs.SIM_VERSION}" for s in envs.SIM_LAYOUTS + envs.REPLAY_SCENES),
                   *envs.ENCOUNTER_IDS):
        env = gym.make(env_id, predictor="cvm")
        digest, seed = hashlib.sha256(), SEED
        obs, _ = env.reset(seed=seed)
        for _ in range(STEPS):
            obs, _, terminated, truncated, _ = env.step(_drive(obs))
            digest.update(_bodies(env.unwrapped.sim))
            if terminated or truncated:
                seed += 1
                obs, _ = env.reset(seed=seed)
        out[env_id] = digest.hexdigest()
    return out


def crowd_digests() -> dict[str, str]:
    """Bare crowds of the layouts no env uses and of the social-force model, STEPS steps with the ego standing."""
    from st_sim.sim import CrowdConfig, CrowdSim, EgoConfig, SocialForceConfig
    from st_sim.sim.layouts import make_layout

    out = {}
    for name, layout, cfg in (("corner", "corner", CrowdConfig()),
                              ("periodic_corridor", "periodic_corridor", CrowdConfig()),
                              ("crossing/social_force", "crossing", CrowdConfig(steering=SocialForceConfig()))):
        sim = CrowdSim(make_layout(layout), cfg, np.random.default_rng(SEED), ego=EgoConfig())
        digest = hashlib.sha256()
        for _ in range(STEPS):
            sim.step(None)
            digest.update(_bodies(sim))
        out[name] = digest.hexdigest()
    return out


def episode_digests() -> dict[str, str]:
    """One navigation episode of each of EPISODES with the ORCA planner (no predictions)."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ids)
    from st_sim.apps.navigation.planners import make_planner
    from st_sim.apps.navigation.world import world_of

    out = {}
    for env_id, seed in EPISODES.items():
        env = gym.make(env_id, predictor="cvm")
        planner = make_planner("orca", world_of(env), "none")
        obs, _ = env.reset(seed=seed)
        planner.reset()
        digest, done = hashlib.sha256(), False
        while not done:
            action = planner.act(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            digest.update(_bodies(env.unwrapped.sim) + _digest(action, [reward]) + str(info["termination"]).encode())
            done = terminated or truncated
        out[f"orca/{env_id}"] = digest.hexdigest()
    return out


def robot_digests() -> tuple[dict[str, str], dict[str, dict[str, int]]]:
    """Each robot kind through each of ROBOT_WORLDS, ROBOT_STEPS steps of over-limit commands, and through each of
    MPC_WORLDS, MPC_STEPS steps of the MPC's commands (a new episode, seed + 1, after each end): the digests, and
    per case how many steps had a command beyond the robot's limits and how many had reactive pedestrians off their
    logs."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ids)
    from st_sim.apps.navigation.planners import make_planner
    from st_sim.apps.navigation.world import world_of
    from st_sim.sim.robot import ROBOT_KINDS, limited_command

    digests, counts = {}, {}
    for kind in ROBOT_KINDS:
        for world, (env_id, keywords) in ROBOT_WORLDS.items():
            env = gym.make(env_id, predictor="cvm", robot=kind, **keywords)
            drives = [("over-limit", ROBOT_STEPS, None)]
            if world in MPC_WORLDS:
                drives.append(("mpc", MPC_STEPS, make_planner("mpc", world_of(env), "cvm")))
            for drive, steps, planner in drives:
                case = f"{drive}/{kind}/{world}"
                digest, seed, counts[case] = hashlib.sha256(), SEED, {"over_limit": 0, "off_log": 0}
                obs, _ = env.reset(seed=seed)
                for _ in range(steps):
                    action = _over_limit(env, obs) if planner is None else planner.act(obs)
                    obs, reward, terminated, truncated, info = env.step(action)
                    digest.update(_digest(action) + _world(env, obs, reward, info))
                    counts[case]["over_limit"] += not np.array_equal(limited_command(env.unwrapped.robot, action)[0],
                                                                     action.astype(np.float64))
                    counts[case]["off_log"] += info.get("off_log", 0) > 0
                    if terminated or truncated:
                        seed += 1
                        obs, _ = env.reset(seed=seed)
                        if planner is not None:
                            planner.reset()
                digests[case] = digest.hexdigest()
    return digests, counts


def sensing_digests() -> tuple[dict[str, str], dict[str, dict[str, int]]]:
    """The holonomic robot through each of ROBOT_WORLDS, ROBOT_STEPS steps toward its goal, seeing with the
    ``realistic`` sensor and tracker: the digests (the world's as ``robot_digests`` takes them, and the detections and
    tracks the sensor made), and per case how many steps had detections and how many had tracks."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ids)

    digests, counts = {}, {}
    for world, (env_id, keywords) in ROBOT_WORLDS.items():
        env = gym.make(env_id, predictor="cvm", sensing="realistic", **keywords)
        case = f"sensing/realistic/{world}"
        digest, counts[case] = hashlib.sha256(), {"detected": 0, "tracked": 0}
        obs, _ = env.reset(seed=SEED)
        for _ in range(ROBOT_STEPS):
            obs, reward, terminated, truncated, info = env.step(_drive(obs))
            seen = info["perception"]
            digest.update(_world(env, obs, reward, info) + _digest(seen["detected_xy_m"], seen["track_xy_m"]))
            counts[case]["detected"] += len(seen["detected_xy_m"]) > 0
            counts[case]["tracked"] += len(seen["track_xy_m"]) > 0
            if terminated or truncated:
                obs, _ = env.reset(seed=SEED + 1)
        digests[case] = digest.hexdigest()
    return digests, counts


def _blas_core() -> str:
    """The kernel family of the OpenBLAS numpy loaded (its ``get_corename``), "unknown" where none is found."""
    try:
        maps = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return "unknown"
    for path in sorted({line.split()[-1] for line in maps if "openblas" in line.rsplit("/", 1)[-1].lower()}):
        library = ctypes.CDLL(path)
        for name in ("scipy_openblas_get_corename64_", "openblas_get_corename64_", "openblas_get_corename"):
            get = getattr(library, name, None)
            if get is not None:
                get.restype = ctypes.c_char_p
                return get().decode()
    return "unknown"


def dispatch() -> dict[str, str]:
    """What each library runs in this process: numpy's enabled dispatch targets, OpenBLAS's core, libm's results
    (glibc reports no choice: a digest of sines, cosines and exponentials of fixed arguments), torch's capability and
    the CPU numba compiles for."""
    import torch
    from numba.core.registry import cpu_target
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    arguments = np.random.default_rng(SEED).uniform(-50.0, 50.0, 4096).tolist()
    libm = [f(x) for x in arguments for f in (math.sin, math.cos, math.exp)]
    return {"numpy": " ".join(f for f in __cpu_dispatch__ if __cpu_features__.get(f)),
            "openblas": _blas_core(),
            "libm": hashlib.sha256(np.array(libm).tobytes()).hexdigest()[:16],
            "torch": torch.backends.cpu.get_cpu_capability(),
            "numba": cpu_target.target_context.codegen().magic_tuple()[1]}


def variants() -> dict[str, tuple[dict[str, str], tuple[str, ...]]]:
    """Name -> (the environment variables of an emulated CPU, the fields of ``dispatch`` they mean to change); the
    default dispatch sets none. numba's comes first, beside the default: where no kernel is cached for a generic CPU
    yet, it compiles the reactive kernels anew (about a minute of one core)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    found = [feature for feature in __cpu_dispatch__ if __cpu_features__.get(feature)]
    out = {"numba generic": ({"NUMBA_CPU_NAME": "generic"}, ("numba",)),
           "default": ({}, ()),
           "numpy without AVX-512": ({"NPY_DISABLE_CPU_FEATURES": " ".join(f for f in found if f in X86_AVX512)},
                                     ("numpy",)),
           "numpy at its baseline": ({"NPY_DISABLE_CPU_FEATURES": " ".join(found)}, ("numpy",)),
           "torch avx2": ({"ATEN_CPU_CAPABILITY": "avx2"}, ("torch",)),
           "torch default": ({"ATEN_CPU_CAPABILITY": "default"}, ("torch",))}
    if platform.machine() in ("x86_64", "AMD64"):
        out["libm and BLAS without AVX2 and FMA"] = (
            {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F", "OPENBLAS_CORETYPE": "Nehalem"},
            ("libm", "openblas"))
    return out


def _run(variables: dict[str, str]) -> dict:
    """The child's report (``dispatch``, ``counts``, ``digests``) under ``variables``."""
    environment = {**os.environ, "OMP_NUM_THREADS": "1", **variables}
    done = subprocess.run([sys.executable, __file__], cwd=ROOT, env=environment, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, f"{variables}: the child failed:\n{done.stderr[-3000:]}"
    return json.loads(done.stdout.splitlines()[-1])


def _took_effect(named: dict, results: dict) -> dict[str, str]:
    """Per variant, what it changed of the default's ``dispatch`` ("" where nothing: it compared the default with
    itself)."""
    reference = results["default"]["dispatch"]
    return {name: "; ".join(f"{field} {reference[field]!r} -> {results[name]['dispatch'][field]!r}"
                            for field in targets if results[name]["dispatch"][field] != reference[field])
            for name, (_, targets) in named.items() if name != "default"}


def test_episodes_are_the_same_on_every_cpu(record_property):
    named = variants()
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(named, pool.map(_run, (variables for variables, _ in named.values())), strict=True))
    changed = _took_effect(named, results)
    report = "\n".join(f"{name}: {what or 'no effect on this CPU (the default compared with itself)'}"
                       for name, what in changed.items())
    print(report)
    record_property("dispatch", report)
    assert any(changed.values()), f"no variant changed any library's dispatch on this CPU:\n{report}"
    reference, counts = results["default"]["digests"], results["default"]["counts"]
    assert len(reference) == 13 + 3 + len(EPISODES) + 2 * (len(ROBOT_WORLDS) + len(MPC_WORLDS)) + len(ROBOT_WORLDS)
    within = [case for case, count in counts.items() if case.startswith("over-limit") and not count["over_limit"]]
    assert not within, f"over-limit drives whose commands never went beyond the robot's limits: {within}"
    still = [case for case, count in counts.items() if case.startswith("over-limit/") and "reactive" in case
             and not count["off_log"]]
    assert not still, f"reactive replays in which no pedestrian left its log: {still}"
    blind = [case for case, count in counts.items() if case.startswith("sensing/") and not count["tracked"]]
    assert not blind, f"sensing drives in which the tracker never held a track: {blind}"
    differing = {name: sorted(case for case in reference if result["digests"][case] != reference[case])
                 for name, result in results.items()}
    differing = {f"{name} {named[name][0]}": cases for name, cases in differing.items() if cases}
    assert not differing, f"episodes that differ from the default dispatch's:\n{report}\n{differing}"


if __name__ == "__main__":
    digests, counts = robot_digests()
    sensed, sensed_counts = sensing_digests()
    print(json.dumps({"dispatch": dispatch(), "counts": {**counts, **sensed_counts},
                      "digests": {**env_digests(), **crowd_digests(), **episode_digests(), **digests, **sensed}}))
