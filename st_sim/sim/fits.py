"""Parameters fitted by scripts and committed as small tables of numbers (no data).

- ``steering_fit.json``: steering parameters of both models, written by ``benchmarks/fit_steering.py``
  (fundamental diagram, counter-flow and bottleneck targets); the steering configs take their defaults
  from it.
- ``population_fit.json``: per-scene walking-speed distribution, standing and group shares, written by
  ``benchmarks/fit_populations.py`` from the ETH/UCY recordings; ``PopulationConfig.fitted`` reads it.
"""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

FIT_DIR = Path(__file__).parent
STEERING_FIT = FIT_DIR / "steering_fit.json"
POPULATION_FIT = FIT_DIR / "population_fit.json"


@cache
def load_fit(path: Path) -> dict[str, Any]:
    """The JSON table at path (read once per process)."""
    return json.loads(Path(path).read_text())


def steering_defaults(model: str) -> dict[str, float]:
    """Fitted parameters of a steering model ("speed_model" or "social_force"), by config field name."""
    return dict(load_fit(STEERING_FIT)["models"][model]["params"])
