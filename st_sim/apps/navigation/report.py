"""Navigation results as text: the metric table the command prints, and one markdown row per run."""

from __future__ import annotations

from typing import Any

from st_sim.apps.navigation.metrics import GROUPS, METRICS, summarize

TABLE_COLUMNS: tuple[str, ...] = ("success", "collision", "collision_at_fault", "collision_robot_on_person",
                                  "collision_person_on_robot", "pedestrian_collision", "wall_collision", "timeout",
                                  "time_to_goal_s", "path_ratio", "min_step_end_gap_m", "discomfort", "jerk_mps3")
"""the columns of ``markdown_row``"""


def metric_label(name: str) -> str:
    """A metric's name with its unit (``METRICS``), as the tables print it."""
    unit = METRICS[name].unit
    return f"{name} [{unit}]" if unit not in ("share", "count", "steps") else name


def see_ego_label(value: bool | None) -> str:
    """How the run treated ``pedestrians_see_ego``."""
    return {True: "pedestrians see the robot", False: "invisible robot"}.get(value, "env default")


def summary_text(result: dict[str, Any]) -> str:
    """Plain-text table of a ``run_navigation`` result: every metric, group by group, with its 95 % interval and
    count."""
    n = len(result["episodes"])
    mode = f", {result['pedestrians']} pedestrians" if result.get("pedestrians") else ""
    lines = [f"{result['env_id']}{mode}  policy {result['policy']}  predictor {result['predictor']}  episodes {n} "
             f"(seeds {result['seed']}..{result['seed'] + n - 1})  [{see_ego_label(result['pedestrians_see_ego'])}]",
             f"{'metric':<34}{'value':>9}   95 % CI            n"]
    for group in GROUPS:
        lines.append(f"{group}:")
        for name in (name for name, metric in METRICS.items() if metric.group == group):
            cell = result["summary"][name]
            lines.append(f"  {metric_label(name):<32}{cell['value']:>9.3f}   [{cell['low']:.3f}, {cell['high']:.3f}]"
                         f"{cell['n']:>6}")
    lines.append(f"planner decisions per second: {result['decisions_per_s']:.1f}")
    return "\n".join(lines)


def markdown_row(result: dict[str, Any]) -> str:
    """One markdown table row: planner, predictor, then TABLE_COLUMNS as ``value [low, high]`` (summarised again
    from the episodes, so that result files of older versions read the same)."""
    summary, cells = summarize(result["episodes"]), []
    for name in TABLE_COLUMNS:
        cell = summary[name]
        digits = 3 if METRICS[name].kind == "rate" else 2
        cells.append(f"{cell['value']:.{digits}f} [{cell['low']:.{digits}f}, {cell['high']:.{digits}f}]")
    return f"| {result['policy']} | {result['predictor']} | {len(result['episodes'])} | " + " | ".join(cells) + " |"


def markdown_header() -> str:
    """Header of the ``markdown_row`` table."""
    names = " | ".join(metric_label(name) for name in TABLE_COLUMNS)
    return f"| planner | predictor | episodes | {names} |\n|" + "---|" * (3 + len(TABLE_COLUMNS))
