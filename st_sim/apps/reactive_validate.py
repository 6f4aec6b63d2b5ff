"""``python -m st_sim reactive-validate``: reactive pedestrians against people who reacted to a real vehicle.

Every experiment with a vehicle under ``--data`` (CITR's layout, ``replays.citr``) is resampled at the env's 0.4 s
step. The vehicle is the robot: a ``--vehicle-length`` x ``--vehicle-width`` box driven along its recorded path.
Each pedestrian that came within ``NEAR_M`` of the vehicle's body gets its **intent**, the same for every model: the
straight line on from where it was, at its mean velocity over the ``INTENT_STEPS`` before, when the vehicle first
came within ``INTENT_GAP_M`` of it (at the earliest ``INTENT_STEPS`` into its track). From there each model walks it
with the vehicle present:

- ``blind``: it walks its intent and ignores the vehicle;
- ``reactive``: STCrowd's reactive pedestrian (``envs.common.reactive``) with its intent as its log and the fitted
  reaction (``envs.common.reaction``), the pedestrians seeing the vehicle's body, position and velocity at the start
  of each step;
- ``attentive``: the same pedestrian noticing the vehicle everywhere and reacting at once (the fitted room, no field
  of view, hearing or reaction time): what attention and reaction time change.

Scored against the recording, per pedestrian: ADE [m] over the interaction window (from its intent to ``POST_STEPS``
after its recorded closest approach), the least gap between its centre and the vehicle's body [m] along every step,
whether the simulated pedestrian's centre entered the body (a collision), and the onset of its reaction: the gap to
the vehicle's body when it first strays ``ONSET_M`` from its intent (none if it never does).
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from tqdm import tqdm

from envs.common.errors import ConfigError
from envs.common.footprint import BODY_RADIUS_M, Body
from envs.common.reaction import FIT_PATH, Reaction, read_reaction
from envs.common.reactive import ReactiveCrowd
from envs.common.routes import OpenGround
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.citr import CART_LENGTH_M, CART_WIDTH_M, CITR_FPS, Experiment, Grid, find_experiments, on_grid
from replays.constants import STEP_S
from replays.data_root import CITR, data_root
from st_sim.command_line import CliError, check_writable

if TYPE_CHECKING:
    from matplotlib.figure import Figure

NEAR_M: Final[float] = 5.0  # pedestrians that come this close to the vehicle's body are scored [m]
INTENT_GAP_M: Final[float] = 15.0  # an intent is taken when the vehicle's body first comes this close [m] ...
INTENT_STEPS: Final[int] = 3  # ... from the mean velocity over this many 0.4 s steps before
POST_STEPS: Final[int] = 5  # the interaction window ends this many steps (2 s) after the recorded closest approach
ONSET_M: Final[float] = 0.5  # a reaction shows once a pedestrian strays this far from its intent [m]
MODELS: Final[tuple[str, ...]] = ("blind", "reactive", "attentive")
HELD_OUT: Final[tuple[str, ...]] = ("vci_lat_bi",)  # CITR folders never fitted on (benchmarks/fit_reaction.py)


@dataclass(frozen=True, eq=False)
class Intents:
    """The scored pedestrians of one experiment and what they meant to do.

    Attributes:
        columns: (N,) their columns in the grid.  start: (N,) the step each intent is taken at.
        last: (N,) each one's last recorded step.  xy_m: (T, N, 2) the intents [m], NaN before their start.
    """

    columns: np.ndarray
    start: np.ndarray
    last: np.ndarray
    xy_m: np.ndarray


def recorded_gap_m(grid: Grid, body: Body) -> np.ndarray:
    """(T, N) gap [m] between each recorded pedestrian and the vehicle's body at every step (NaN where absent)."""
    return body.gap_m(grid.xy_m - grid.vehicle_xy_m[:, None], grid.vehicle_heading_rad[:, None])


