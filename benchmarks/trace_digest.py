"""What the simulator and the predictor produce, kept to compare two commits: run it at each, then compare.

    git worktree add ../base 433f206
    (cd ../base && PYTHONPATH=. python "$OLDPWD/benchmarks/trace_digest.py" --out "$OLDPWD/runs/digest-base")
    python benchmarks/trace_digest.py --out runs/digest-head
    python benchmarks/trace_digest.py --compare runs/digest-base runs/digest-head

Crowds: five crowds of each layout (the crossing, corridor and bottleneck, and the ZARA1, UNIV and HOTEL geometry with
their fitted populations, with and without an ego robot driven at random), stepped 150 steps, each third step alone
and the others together (``step_crowds``); one SHA-256 line per crowd and step over ids, positions, velocities,
groups, who stands, goals, the ego's position, nearest distance and contact. Forecasts: the shipped stochastic
UNIV and ETH models and the universal one on up to 3,000 test agents of their scene (futures and anchors), and the
observations of a vector env of six SimCrossing-v1 sub-envs over 100 steps. ``--compare`` prints how many crowd lines
differ and the largest difference of every forecast array [m].
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

import gymnasium as gym
import numpy as np

import envs  # noqa: F401  (registers the ids)
import predictor
from envs.common.layouts import build_layout
from replays import load_scene, load_windows
from replays.atomic import atomic_path, write_text_atomic
from st_sim.sim import CrowdConfig, CrowdSim, EgoConfig, PopulationConfig
from st_sim.sim.crowd import step_crowds

CROWDS, FORECASTS = "crowds.txt", "forecasts.npz"  # what --out writes
LAYOUTS = ("crossing", "corridor", "bottleneck", "zara1", "univ", "hotel")  # the last three: fitted populations


def crowd_lines(steps: int) -> list[str]:
    """One digest line per crowd and step (see the module docstring)."""
    lines = []
    for name in LAYOUTS:
        layout = build_layout(name)
        cfg = CrowdConfig(population=PopulationConfig.fitted(name)) if name in ("zara1", "univ", "hotel") else \
            CrowdConfig()
        for ego in (False, True):
            sims = [CrowdSim(layout, cfg, np.random.default_rng(100 + i), ego=EgoConfig() if ego else None)
                    for i in range(5)]
            rng = np.random.default_rng(7)
            for t in range(steps):
                velocities = [rng.uniform(-1.5, 1.5, 2) if ego else None for _ in sims]
                if t % 3 == 0:
                    for sim, velocity in zip(sims, velocities, strict=True):
                        sim.step(velocity)
                else:
                    step_crowds(sims, velocities)
                lines += [f"{name} ego={ego} step {t} crowd {k} {crowd_digest(sim)}" for k, sim in enumerate(sims)]
    return lines


def crowd_digest(sim: CrowdSim) -> str:
    digest = hashlib.sha256()
    for array in (sim.ids, sim.positions_m, sim.velocities_mps, sim.groups, sim.standing, sim.goals_m):
        digest.update(np.ascontiguousarray(array).tobytes())
    if sim.ego_cfg is not None:
        contact = sim.ego_contact
        digest.update(sim.ego_position_m.tobytes() + np.float64(sim.ego_nearest_m).tobytes())
        digest.update(repr(None if contact is None else (contact.time_s, contact.pedestrian_ids.tolist(),
                                                         contact.pedestrians_xy_m.tolist())).encode())
    return digest.hexdigest()[:16]


def forecasts() -> dict[str, np.ndarray]:
    """The forecasts of three shipped models on test windows, and a vector env's observations, by name."""
    out = {}
    for name, scene_name in (("stochastic/univ", "univ"), ("stochastic/eth", "eth"), ("universal", "zara1")):
        windows = load_windows("stochastic", scene_name, "test")
        n = min(3000, len(windows.obs))
        detail = predictor.load_pretrained(name).predict_detailed(windows.obs[:n], windows.group[:n],
                                                                  load_scene(scene_name), 20)
        for label in ("futures", "prototype_anchors", "adapted_anchors"):
            out[f"{name} {label}"] = getattr(detail, label)
    vec = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=6, vectorization_mode="vector_entry_point",
                       predictor="singular", autoreset_mode="SameStep", max_episode_steps=40)
    obs, _ = vec.reset(seed=3)
    rng = np.random.default_rng(0)
    steps = []
    for _ in range(100):
        obs, reward, *_ = vec.step(rng.uniform(-1.5, 1.5, (6, 2)).astype(np.float32))
        steps.append((obs["history"], obs["futures"], reward))
    for i, name in enumerate(("history", "futures", "reward")):
        out[f"vector env {name}"] = np.stack([step[i] for step in steps])
    return out


def compare(base: Path, head: Path) -> None:
    """Print how the two runs' crowds and forecasts differ."""
    lines = [(base / CROWDS).read_text().splitlines(), (head / CROWDS).read_text().splitlines()]
    differing = sum(a != b for a, b in zip(*lines, strict=True))
    print(f"crowd lines: {len(lines[0])}, differing: {differing}")
    with np.load(base / FORECASTS) as a, np.load(head / FORECASTS) as b:
        for name in a.files:
            print(f"{name}: largest difference {np.abs(a[name].astype(np.float64) - b[name]).max():.3g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=150, help="steps of every crowd (default: 150)")
    parser.add_argument("--out", type=Path, help="write the crowds' digest and the forecasts into this folder")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("BASE", "HEAD"), help="compare two --out folders")
    args = parser.parse_args()
    if args.compare:
        compare(*args.compare)
        return
    if args.out is None:
        parser.error("give --out DIR, or --compare BASE HEAD")
    args.out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out / CROWDS, "\n".join(crowd_lines(args.steps)) + "\n")
    with atomic_path(args.out / FORECASTS) as tmp, open(tmp, "wb") as file:
        np.savez(file, **forecasts())
    print(f"wrote {args.out / CROWDS} and {args.out / FORECASTS}")


if __name__ == "__main__":
    main()
