"""Fit each ETH/UCY scene's population (walking speeds, people standing, groups) from its recording.

Per scene, from the test recordings (``raw/all_data``; statistics from ``st_sim.sim.crowd_stats``):

- walkers' preferred speed: mean and standard deviation of the people's median walking speed (steps outside
  standing spells; people with at least 3 such steps), clipped to its 1st-99th percentiles;
- standing_share: share of person-steps inside standing spells (3 or more steps slower than 0.25 m/s);
  dwell_mean_s: mean spell length (spells cut by the recording's ends count as they are);
- group_share: share of walkers who walk with somebody (on average closer than 1.2 m, velocities on average
  less than 0.3 m/s apart, over 2 s or more); triple_share: share of such groups with three or more.

The numbers (no data) go to ``st_sim/sim/population_fit.json``, which ``PopulationConfig.fitted(scene)`` reads.

    STCROWD_DATA=... python benchmarks/fit_populations.py
"""

from __future__ import annotations

import argparse
import datetime
from pathlib import Path

import numpy as np

from replays import SCENE_NAMES, strict_json
from replays.constants import STEP_S
from st_sim.sim import PopulationConfig
from st_sim.sim.crowd_stats import (
    Steps,
    merged,
    people_per_frame,
    scene_recordings,
    standing_steps,
    walker_speeds_mps,
    walking_groups,
)
from st_sim.sim.fits import POPULATION_FIT


def fit_scene(scene: str) -> tuple[dict, dict]:
    """PopulationConfig fields fitted to a scene, and the recording's counts they came from."""
    rec = merged(scene_recordings(scene), scene)
    steps = Steps.of(rec)
    standing, spells = standing_steps(steps)
    walkers = walker_speeds_mps(steps, standing)
    group_share, triple_share = walking_groups(steps, standing)
    low, high = np.percentile(walkers, [1, 99])
    params = {"speed_mean_mps": round(float(walkers.mean()), 3), "speed_std_mps": round(float(walkers.std()), 3),
              "speed_range_mps": [round(float(low), 3), round(float(high), 3)],
              "standing_share": round(float(standing.mean()), 3),
              "dwell_mean_s": round(float(spells.mean() * STEP_S) if spells.size else 0.4, 2),
              "group_share": round(group_share, 3), "triple_share": round(triple_share, 3)}
    PopulationConfig(**{**params, "speed_range_mps": tuple(params["speed_range_mps"])})  # checks the ranges
    counts = {"steps": len(steps.speed_mps), "walkers": len(walkers), "standing_spells": len(spells),
              "people_per_frame": round(people_per_frame(rec), 2)}
    return params, counts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=POPULATION_FIT, help=f"table to write (default: {POPULATION_FIT})")
    args = parser.parse_args(argv)
    table = {"fitted_by": "benchmarks/fit_populations.py", "date": datetime.date.today().isoformat(), "scenes": {}}
    for scene in SCENE_NAMES:
        params, counts = fit_scene(scene)
        table["scenes"][scene] = {"params": params, "from": counts}
        print(scene, params, counts, flush=True)
    args.out.write_text(strict_json.dumps(table, indent=2) + "\n")
    print(f"written to {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