def intents(grid: Grid, body: Body) -> Intents:
    """The intents of the pedestrians of ``grid`` that came within ``NEAR_M`` of the vehicle (module docstring)."""
    gap = recorded_gap_m(grid, body)
    steps = np.arange(len(grid.times_s))
    columns, start, last = [], [], []
    for column in np.flatnonzero(np.nanmin(np.where(grid.present, gap, np.inf), axis=0) <= NEAR_M):
        seen = np.flatnonzero(grid.present[:, column])
        inside = seen[gap[seen, column] < INTENT_GAP_M]
        begin = min(max(int(inside[0]), seen[0] + INTENT_STEPS), seen[-1] - 1)
        if begin >= seen[0] + INTENT_STEPS:  # long enough to take a velocity and to walk one step
            columns.append(column)
            start.append(begin)
            last.append(int(seen[-1]))
    columns, start = np.array(columns, int), np.array(start, int)
    velocity = (grid.xy_m[start, columns] - grid.xy_m[start - INTENT_STEPS, columns]) / (INTENT_STEPS * STEP_S)
    since_s = (steps[:, None] - start[None]) * STEP_S  # (T, N)
    xy = grid.xy_m[start, columns][None] + since_s[..., None] * velocity[None]
    return Intents(columns, start, np.array(last, int), np.where((since_s >= 0)[..., None], xy, np.nan))


def walk(grid: Grid, intent: Intents, body: Body, reaction: Reaction | None) -> np.ndarray:
    """(T, N, 2) positions [m] of the scored pedestrians walking their intents with the vehicle driving its recorded
    path (``reaction`` None: blind, the intents themselves)."""
    if reaction is None:
        return intent.xy_m.copy()
    present = ~np.isnan(intent.xy_m[..., 0])
    crowd = ReactiveCrowd(intent.xy_m, present, OpenGround(), body, BODY_RADIUS_M, reaction)
    path = [crowd.reset(0).copy()]
    for index in range(1, len(grid.times_s)):
        heading = grid.vehicle_heading_rad[index - 1]
        here = grid.vehicle_xy_m[index - 1]
        expected = here + STEP_S * grid.vehicle_speed_mps[index - 1] * np.array([np.cos(heading), np.sin(heading)])
        path.append(crowd.step(index, here, expected, heading).copy())
    return np.array(path)


def score(grid: Grid, intent: Intents, xy_m: np.ndarray, body: Body) -> list[dict[str, Any]]:
    """Per scored pedestrian of one experiment, how ``xy_m`` (T, N, 2) walked: ``ade_m`` against the recording over
    the interaction window, ``min_clearance_m`` (least gap to the vehicle's body along the steps), ``collision``
    (its centre inside the body) and ``onset_gap_m`` (gap when it first strayed ``ONSET_M`` from its intent, or
    None)."""
    recorded = grid.xy_m[:, intent.columns]
    closest = recorded_gap_m(grid, body)[:, intent.columns]
    vehicle, heading = grid.vehicle_xy_m, grid.vehicle_heading_rad
    rows = []
    for n, (begin, end) in enumerate(zip(intent.start, intent.last, strict=True)):
        span = slice(begin, end + 1)
        stop = min(begin + int(np.nanargmin(closest[span, n])) + POST_STEPS, end)
        ade = float(np.linalg.norm(xy_m[begin:stop + 1, n] - recorded[begin:stop + 1, n], axis=-1).mean())
        swept = body.swept_gap_m(xy_m[begin:end, n] - vehicle[begin:end], xy_m[begin + 1:end + 1, n]
                                 - vehicle[begin + 1:end + 1], heading[begin:end])
        clearance = float(swept.min())
        strayed = np.flatnonzero(np.linalg.norm(xy_m[span, n] - intent.xy_m[span, n], axis=-1) > ONSET_M)
        onset = float(body.gap_m(xy_m[begin + strayed[0], n] - vehicle[begin + strayed[0]],
                                 heading[begin + strayed[0]])) if strayed.size else None
        rows.append({"ade_m": ade, "min_clearance_m": clearance, "collision": bool(clearance <= 0.0),
                     "onset_gap_m": onset})
    return rows


@dataclass(frozen=True, eq=False)
class Case:
    """One experiment ready to simulate: its grid, its scored pedestrians' intents and how they really walked."""

    name: str
    group: str
    """the experiment's top folder (``vci_front``), "." for an experiment at the top"""
    grid: Grid
    intent: Intents
    recorded: list[dict[str, Any]]


def cases(experiments: list[Experiment], body: Body) -> list[Case]:
    """The experiments with at least one scored pedestrian, resampled at 0.4 s, with their intents and recorded
    scores."""
    found = []
    for experiment in experiments:
        grid = on_grid(experiment, STEP_S)
        intent = intents(grid, body)
        if len(intent.columns):
            group = experiment.name.split("/")[0] if "/" in experiment.name else "."
            found.append(Case(experiment.name, group, grid, intent,
                              score(grid, intent, grid.xy_m[:, intent.columns], body)))
    return found


