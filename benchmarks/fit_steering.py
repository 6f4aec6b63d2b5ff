"""Fit the steering parameters of a model to the validation targets and write them to steering_fit.json.

Objective (lower is better), every scenario from ``st_sim.sim.validation`` with seed 0 (common random numbers,
so the objective is deterministic):

- fundamental diagram, periodic 20 m x 4 m corridor at 0.5, 1, 1.5, 2 and 3 /m^2: squared relative error to
  Weidmann's speed, plus 5 x the squared excess beyond the +-20 % band;
- gridlock: (0.05 - speed) / 0.05 at 4 /m^2 when slower than 0.05 m/s;
- counter-flow corridor with 200 pedestrians: squared shortfall below 0.8 m/s (relative) and below a lane
  index of 0.5;
- bottleneck of 1.2 m: squared relative distance of the specific flow from the published 1.6-2.0 /(m s).

Search: a scrambled Sobol sample of the parameter box (log scale for the positive ones), then Nelder-Mead from
the best point. The best parameters replace the model's entry in ``st_sim/sim/steering_fit.json`` (the configs'
defaults), with the objective's parts and the date.

    OMP_NUM_THREADS=1 python benchmarks/fit_steering.py --model speed_model --samples 32 --iterations 40
    OMP_NUM_THREADS=1 python benchmarks/fit_steering.py --model social_force --samples 32 --iterations 40
"""

from __future__ import annotations

import argparse
import datetime
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc

from replays import strict_json
from st_sim.sim import CrowdConfig, SocialForceConfig, SpeedModelConfig
from st_sim.sim.fits import STEERING_FIT
from st_sim.sim.measures import SPECIFIC_FLOW_RANGE, weidmann_speed_mps
from st_sim.sim.validation import bottleneck_flow, counterflow, fundamental_diagram

FD_DENSITIES = (0.5, 1.0, 1.5, 2.0, 3.0)  # [1/m^2]
BAND = 0.2  # the fundamental diagram's target band, relative to Weidmann [-]
COUNTERFLOW_SPEED_MPS = 0.8  # target mean speed of the 200-pedestrian counter-flow [m/s]
LANE_TARGET = 0.5  # lane index the counter-flow should reach [-]
BOTTLENECK_DOOR_M = 1.2
SPACES = {  # model: (config class, {field: (low, high)})
    "speed_model": (SpeedModelConfig, {"time_gap_s": (0.2, 1.5), "agent_strength": (0.05, 3.0),
                                       "agent_range_m": (0.05, 1.0), "look_ahead_s": (0.1, 3.0),
                                       "keep_right": (0.05, 2.0), "wall_strength": (0.1, 5.0),
                                       "relaxation_time_s": (0.05, 1.0)}),
    "social_force": (SocialForceConfig, {"relaxation_time_s": (0.2, 1.5), "time_gap_s": (0.2, 1.5),
                                         "agent_strength_mps2": (0.2, 10.0), "agent_range_m": (0.05, 1.0),
                                         "look_ahead_s": (0.1, 3.0), "keep_right_mps2": (0.05, 5.0)}),
}


def objective_parts(steering: SpeedModelConfig | SocialForceConfig) -> dict[str, float]:
    """Every scenario's figure and the loss terms (see the module docstring)."""
    cfg = CrowdConfig(steering=steering)
    parts: dict[str, float] = {}
    loss = 0.0
    for rho in FD_DENSITIES:
        speed = fundamental_diagram(cfg, rho, warmup_steps=30, steps=40).mean_speed_mps
        error = speed / float(weidmann_speed_mps(rho)) - 1.0
        parts[f"fd_{rho:g}_mps"] = speed
        loss += error**2 + 5.0 * max(abs(error) - BAND, 0.0) ** 2
    jam = fundamental_diagram(cfg, 4.0, warmup_steps=30, steps=40).mean_speed_mps
    parts["fd_4_mps"] = jam
    loss += max(0.05 - jam, 0.0) / 0.05
    flow = counterflow(cfg, warmup_steps=30, steps=60)
    parts["counterflow_mps"], parts["counterflow_lanes"] = flow.mean_speed_mps, flow.lane_index
    loss += max(1.0 - flow.mean_speed_mps / COUNTERFLOW_SPEED_MPS, 0.0) ** 2
    loss += max(LANE_TARGET - flow.lane_index, 0.0) ** 2
    specific, _ = bottleneck_flow(cfg, BOTTLENECK_DOOR_M)
    low, high = SPECIFIC_FLOW_RANGE
    parts["bottleneck_per_m_s"] = specific
    loss += (max(low - specific, specific - high, 0.0) / ((low + high) / 2)) ** 2
    parts["loss"] = loss
    return parts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", choices=sorted(SPACES), required=True, help="steering model to fit")
    parser.add_argument("--samples", type=int, default=32, help="Sobol points of the first search (default: 32)")
    parser.add_argument("--iterations", type=int, default=40, help="Nelder-Mead evaluations after it (default: 40)")
    parser.add_argument("--out", type=Path, default=STEERING_FIT, help=f"fit table to update (default: {STEERING_FIT})")
    args = parser.parse_args(argv)

    # search space: log scale for every parameter (all positive)
    kind, box = SPACES[args.model]
    names = list(box)
    log_low, log_high = np.log([box[k][0] for k in names]), np.log([box[k][1] for k in names])
    base = kind()
    history: list[tuple[float, dict[str, float], dict[str, float]]] = []

    def evaluate(z: np.ndarray) -> float:
        params = {k: float(v) for k, v in zip(names, np.exp(np.clip(z, log_low, log_high)), strict=True)}
        started = time.time()
        parts = objective_parts(replace(base, **params))
        history.append((parts["loss"], params, parts))
        print(f"[{len(history):3d}] loss {parts['loss']:.4f}  " + "  ".join(f"{k}={v:.3g}" for k, v in params.items())
              + f"  ({time.time() - started:.0f} s)\n      " + "  ".join(f"{k}={v:.3g}" for k, v in parts.items()),
              flush=True)
        return parts["loss"]

    # search: Sobol sample, then Nelder-Mead from the best
    sobol = qmc.Sobol(len(names), scramble=True, seed=0).random(args.samples)
    starts = log_low + sobol * (log_high - log_low)
    losses = [evaluate(z) for z in starts]
    best_start = starts[int(np.argmin(losses))]
    minimize(evaluate, best_start, method="Nelder-Mead",
             options={"maxfev": args.iterations, "initial_simplex": best_start + np.vstack(
                 [np.zeros(len(names)), 0.25 * np.eye(len(names)) * (log_high - log_low)])})

    # record the best
    loss, params, parts = min(history, key=lambda item: item[0])
    table = json.loads(args.out.read_text()) if args.out.exists() else {"models": {}}
    table["models"][args.model] = {
        "params": params, "figures": parts, "evaluations": len(history),
        "fitted_by": f"benchmarks/fit_steering.py --model {args.model} --samples {args.samples} "
                     f"--iterations {args.iterations}", "date": datetime.date.today().isoformat()}
    args.out.write_text(strict_json.dumps(table, indent=2) + "\n")
    print(f"best loss {loss:.4f}: {params}\nwritten to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
