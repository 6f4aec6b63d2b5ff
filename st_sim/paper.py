"""The paper's published numbers (SingularTrajectory, CVPR 2024), kept in ``paper_results.json``."""

from __future__ import annotations

import json
from functools import cache
from importlib import resources


@cache
def paper_results() -> dict[str, dict[str, list[float]]]:
    """task -> scene (or domain pair, or "avg") -> [ADE, FDE] in metres."""
    data = json.loads(resources.files("st_sim").joinpath("paper_results.json").read_text())
    return {task: table for task, table in data.items() if not task.startswith("_")}


def paper_numbers(task: str, scene: str) -> tuple[float, float] | None:
    """The paper's (ADE, FDE) for a task and scene or pair (``"A2B"``), or None if it reports none."""
    row = paper_results().get(task, {}).get(scene)
    return (row[0], row[1]) if row else None