def model_reactions(reaction: Reaction) -> dict[str, Reaction | None]:
    """The reaction of each model of ``MODELS`` (None: blind)."""
    return {"blind": None, "reactive": reaction,
            "attentive": dataclasses.replace(reaction, fov_deg=180.0, reaction_s=0.0)}


def validate(experiments: list[Experiment], body: Body, reaction: Reaction, models: tuple[str, ...] = MODELS,
             progress: bool = True) -> dict[str, Any]:
    """Score the recorded pedestrians and every model on ``experiments``; returns the summary over all of them, per
    group (the experiment's top folder), and one row per scored pedestrian (see ``summary``)."""
    reactions = model_reactions(reaction)
    rows = []
    found = cases(experiments, body)
    if not found:
        raise CliError(f"no pedestrian came within {NEAR_M:g} m of a vehicle in {len(experiments)} experiment(s)")
    for case in tqdm(found, desc="reactive-validate", unit="experiment", disable=not progress):
        scored = {model: score(case.grid, case.intent, walk(case.grid, case.intent, body, reactions[model]), body)
                  for model in models}
        for n, column in enumerate(case.intent.columns):
            rows.append({"experiment": case.name, "group": case.group, "id": int(case.grid.pedestrian_ids[column]),
                         "recorded": case.recorded[n], **{model: scored[model][n] for model in models}})
    groups = sorted({row["group"] for row in rows})
    return {**summary(rows, models), "groups": {group: summary([r for r in rows if r["group"] == group], models)
                                                for group in groups}, "pedestrian_rows": rows}


def summary(rows: list[dict[str, Any]], models: tuple[str, ...]) -> dict[str, Any]:
    """``{"pedestrians": N, "recorded": {...}, "models": {model: {...}}}``: medians of the least clearance and of
    the onset gap, the share that reacted (strayed from the intent), and per model the mean ADE and the collisions."""
    def figures(key: str) -> dict[str, Any]:
        clearance = [row[key]["min_clearance_m"] for row in rows]
        onsets = [row[key]["onset_gap_m"] for row in rows if row[key]["onset_gap_m"] is not None]
        return {"min_clearance_m_median": float(np.median(clearance)),
                "onset_gap_m_median": float(np.median(onsets)) if onsets else None,
                "reacted_share": len(onsets) / len(rows)}

    return {"pedestrians": len(rows), "recorded": figures("recorded"),
            "models": {model: {"ade_m": float(np.mean([row[model]["ade_m"] for row in rows])), **figures(model),
                               "collisions": int(sum(row[model]["collision"] for row in rows))} for model in models}}


