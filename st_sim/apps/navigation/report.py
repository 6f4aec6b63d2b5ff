"""Navigation results as text: the metric table the command prints, and one markdown row per run."""

from __future__ import annotations

from typing import Any

from st_sim.apps.navigation.metrics import MEANS, RATES

LABELS: dict[str, str] = {
    "success": "success", "collision": "collision (any)", "pedestrian_collision": "  with a pedestrian",
    "wall_collision": "  with a wall", "collision_at_fault": "collision at fault",
    "timeout": "timeout", "time_to_goal_s": "time to goal [s]",
    "path_ratio": "path / straight line", "min_clearance_m": "min distance to pedestrians [m]",
    "discomfort": "discomfort (< 0.2 m)", "jerk_mps3": "jerk [m/s^3]", "off_map": "off-map steps",
    "log_ade_m": "pedestrians off their log [m]",
}
TABLE_COLUMNS: tuple[str, ...] = ("success", "collision", "collision_at_fault", "pedestrian_collision",
                                  "wall_collision", "timeout", "time_to_goal_s", "path_ratio", "min_clearance_m",
                                  "discomfort", "jerk_mps3")


def see_ego_label(value: bool | None) -> str:
    """How the run treated ``pedestrians_see_ego``."""
    return {True: "pedestrians see the robot", False: "invisible robot"}.get(value, "env default")


def summary_text(result: dict[str, Any]) -> str:
    """Plain-text table of a ``run_navigation`` result: every metric with its 95 % interval and count."""
    n = len(result["episodes"])
    mode = f", {result['pedestrians']} pedestrians" if result.get("pedestrians") else ""
    lines = [f"{result['env_id']}{mode}  planner {result['policy']}  predictor {result['predictor']}  episodes {n} "
             f"(seeds {result['seed']}..{result['seed'] + n - 1})  [{see_ego_label(result['pedestrians_see_ego'])}]",
             f"{'metric':<32}{'value':>9}   95 % CI            n"]
    for name in (*RATES, *MEANS):
        cell = result["summary"][name]
        lines.append(f"{LABELS[name]:<32}{cell['value']:>9.3f}   [{cell['low']:.3f}, {cell['high']:.3f}]"
                     f"{cell['n']:>6}")
    lines.append(f"planner decisions per second: {result['decisions_per_s']:.1f}")
    return "\n".join(lines)


def markdown_row(result: dict[str, Any]) -> str:
    """One markdown table row: planner, predictor, then TABLE_COLUMNS as ``value [low, high]``."""
    cells = []
    for name in TABLE_COLUMNS:
        cell = result["summary"][name]
        digits = 3 if name in RATES else 2
        cells.append(f"{cell['value']:.{digits}f} [{cell['low']:.{digits}f}, {cell['high']:.{digits}f}]")
    return f"| {result['policy']} | {result['predictor']} | {len(result['episodes'])} | " + " | ".join(cells) + " |"


def markdown_header() -> str:
    """Header of the ``markdown_row`` table."""
    names = " | ".join(LABELS[name].strip() for name in TABLE_COLUMNS)
    return f"| planner | predictor | episodes | {names} |\n|" + "---|" * (3 + len(TABLE_COLUMNS))
