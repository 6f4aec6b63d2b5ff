"""The same simulated crowds on every CPU: every simulated layout and encounter, stepped in fresh processes under the
default dispatch and under emulated older CPUs, moves every body to the same bits.

numpy, OpenBLAS, glibc's libm, torch and numba each pick their kernels for the CPU at run time; the variables below
make them pick those of an older CPU (they are read at import, so each variant is a child process):

- ``NPY_DISABLE_CPU_FEATURES``: numpy without AVX-512, and numpy at its baseline (no AVX2 either on x86-64); only
  the dispatched features that numpy found on this machine are named (numpy refuses a baseline one);
- ``GLIBC_TUNABLES`` and ``OPENBLAS_CORETYPE`` (x86-64): libm's and OpenBLAS's kernels without AVX2 and FMA;
- ``ATEN_CPU_CAPABILITY`` (avx2, default) and ``NUMBA_CPU_NAME=generic``.

A child (this file run as a script) steps the simulated envs with a fixed drive to the goal, a few bare crowds (the
other layouts, the social-force model) and short navigation episodes with the ORCA planner, and prints one SHA-256
digest of every body's position and velocity (float64 bytes) per case. Under ``--perturb`` the children run
unperturbed: the test compares runs with each other, not with stored digests.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

STEPS = 100  # env steps per simulated env, crowd steps per bare crowd
SEED = 11
EPISODES = {"STCrowd-SimCrossing-v1": 1863924143, "STCrowd-SimBottleneck-v1": 1102676120,
            "STCrowd-SimGroup-v1": 1667152401}
"""the navigation episodes: env id -> reset seed (the suite's first val seeds)"""
X86_AVX512 = ("X86_V4", "AVX512_ICL", "AVX512_SPR")  # numpy's dispatch targets that need AVX-512
ROOT = Path(__file__).resolve().parents[1]


def _digest(*arrays: np.ndarray) -> bytes:
    return b"".join(np.ascontiguousarray(a, np.float64).tobytes() for a in arrays)


def _drive(obs: dict[str, np.ndarray]) -> np.ndarray:
    """1 m/s toward the goal (+, *, sqrt: the action itself is the same everywhere)."""
    x, y = (float(v) for v in obs["ego"][4:6] - obs["ego"][0:2])
    return np.array([x, y], np.float32) / np.float32(max(math.sqrt(x * x + y * y), 1e-9))


def _bodies(sim) -> bytes:
    """Every body's state: pedestrians' ids, positions and velocities, then the ego's."""
    ego = [] if sim.ego_position_m is None else [sim.ego_position_m, sim.ego_velocity_mps]
    return _digest(sim.ids, sim.positions_m, sim.velocities_mps, *ego)


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


def variants() -> dict[str, dict[str, str]]:
    """Name -> the environment variables of each emulated CPU (the default dispatch: no variables)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    found = [feature for feature in __cpu_dispatch__ if __cpu_features__.get(feature)]
    out = {"default": {},
           "numpy without AVX-512": {"NPY_DISABLE_CPU_FEATURES": " ".join(f for f in found if f in X86_AVX512)},
           "numpy at its baseline": {"NPY_DISABLE_CPU_FEATURES": " ".join(found)},
           "torch avx2": {"ATEN_CPU_CAPABILITY": "avx2"},
           "torch default": {"ATEN_CPU_CAPABILITY": "default"},
           "numba generic": {"NUMBA_CPU_NAME": "generic"}}
    if platform.machine() in ("x86_64", "AMD64"):
        out["libm and BLAS without AVX2 and FMA"] = {
            "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F", "OPENBLAS_CORETYPE": "Nehalem"}
    return out


def _run(variables: dict[str, str]) -> dict[str, str]:
    environment = {**os.environ, "OMP_NUM_THREADS": "1", **variables}
    done = subprocess.run([sys.executable, __file__], cwd=ROOT, env=environment, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, f"{variables}: the child failed:\n{done.stderr[-3000:]}"
    return json.loads(done.stdout.splitlines()[-1])


def test_simulated_crowds_are_the_same_on_every_cpu():
    named = variants()
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(named, pool.map(_run, named.values()), strict=True))
    reference = results["default"]
    assert len(reference) == 13 + 3 + len(EPISODES)
    differing = {name: sorted(case for case in reference if digests[case] != reference[case])
                 for name, digests in results.items()}
    differing = {f"{name} {named[name]}": cases for name, cases in differing.items() if cases}
    assert not differing, f"crowds that differ from the default dispatch's: {differing}"


if __name__ == "__main__":
    print(json.dumps({**env_digests(), **crowd_digests(), **episode_digests()}))