def markdown_table(result: dict[str, Any]) -> str:
    """One row per group and model, and the totals: pedestrians, ADE, median least clearance (recorded and
    simulated), collisions, median onset gap, share that reacted."""
    lines = ["| experiments | pedestrians | model | ADE [m] | median least clearance [m] (recorded) | collisions "
             "| median onset gap [m] (recorded) | reacted (recorded) |", "|---|---|---|---|---|---|---|---|"]
    parts = [*result["groups"].items(), ("all", result)]
    for name, part in parts:
        rec = part["recorded"]
        for model, fig in part["models"].items():
            onset = "–" if fig["onset_gap_m_median"] is None else f"{fig['onset_gap_m_median']:.2f}"
            rec_onset = "–" if rec["onset_gap_m_median"] is None else f"{rec['onset_gap_m_median']:.2f}"
            held = " (held out)" if name in HELD_OUT else ""
            lines.append(f"| {name}{held} | {part['pedestrians']} | {model} | {fig['ade_m']:.3f} | "
                         f"{fig['min_clearance_m_median']:.2f} ({rec['min_clearance_m_median']:.2f}) | "
                         f"{fig['collisions']} | {onset} ({rec_onset}) | {fig['reacted_share']:.2f} "
                         f"({rec['reacted_share']:.2f}) |")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """The ``reactive-validate`` command: read, validate, print the table, write the JSON (and the chart)."""
    for value, flag in ((args.fps, "--fps"), (args.vehicle_length, "--vehicle-length"),
                        (args.vehicle_width, "--vehicle-width")):
        if not (np.isfinite(value) and value > 0):
            raise CliError(f"{flag} {value}: expected a positive number")
    check_writable(Path(args.json).parent)
    try:
        reaction = read_reaction(Path(args.reaction))
    except ConfigError as err:
        raise CliError(f"--reaction {err}") from None
    shipped = Path(args.reaction).resolve() == FIT_PATH.resolve()
    root = data_root(dataset=CITR) if args.data is None else Path(args.data)
    experiments = find_experiments(root, args.fps)
    body = Body(args.vehicle_length, args.vehicle_width)
    result = validate(experiments, body, reaction, progress=not args.quiet)
    result["settings"] = {"data": str(args.data) if args.data else "$STCROWD_CITR or the cache", "fps": args.fps,
                          "vehicle_length_m": args.vehicle_length, "vehicle_width_m": args.vehicle_width,
                          "step_s": STEP_S, "near_m": NEAR_M, "intent_gap_m": INTENT_GAP_M,
                          "intent_steps": INTENT_STEPS, "post_steps": POST_STEPS, "onset_m": ONSET_M,
                          "reaction": dataclasses.asdict(reaction),
                          "reaction_file": "envs/common/reaction_fit.json" if shipped else str(args.reaction),
                          "held_out": list(HELD_OUT)}
    print(markdown_table(result))
    write_text_atomic(args.json, strict_json.dumps(result, indent=1))
    print(f"wrote {args.json}")
    if args.chart:
        from st_sim.charts import save_figure

        print(f"wrote {save_figure(validation_chart(result), args.chart)}")
    return 0


def validation_chart(result: dict[str, Any], models: tuple[str, ...] = ("blind", "reactive")) -> Figure:
    """Recorded against simulated least clearance and onset gap, one point per pedestrian and model, the held-out
    experiments apart (``st_sim.charts.identity_scatter``)."""
    from st_sim.charts import identity_scatter

    rows = result["pedestrian_rows"]
    panels: dict[str, dict[str, tuple[list[float], list[float]]]] = {}
    for key, what in (("min_clearance_m", "least clearance"), ("onset_gap_m", "onset of the reaction")):
        panel = panels.setdefault(f"{what} to the vehicle's body [m]", {})
        for model in models:
            for held in (False, True):
                pairs = [(row["recorded"][key], row[model][key]) for row in rows
                         if (row["group"] in HELD_OUT) == held and row["recorded"][key] is not None
                         and row[model][key] is not None]
                if pairs:
                    label = f"{model}, {'held out' if held else 'fitted on'}"
                    panel[label] = tuple(map(list, zip(*pairs, strict=True)))
    return identity_scatter("recorded [m]", "simulated [m]", panels,
                            title="CITR: pedestrians round a golf cart, recorded and simulated")


def add_parser(commands: argparse._SubParsersAction) -> None:
    """The ``reactive-validate`` subcommand's flags."""
    parser = commands.add_parser("reactive-validate", help="score reactive pedestrians against recorded reactions "
                                                            "to a vehicle (CITR layout)")
    parser.add_argument("--data", default=None, metavar="DIR",
                        help="folder of experiments (NAME_traj_ped_filtered.csv and NAME_traj_veh_filtered.csv, "
                             "subfolders included) (default: the CITR data root, $STCROWD_CITR or "
                             "~/.cache/stcrowd/citr, SHA-256 checked)")
    parser.add_argument("--fps", type=float, default=CITR_FPS, help=f"frames per second (default: {CITR_FPS})")
    parser.add_argument("--vehicle-length", type=float, default=CART_LENGTH_M,
                        help=f"vehicle length [m] (default: {CART_LENGTH_M}, CITR's EZ-GO golf cart)")
    parser.add_argument("--vehicle-width", type=float, default=CART_WIDTH_M,
                        help=f"vehicle width [m] (default: {CART_WIDTH_M})")
    parser.add_argument("--reaction", default=FIT_PATH, metavar="FIT",
                        help="the reactive pedestrians' reaction: a fit file as benchmarks/fit_reaction.py --out "
                             "writes (default: the shipped envs/common/reaction_fit.json)")
    parser.add_argument("--json", required=True, metavar="OUT", help="write the figures here (JSON)")
    parser.add_argument("--chart", default=None, metavar="PNG",
                        help="also draw recorded against simulated clearance and onset here (default: none)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
