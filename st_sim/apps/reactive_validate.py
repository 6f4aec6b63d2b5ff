"""``python -m st_sim reactive-validate``: reactive pedestrians against people who reacted to a real vehicle.

Every experiment with a vehicle under ``--data`` (CITR's layout) becomes a case (``st_sim.apps.vehicle_cases``: the
vehicle is a ``--vehicle-length`` x ``--vehicle-width`` box driven along its recorded path; each pedestrian that came
within ``NEAR_M`` of it gets its intent, the same for every model, and is scored against the recording: ADE, least
clearance, collisions, onset of the reaction). The models:

- ``blind``: it walks its intent and ignores the vehicle;
- ``reactive``: STCrowd's reactive pedestrian (``st_sim.reactive.reactive``) with its intent as its log and the fitted
  reaction (``st_sim.reactive.reaction``, or ``--reaction FIT``);
- ``attentive``: the same pedestrian noticing the vehicle everywhere and reacting at once (the fitted room, no field
  of view, hearing or reaction time): what attention and reaction time change.

The folders a fit was fitted on are those its file names (``fitted_on``); every other folder is marked held out.

``--cross-validate``: leave one folder out (``st_sim.apps.reaction_search``). For each folder, the reactive
pedestrians take the fit that the fitting procedure (``CV_PROCEDURE``, ``--variant``, ``--clearance-tolerance``)
ends at on the other folders only, and are scored on the folder left out: how the fitting carries over to people it
never saw. Fold fits are kept in ``--fold-fits`` and reused. ``--no-refit`` instead scores the ``--reaction`` fit on
every folder (cheap; on a folder that fit saw it measures nothing held out).

``--realism``: the realism score of the blind and the reactive pedestrians (``st_sim.apps.sim_agents``: ``--rollouts``
seeded rollouts each, paces and traits drawn per ``vehicle_cases.Variety``: the traits with the environments' spread,
``st_sim.reactive.reaction.fitted_spread``, or ``--trait-sigma``), over every case and, with
``--cross-validate``, per fold.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from tqdm import tqdm

from envs.common.errors import ConfigError
from replays import strict_json
from replays.atomic import write_text_atomic
from replays.citr import CART_LENGTH_M, CART_WIDTH_M, CITR_FPS, Experiment, find_experiments
from replays.constants import STEP_S
from replays.data_root import CITR, data_root
from st_sim.apps.reaction_search import CV_PROCEDURE, VARIANTS, Model, Scorer, cv_score, fold_fit
from st_sim.apps.sim_agents import WEIGHTS, case_realism
from st_sim.apps.vehicle_cases import INTENT_GAP_M, INTENT_STEPS, NEAR_M, ONSET_M, POST_STEPS, Case, Variety, cases
from st_sim.command_line import CliError, check_writable, non_negative_float, positive_int
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import FIT_PATH, Reaction, Spread, fitted_spread, read_fitted_on, read_reaction

if TYPE_CHECKING:
    from matplotlib.figure import Figure

MODELS: Final[tuple[str, ...]] = ("blind", "reactive", "attentive")
CV_MODELS: Final[tuple[str, ...]] = ("blind", "reactive")  # the models of a fold
ROLLOUTS: Final[int] = 32  # seeded rollouts per pedestrian and model of the realism score (WOSAC's)


def model_reactions(reaction: Model, models: tuple[str, ...] = MODELS) -> dict[str, Model | None]:
    """The reaction of each of ``models`` (None: blind; ``reaction`` may be a sub-goal model where ``models`` has no
    ``attentive``, which is the reactive pedestrian's)."""
    every = {"blind": None, "reactive": reaction}
    if "attentive" in models:
        every["attentive"] = dataclasses.replace(reaction, fov_deg=180.0, reaction_s=0.0)
    return {model: every[model] for model in models}


def pedestrian_rows(scorer: Scorer, found: list[Case], reactions: dict[str, Reaction | None],
                    progress: bool = True) -> list[dict[str, Any]]:
    """One row per scored pedestrian of ``found``: its experiment, folder (``group``) and id, its recorded scores
    and those of every model of ``reactions`` (``vehicle_cases.score``)."""
    rows = []
    for case in tqdm(found, desc="reactive-validate", unit="experiment", disable=not progress):
        scored = {model: scorer.rows(case, reaction) for model, reaction in reactions.items()}
        for n, column in enumerate(case.intent.columns):
            rows.append({"experiment": case.name, "group": case.group, "id": int(case.grid.pedestrian_ids[column]),
                         "recorded": case.recorded[n], **{model: scored[model][n] for model in reactions}})
    return rows


def report(rows: list[dict[str, Any]], models: tuple[str, ...]) -> dict[str, Any]:
    """``summary`` of ``rows``, the same per group, and the rows."""
    groups = sorted({row["group"] for row in rows})
    return {**summary(rows, models), "groups": {group: summary([r for r in rows if r["group"] == group], models)
                                                for group in groups}, "pedestrian_rows": rows}


def validate(experiments: list[Experiment], body: Body, reaction: Reaction, models: tuple[str, ...] = MODELS,
             progress: bool = True) -> dict[str, Any]:
    """Score the recorded pedestrians and every model on ``experiments``; returns the summary over all of them, per
    group (the experiment's top folder), and one row per scored pedestrian (see ``summary``)."""
    found = found_cases(experiments, body)
    return report(pedestrian_rows(Scorer(found, body), found, model_reactions(reaction, models), progress), models)


def found_cases(experiments: list[Experiment], body: Body) -> list[Case]:
    """``vehicle_cases.cases``, or one error line when nobody came near a vehicle."""
    found = cases(experiments, body)
    if not found:
        raise CliError(f"no pedestrian came within {NEAR_M:g} m of a vehicle in {len(experiments)} experiment(s)")
    return found


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


def variety_of(args: argparse.Namespace) -> Variety:
    """The rollouts' variety: ``--pace-sigma`` and the traits of ``--trait-sigma`` or the fitted spread."""
    try:
        spread = fitted_spread() if args.trait_sigma is None else Spread.even(args.trait_sigma)
    except ConfigError as err:  # the shipped spread file, or the flag
        raise CliError(str(err) if args.trait_sigma is None else f"--trait-sigma: {err}") from None
    return Variety(args.pace_sigma, spread)


def realism_of(found: list[Case], body: Body, reaction: Reaction, args: argparse.Namespace) -> dict[str, Any]:
    """``{"blind": ..., "reactive": ...}``: ``sim_agents.case_realism`` of both models on ``found``."""
    variety = variety_of(args)
    return {model: case_realism(found, body, model_reaction, args.rollouts, args.seed, variety,
                                progress=not args.quiet)
            for model, model_reaction in model_reactions(reaction, CV_MODELS).items()}


def cross_validation(scorer: Scorer, fold_fits: dict[str, tuple[Reaction, tuple[str, ...] | None]],
                     args: argparse.Namespace) -> list[dict[str, Any]]:
    """One entry per folder left out (``fold_fits``: folder -> the reaction scored there and the folders it was
    fitted on, None where unknown): ``held_out``, ``fitted_on``, ``unseen`` (the fit never saw the folder), the
    reaction, ``summary`` of blind and reactive on the folder, their ``ade_ratio`` and, with ``--realism``,
    ``realism``."""
    folds = []
    for held_out, (reaction, fitted_on) in fold_fits.items():
        found = scorer.of([held_out])
        fold = {"held_out": held_out, "fitted_on": None if fitted_on is None else list(fitted_on),
                "unseen": None if fitted_on is None else held_out not in fitted_on,
                "reaction": dataclasses.asdict(reaction),
                **summary(pedestrian_rows(scorer, found, model_reactions(reaction, CV_MODELS), False), CV_MODELS)}
        fold["ade_ratio"] = fold["models"]["reactive"]["ade_m"] / fold["models"]["blind"]["ade_m"]
        if args.realism:
            fold["realism"] = realism_of(found, scorer.body, reaction, args)
        folds.append(fold)
    return folds


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
            held = " (held out)" if name in result["settings"]["held_out"] else ""
            lines.append(f"| {name}{held} | {part['pedestrians']} | {model} | {fig['ade_m']:.3f} | "
                         f"{fig['min_clearance_m_median']:.2f} ({rec['min_clearance_m_median']:.2f}) | "
                         f"{fig['collisions']} | {onset} ({rec_onset}) | {fig['reacted_share']:.2f} "
                         f"({rec['reacted_share']:.2f}) |")
    return "\n".join(lines)


def folds_table(result: dict[str, Any]) -> str:
    """One row per fold: the folder left out (marked where the fit saw it), its pedestrians, blind and reactive ADE
    and their ratio, median least clearance (recorded), collisions, and the realism meta scores where measured; then
    the CV score."""
    lines = ["| held out | pedestrians | blind ADE [m] | reactive ADE [m] | ratio | reactive clearance [m] "
             "(recorded) | collisions blind / reactive | realism meta blind / reactive |", "|" + "---|" * 8]
    for fold in result["folds"]:
        blind, reactive = fold["models"]["blind"], fold["models"]["reactive"]
        meta = (f"{fold['realism']['blind']['meta']:.3f} / {fold['realism']['reactive']['meta']:.3f}"
                if "realism" in fold else "–")
        seen = " (seen by the fit)" if fold["unseen"] is False else ""
        lines.append(f"| {fold['held_out']}{seen} | {fold['pedestrians']} | {blind['ade_m']:.3f} | "
                     f"{reactive['ade_m']:.3f} | {fold['ade_ratio']:.3f} | {reactive['min_clearance_m_median']:.2f} "
                     f"({fold['recorded']['min_clearance_m_median']:.2f}) | {blind['collisions']} / "
                     f"{reactive['collisions']} | {meta} |")
    cv = result["cross_validation"]
    lines.append(f"\nheld-out ADE ratio: mean {cv['mean_ade_ratio']:.3f}, worst {cv['worst_ade_ratio']:.3f} "
                 f"({cv['worst_fold']}); criterion max(mean / 0.8, worst / 0.9) = {cv['criterion']:.3f}")
    return "\n".join(lines)


def realism_table(realism: dict[str, Any]) -> str:
    """One row per model: the meta score, every feature's score and minADE."""
    names = list(WEIGHTS)
    lines = [f"| model | meta | {' | '.join(names)} | minADE [m] |", "|" + "---|" * (len(names) + 3)]
    for model, score in realism.items():
        features = " | ".join(f"{score['features'][name]:.3f}" for name in names)
        lines.append(f"| {model} | {score['meta']:.3f} | {features} | {score['min_ade_m']:.3f} |")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    """The ``reactive-validate`` command: read, validate, print the tables, write the JSON (and the charts)."""
    for value, flag in ((args.fps, "--fps"), (args.vehicle_length, "--vehicle-length"),
                        (args.vehicle_width, "--vehicle-width")):
        if not (np.isfinite(value) and value > 0):
            raise CliError(f"{flag} {value}: expected a positive number")
    for value, flag in ((args.pace_sigma, "--pace-sigma"), (args.trait_sigma, "--trait-sigma")):
        if value is not None and not (np.isfinite(value) and value >= 0):
            raise CliError(f"{flag} {value}: expected a number >= 0")
    variety_of(args)  # a spread out of range: one error line before anything runs
    if args.no_refit and not args.cross_validate:
        raise CliError("--no-refit goes with --cross-validate (it scores --reaction on every fold)")
    check_writable(Path(args.json).parent)
    try:
        reaction = read_reaction(Path(args.reaction))
        fitted_on = read_fitted_on(Path(args.reaction))
    except ConfigError as err:
        raise CliError(f"--reaction {err}") from None
    shipped = Path(args.reaction).resolve() == FIT_PATH.resolve()
    root = data_root(dataset=CITR) if args.data is None else Path(args.data)
    body = Body(args.vehicle_length, args.vehicle_width)
    found = found_cases(find_experiments(root, args.fps), body)
    scorer = Scorer(found, body)
    if args.cross_validate and len(scorer.groups) < 2:
        raise CliError(f"--cross-validate needs at least two folders of experiments; found {scorer.groups}")
    result = report(pedestrian_rows(scorer, found, model_reactions(reaction), not args.quiet), MODELS)
    result["settings"] = {"data": str(args.data) if args.data else "$STCROWD_CITR or the cache", "fps": args.fps,
                          "vehicle_length_m": args.vehicle_length, "vehicle_width_m": args.vehicle_width,
                          "step_s": STEP_S, "near_m": NEAR_M, "intent_gap_m": INTENT_GAP_M,
                          "intent_steps": INTENT_STEPS, "post_steps": POST_STEPS, "onset_m": ONSET_M,
                          "reaction": dataclasses.asdict(reaction),
                          "reaction_file": "st_sim/reactive/reaction_fit.json" if shipped else str(args.reaction),
                          "held_out": [group for group in scorer.groups
                                       if fitted_on is not None and group not in fitted_on]}
    print(markdown_table(result))
    if args.realism:
        result["settings"]["realism"] = {"rollouts": args.rollouts, "seed": args.seed,
                                         "variety": dataclasses.asdict(variety_of(args)),
                                         "weights": WEIGHTS}
        result["realism"] = realism_of(found, body, reaction, args)
        print(realism_table(result["realism"]))
    if args.cross_validate:
        procedure = dataclasses.replace(CV_PROCEDURE, variant=args.variant,
                                        clearance_tolerance=args.clearance_tolerance)
        fold_fits = {}
        for held_out in scorer.groups:
            if args.no_refit:
                fold_fits[held_out] = reaction, fitted_on
            else:
                fit = fold_fit(scorer, [group for group in scorer.groups if group != held_out], procedure,
                               Path(args.fold_fits), not args.quiet)
                fold_fits[held_out] = fit.reaction, fit.fitted_on
        result["folds"] = cross_validation(scorer, fold_fits, args)
        result["cross_validation"] = {
            **cv_score({fold["held_out"]: fold["ade_ratio"] for fold in result["folds"]}), "refit": not args.no_refit,
            "procedure": None if args.no_refit else procedure.record(),
            "fold_fits": None if args.no_refit else str(args.fold_fits)}
        print(folds_table(result))
    write_text_atomic(args.json, strict_json.dumps(result, indent=1))
    print(f"wrote {args.json}")
    if args.chart:
        from st_sim.charts import save_figure

        print(f"wrote {save_figure(validation_chart(result), args.chart)}")
        if args.realism or args.cross_validate:
            chart = Path(args.chart)
            print(f"wrote {save_figure(scores_chart(result), chart.with_name(chart.stem + '-scores.png'))}")
    return 0


def validation_chart(result: dict[str, Any], models: tuple[str, ...] = ("blind", "reactive")) -> Figure:
    """Recorded against simulated least clearance and onset gap, one point per pedestrian and model, the held-out
    experiments apart (``st_sim.charts.identity_scatter``)."""
    from st_sim.charts import identity_scatter

    rows, held_out = result["pedestrian_rows"], result["settings"]["held_out"]
    panels: dict[str, dict[str, tuple[list[float], list[float]]]] = {}
    for key, what in (("min_clearance_m", "least clearance"), ("onset_gap_m", "onset of the reaction")):
        panel = panels.setdefault(f"{what} to the vehicle's body [m]", {})
        for model in models:
            for held in (False, True):
                pairs = [(row["recorded"][key], row[model][key]) for row in rows
                         if (row["group"] in held_out) == held and row["recorded"][key] is not None
                         and row[model][key] is not None]
                if pairs:
                    label = f"{model}, {'held out' if held else 'fitted on'}"
                    panel[label] = tuple(map(list, zip(*pairs, strict=True)))
    return identity_scatter("recorded [m]", "simulated [m]", panels,
                            title="CITR: pedestrians round a golf cart, recorded and simulated")


def scores_chart(result: dict[str, Any]) -> Figure:
    """Bars of blind against reactive: the realism feature scores and meta score over every case, and per fold the
    held-out ADE and the realism meta score (``st_sim.charts.grouped_bars``)."""
    from st_sim.charts import grouped_bars

    panels: dict[str, tuple[list[str], dict[str, list[float]]]] = {}
    if "realism" in result:
        names = [*WEIGHTS, "meta"]
        panels["realism, every pedestrian (score in [0, 1], higher: likelier)"] = (names, {
            model: [score["features"][name] if name != "meta" else score["meta"] for name in names]
            for model, score in result["realism"].items()})
    if "folds" in result:
        held = [fold["held_out"] for fold in result["folds"]]
        panels["cross-validation: ADE [m] on the folder held out"] = (held, {
            model: [fold["models"][model]["ade_m"] for fold in result["folds"]] for model in CV_MODELS})
        if all("realism" in fold for fold in result["folds"]):
            panels["cross-validation: realism meta score on the folder held out"] = (held, {
                model: [fold["realism"][model]["meta"] for fold in result["folds"]] for model in CV_MODELS})
    return grouped_bars("", panels, title="CITR: blind and reactive pedestrians round a golf cart")


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
                             "writes (default: the shipped st_sim/reactive/reaction_fit.json)")
    parser.add_argument("--json", required=True, metavar="OUT", help="write the figures here (JSON)")
    parser.add_argument("--chart", default=None, metavar="PNG",
                        help="also draw recorded against simulated clearance and onset here, and with --realism or "
                             "--cross-validate their scores beside it (PNG-scores.png) (default: none)")
    parser.add_argument("--cross-validate", action="store_true",
                        help="leave one folder out: per folder, the reactive pedestrians fitted on the other folders "
                             "only (st_sim.apps.reaction_search.CV_PROCEDURE) scored on it; adds folds and "
                             "cross_validation to the JSON")
    parser.add_argument("--no-refit", action="store_true",
                        help="with --cross-validate: score --reaction on every folder instead of refitting (cheap)")
    parser.add_argument("--variant", choices=list(VARIANTS), default="reactive",
                        help="with --cross-validate: the variant of the reaction refitted per fold (default: reactive)")
    parser.add_argument("--clearance-tolerance", type=non_negative_float,
                        default=CV_PROCEDURE.clearance_tolerance, metavar="T",
                        help=f"with --cross-validate: the refit's loss lets the median least clearance miss the "
                             f"recorded one by up to this share at no cost (default: "
                             f"{CV_PROCEDURE.clearance_tolerance:g})")
    parser.add_argument("--fold-fits", default="runs/reaction_cv", metavar="DIR",
                        help="with --cross-validate: each fold's fit is kept here and reused by a later run of the "
                             "same procedure on the same data (default: runs/reaction_cv)")
    parser.add_argument("--realism", action="store_true",
                        help="add the WOSAC-style realism score of blind and reactive pedestrians (st_sim.apps."
                             "sim_agents), over every pedestrian and per fold")
    parser.add_argument("--rollouts", type=positive_int, default=ROLLOUTS,
                        help=f"with --realism: seeded rollouts per model (default: {ROLLOUTS})")
    parser.add_argument("--seed", type=int, default=0, help="with --realism: the rollouts' seed (default: 0)")
    parser.add_argument("--pace-sigma", type=float, default=Variety.pace_sigma,
                        help=f"with --realism: spread of each rollout's pace factor, N(1, sigma) (default: "
                             f"{Variety.pace_sigma})")
    parser.add_argument("--trait-sigma", type=float, default=None,
                        help="with --realism: every reactive pedestrian's traits (noticing, reaction time, room, "
                             "patience) drawn as exp(N(0, sigma)) (default: the environments' fitted spread, "
                             "st_sim/reactive/spread_fit.json)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
