"""How close simulated crowds walk to ETH/UCY: speed and nearest-neighbour distributions per scene, with the
noise floor of the recordings themselves.

Per scene: ``real`` is the scene's test recording (``raw/all_data``); ``sim`` is CrowdSim in the scene's
geometry (``layout_from_scene``) with the population fitted to that recording (``PopulationConfig.fitted``,
``benchmarks/fit_populations.py``), starting with the recording's mean number of people per frame, new people
arriving at the recording's rate (people per second, shared evenly by the layout's gates; the population cap is
twice the recorded head count, so that the head count comes from arrivals and walking times), recorded for
--steps steps after --warmup. Speeds are displacements between consecutive 0.4 s frames of the same
person; nearest-neighbour distances are taken in every frame with at least two people. W is the 1-D Wasserstein
distance between the simulated and the real distribution; the floor is W between the first and the second half
(by frame) of each real recording, the distance two samples of the same scene already have. A scene passes when
W(speed) <= 2 x floor.

    OMP_NUM_THREADS=1 STCROWD_DATA=... python benchmarks/realism.py [--steps 500] [--seed 0]
"""

from __future__ import annotations

import argparse

import numpy as np

from replays import SCENE_NAMES, load_scene
from replays.constants import FRAME_STRIDE, STEP_S
from replays.recording import Recording
from st_sim.sim import CrowdConfig, CrowdSim, PopulationConfig, layout_from_scene
from st_sim.sim.crowd_stats import (
    STAND_MPS,
    Steps,
    frame_nearest_neighbours_m,
    halves,
    merged,
    people_per_frame,
    scene_recordings,
)
from st_sim.sim.measures import speed_distance_mps

PASS_FACTOR = 2.0  # a scene passes when W(speed) is at most this multiple of the real halves' floor
HEADER = ("| scene | people/frame real / sim | mean speed real / sim (m/s) | standing real / sim | W speed (m/s) "
          "| floor | W / floor | pass | mean NN real / sim (m) | W NN (m) | floor NN |")


def arrivals_per_s(parts: list[Recording]) -> float:
    """People per second who appear in the recordings (distinct agents over the annotated time)."""
    return sum(len(np.unique(r.agent)) for r in parts) / sum(len(np.unique(r.frame)) * STEP_S for r in parts)


def simulated(scene: str, people: float, arrivals_hz: float, steps: int, warmup: int, seed: int) -> Recording:
    """CrowdSim in the scene's geometry with its fitted population, head count and arrival rate [1/s], without
    the warm-up steps."""
    layout = layout_from_scene(load_scene(scene))
    cfg = CrowdConfig(population=PopulationConfig.fitted(scene), max_pedestrians=max(2, round(2 * people)),
                      spawn_rate_hz=arrivals_hz / len(layout.entries))
    sim = CrowdSim(layout, cfg, np.random.default_rng(seed), n_initial=max(1, round(people)))
    for _ in range(warmup + steps):
        sim.step()
    rec = sim.history()
    keep = rec.frame >= warmup * FRAME_STRIDE
    return Recording(rec.name, rec.frame[keep], rec.agent[keep], rec.xy_m[keep])


def compare(scene: str, steps: int, warmup: int, seed: int) -> tuple[str, bool]:
    """One table row for a scene, and whether it passes."""
    parts = scene_recordings(scene)
    real = merged(parts, scene)
    first = merged([halves(r)[0] for r in parts], "first")
    second = merged([halves(r)[1] for r in parts], "second")
    sim = simulated(scene, people_per_frame(real), arrivals_per_s(parts), steps, warmup, seed)
    speed = {name: Steps.of(rec).speed_mps for name, rec in (("real", real), ("sim", sim), ("a", first),
                                                             ("b", second))}
    nn = {name: frame_nearest_neighbours_m(rec) for name, rec in (("real", real), ("sim", sim), ("a", first),
                                                                  ("b", second))}
    w_speed, floor = speed_distance_mps(speed["sim"], speed["real"]), speed_distance_mps(speed["a"], speed["b"])
    w_nn, floor_nn = speed_distance_mps(nn["sim"], nn["real"]), speed_distance_mps(nn["a"], nn["b"])
    ok = w_speed <= PASS_FACTOR * floor
    row = (f"| {scene} | {people_per_frame(real):.1f} / {people_per_frame(sim):.1f} "
           f"| {speed['real'].mean():.2f} / {speed['sim'].mean():.2f} "
           f"| {np.mean(speed['real'] < STAND_MPS):.2f} / {np.mean(speed['sim'] < STAND_MPS):.2f} "
           f"| {w_speed:.3f} | {floor:.3f} | {w_speed / floor:.1f} | {'yes' if ok else 'no'} "
           f"| {nn['real'].mean():.2f} / {nn['sim'].mean():.2f} | {w_nn:.3f} | {floor_nn:.3f} |")
    return row, ok


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=500, help="recorded 0.4 s steps per simulation (default: 500)")
    parser.add_argument("--warmup", type=int, default=100, help="steps dropped before recording (default: 100)")
    parser.add_argument("--seed", type=int, default=0, help="crowd seed (default: 0)")
    args = parser.parse_args(argv)

    print(f"speeds per 0.4 s step, nearest-neighbour (NN) distances; W = 1-D Wasserstein distance; pass: W <= "
          f"{PASS_FACTOR:g} x floor; standing = share of steps slower than {STAND_MPS} m/s")
    print(HEADER)
    print("|" + "---|" * HEADER.count(" |"))
    passed = 0
    for scene in SCENE_NAMES:
        row, ok = compare(scene, args.steps, args.warmup, args.seed)
        passed += ok
        print(row, flush=True)
    print(f"{passed} of {len(SCENE_NAMES)} scenes within {PASS_FACTOR:g} x the noise floor")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
