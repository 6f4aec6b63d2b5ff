"""How close simulated crowds walk to ETH/UCY: speeds per 0.4 s step and nearest-neighbour distances.

Rows ``real``: the recordings of each scene's test set (``raw/all_data``), read with ``replays``.
Rows ``sim``: CrowdSim in the three synthetic layouts (default CrowdConfig) and in the five real scenes'
geometry with the population cap set to the recording's mean number of people per frame; the first
``--warmup`` steps are dropped. Speeds are displacements between consecutive frames of the same person
divided by 0.4 s; the nearest-neighbour distance is averaged over every person of every frame with at
least two people.

    OMP_NUM_THREADS=1 STCROWD_DATA=... python benchmarks/realism.py [--steps 300] [--seed 0]
"""

from __future__ import annotations

import argparse

import numpy as np

from replays import SCENES, STEP_S, data_root, load_scene, read_recording
from replays.constants import FRAME_STRIDE
from replays.recording import Recording
from st_sim.sim import CrowdConfig, CrowdSim, layout_from_scene, make_layout
from st_sim.sim.diagnostics import nearest_neighbour_m, step_speeds_mps

SYNTHETIC = ("crossing", "corridor", "bottleneck")
HEADER = (f"{'crowd':<12}{'source':<7}{'people/frame':>13}{'mean':>7}{'std':>7}{'q25':>7}{'q50':>7}{'q75':>7}"
          f"{'NN m':>8}")


def crowd_stats(rec: Recording) -> dict[str, float]:
    """Speed distribution [m/s], mean people per frame and mean nearest-neighbour distance [m] of a recording."""
    speeds = step_speeds_mps(rec.frame, rec.agent, rec.xy_m, FRAME_STRIDE, STEP_S)
    order = np.argsort(rec.frame, kind="stable")
    frame, xy = rec.frame[order], rec.xy_m[order]
    starts = np.flatnonzero(np.r_[True, frame[1:] != frame[:-1]])
    groups = np.split(xy, starts[1:])
    nn = np.concatenate([nearest_neighbour_m(g) for g in groups])
    q25, q50, q75 = np.percentile(speeds, [25, 50, 75])
    return {"people": float(np.mean([len(g) for g in groups])), "mean": float(speeds.mean()),
            "std": float(speeds.std()), "q25": q25, "q50": q50, "q75": q75,
            "nn": float(nn.mean()) if nn.size else float("nan")}


def row(name: str, source: str, stats: dict[str, float]) -> str:
    return (f"{name:<12}{source:<7}{stats['people']:>13.1f}{stats['mean']:>7.2f}{stats['std']:>7.2f}"
            f"{stats['q25']:>7.2f}{stats['q50']:>7.2f}{stats['q75']:>7.2f}{stats['nn']:>8.2f}")


def simulated(layout_name: str, cfg: CrowdConfig, steps: int, warmup: int, seed: int) -> Recording:
    """A CrowdSim run's recording without its first warmup steps."""
    layout = make_layout(layout_name) if layout_name in SYNTHETIC else layout_from_scene(load_scene(layout_name))
    sim = CrowdSim(layout, cfg, np.random.default_rng(seed))
    for _ in range(warmup + steps):
        sim.step()
    rec = sim.history()
    keep = rec.frame >= warmup * FRAME_STRIDE
    return Recording(rec.name, rec.frame[keep], rec.agent[keep], rec.xy_m[keep])


def real_recordings(scene: str) -> Recording:
    """The scene's test recordings, agent ids made distinct across files, frames kept apart."""
    root = data_root()
    parts = [read_recording(root / "raw" / "all_data" / f"{name}.txt") for name in SCENES[scene].recordings]
    frame_offset, agent_offset, frames, agents, xys = 0, 0, [], [], []
    for rec in parts:
        frames.append(rec.frame + frame_offset)
        agents.append(rec.agent + agent_offset)
        xys.append(rec.xy_m)
        frame_offset += int(rec.frame.max()) + 10 * FRAME_STRIDE
        agent_offset += int(rec.agent.max()) + 1
    return Recording(scene, np.concatenate(frames), np.concatenate(agents), np.concatenate(xys))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300, help="recorded 0.4 s steps per simulation (default: 300)")
    parser.add_argument("--warmup", type=int, default=50, help="steps dropped before recording (default: 50)")
    parser.add_argument("--seed", type=int, default=0, help="crowd seed (default: 0)")
    args = parser.parse_args(argv)

    print("speed per 0.4 s step [m/s] and mean nearest-neighbour distance [m]")
    print(HEADER)
    for name in SYNTHETIC:
        print(row(name, "sim", crowd_stats(simulated(name, CrowdConfig(), args.steps, args.warmup, args.seed))),
              flush=True)
    for scene in SCENES:
        real = crowd_stats(real_recordings(scene))
        print(row(scene, "real", real), flush=True)
        cfg = CrowdConfig(max_pedestrians=max(2, round(real["people"])))
        print(row(scene, "sim", crowd_stats(simulated(scene, cfg, args.steps, args.warmup, args.seed))), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
