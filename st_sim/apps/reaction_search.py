"""Fitting the reactive pedestrians' reaction (``st_sim.reactive.reaction.Reaction``) to people round a vehicle, and
telling how well the fitting carries over to people it never saw (``benchmarks/fit_reaction.py``, ``python -m st_sim
reactive-validate --cross-validate``).

**The loss** of a reaction on some folders of experiments (what the search minimises, on training folders only): per
folder, the reactive pedestrians' ADE as a share of the blind ones' plus the relative error of their median least
clearance to the vehicle against the recorded one beyond a tolerance (``Procedure.clearance_tolerance``: 0, every
error counts; ``CLEARANCE_TOLERANCE``, the 25 % the clearance target allows, errors within it cost nothing),
averaged over the folders; plus ``COLLISION_WEIGHT`` times the share of simulated pedestrians inside the vehicle
(``vehicle_cases`` has the intents and the scores).

**The search** is a coordinate descent over fixed grids (``GRIDS``): each sweep tries every value of one grid with
the other fields held, keeps the best, and goes on to the next grid; it stops after a sweep that improves nothing or
after ``Procedure.sweeps``. A **variant** (``VARIANTS``) holds some fields and skips the grids that touch them
(``attentive`` notices the vehicle everywhere and at once), or ties some together (``one-room`` keeps one room per m/s
of the vehicle's speed whichever way it comes: head-on, from behind and across take one value, searched as one grid),
so that a folder left out borrows what the others fitted instead of a field only it constrains.

**Cross-validation** (leave one folder out): for each folder, the search runs on the other folders from the same
start and the fit it ends at is scored on the folder left out: its reactive ADE as a share of the blind one there
(the held-out ratio). A fitting procedure's CV score is the mean and the worst of its held-out ratios; procedures
are compared by ``cv_criterion``: max(mean / ``CV_TARGETS[0]``, worst / ``CV_TARGETS[1]``), lower better, at most 1
exactly where both targets hold (mean <= 0.8, worst <= 0.9), ties broken by the mean. Each fold's fit is written to
its own file as it ends (``fold_fit``) and read back by a later run with the same procedure and data whose
pedestrians walk as they did: a long run resumes where it stopped.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
from tqdm import tqdm

from replays import strict_json
from replays.atomic import write_text_atomic
from st_sim.apps.subgoal_force import SubGoalForce
from st_sim.apps.vehicle_cases import Case, score, walk
from st_sim.reactive.footprint import Body
from st_sim.reactive.reaction import Reaction

COLLISION_WEIGHT: Final[float] = 10.0  # loss of simulated pedestrians inside the vehicle, per share of them [-]
PER_MPS: Final[tuple[float, ...]] = (0.0, 0.1, 0.2, 0.3, 0.45, 0.6, 0.8, 1.0, 1.3, 1.6, 2.0)  # room per m/s [s]
GRIDS: Final[dict[str, tuple[tuple[float, ...], ...]]] = {  # fields joined by "+" are searched together
    "fov_deg+hearing_m": ((30.0, 45.0, 60.0, 75.0, 90.0, 105.0, 120.0, 150.0, 180.0),
                          (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)),
    "reaction_s": ((0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.6, 2.0),),
    "anticipation_s": ((0.4, 0.8, 1.2, 1.6, 2.0, 2.4, 3.2, 4.0),),
    "clearance_m": ((0.0, 0.15, 0.3, 0.5, 0.75, 1.0, 1.5),),
    "head_on_s": (PER_MPS,),
    "behind_s": (PER_MPS,),
    "crossing_s": (PER_MPS,),
    "delay_cost+aside_cost": ((0.25, 0.5, 1.0), (0.5, 1.0, 2.0)),  # aside at least half a frame's delay a metre, so
    # that they rejoin their logs (tests/test_envs_reactive.py's draws); with the crossing room, which they trade with:
    "delay_cost+aside_cost+crossing_s": ((0.25, 0.5, 1.0), (0.5, 1.0, 2.0), PER_MPS),
}
ROOM_FIELDS: Final[tuple[str, ...]] = ("head_on_s", "behind_s", "crossing_s")  # room per m/s, by approach


Model = Reaction | SubGoalForce
"""what walks the pedestrians: STCrowd's reactive pedestrians with a reaction, or the sub-goal social force model"""


def model_of(params: dict[str, float]) -> Model:
    """The model a fit file's ``params`` describe: a ``SubGoalForce`` where they are its fields, else a reaction."""
    if set(params) == {field.name for field in dataclasses.fields(SubGoalForce)}:
        return SubGoalForce(**params)
    return Reaction(**params)


SUB_GOAL_GRIDS: Final[dict[str, tuple[tuple[float, ...], ...]]] = {  # the sub-goal social force model's
    "tau_s": ((0.2, 0.35, 0.5, 0.8, 1.2),),
    "lookahead_s": ((0.8, 1.2, 2.0, 3.2, 4.8),),
    "conflict_s": ((0.0, 1.0, 2.0, 3.0, 4.0, 6.0),),  # 0: no sub-goals, forces alone
    "margin_m": ((0.0, 0.25, 0.5, 1.0, 1.5, 2.0),),
    "ahead_penalty_m": ((0.0, 1.0, 2.0, 5.0, 20.0),),
    "vehicle_strength+vehicle_range_m": ((0.0, 1.0, 2.0, 4.0, 8.0), (0.2, 0.4, 0.8, 1.5)),
    "pedestrian_strength+pedestrian_range_m": ((0.0, 0.5, 1.0, 2.0, 4.0), (0.1, 0.2, 0.3, 0.5)),
}


@dataclass(frozen=True)
class Variant:
    """A family of reactions: the fields it ``holds`` (not searched) and those it ``ties`` (one value for all,
    searched together on the first tied field's grid); or another model altogether (``start``, ``grids``: a
    ``SubGoalForce`` searched over its own grids, the procedure's search and start unused)."""

    holds: dict[str, float]
    ties: tuple[str, ...] = ()
    start: SubGoalForce | None = None
    grids: dict[str, tuple[tuple[float, ...], ...]] | None = None


VARIANTS: Final[dict[str, Variant]] = {
    "reactive": Variant({}),
    "attentive": Variant({"fov_deg": 180.0, "reaction_s": 0.0}),  # noticing the vehicle everywhere, reacting at once
    "one-room": Variant({}, ROOM_FIELDS),  # the same room whichever way the vehicle comes
    "sub-goal": Variant({}, start=SubGoalForce(), grids=SUB_GOAL_GRIDS),  # SG-SFM (st_sim.apps.subgoal_force)
}
FIRST_GUESS: Final[Reaction] = Reaction(  # the start of the first fit (commit bd17cf8's guesses, before any data;
    fov_deg=100.0, hearing_m=3.0, reaction_s=0.6, anticipation_s=1.6, clearance_m=0.3,  # delay and aside: the
    head_on_s=0.4, behind_s=0.3, crossing_s=0.3, delay_cost=1.0, aside_cost=0.5)  # constants they replaced)
CV_TARGETS: Final[tuple[float, float]] = (0.8, 0.9)  # held-out ADE ratio targets: mean, worst (issue 50)
CLEARANCE_TOLERANCE: Final[float] = 0.25  # the clearance target: median least clearance within 25 % of the recorded


class Scorer:
    """How reactions walk the pedestrians of ``cases`` round the vehicle (``Body``), each walk of an experiment done
    once per reaction (kept for the life of the scorer), and the figures per folder (``Case.group``)."""

    def __init__(self, cases: Sequence[Case], body: Body):
        self.cases, self.body = list(cases), body
        self.groups: list[str] = sorted({case.group for case in self.cases})
        self._rows: dict[tuple[Model | None, str], list[dict[str, Any]]] = {}
        self.blind_ade_m = {group: float(np.mean([row["ade_m"] for case in self.of([group])
                                                  for row in self.rows(case, None)])) for group in self.groups}
        """mean ADE [m] of the blind pedestrians (walking their intents) per folder"""

    def of(self, groups: Sequence[str]) -> list[Case]:
        """The cases of the folders ``groups``."""
        return [case for case in self.cases if case.group in groups]

    def rows(self, case: Case, reaction: Model | None) -> list[dict[str, Any]]:
        """``vehicle_cases.score`` of the pedestrians of ``case`` walked with ``reaction`` (None: blind)."""
        key = (reaction, case.name)
        if key not in self._rows:
            self._rows[key] = score(case.grid, case.intent, walk(case.grid, case.intent, self.body, reaction),
                                    self.body)
        return self._rows[key]

    def figures(self, groups: Sequence[str], reaction: Model) -> dict[str, dict[str, Any]]:
        """Per folder of ``groups``: ``ade_ratio`` (reactive ADE / blind ADE), ``clearance_m`` and
        ``recorded_clearance_m`` (median least clearance [m], simulated and recorded), ``collisions`` and
        ``pedestrians``."""
        found: dict[str, dict[str, Any]] = {}
        for group in sorted(groups):
            pairs = [(simulated, recorded) for case in self.of([group])
                     for simulated, recorded in zip(self.rows(case, reaction), case.recorded, strict=True)]
            found[group] = {
                "ade_ratio": float(np.mean([s["ade_m"] for s, _ in pairs])) / self.blind_ade_m[group],
                "clearance_m": float(np.median([s["min_clearance_m"] for s, _ in pairs])),
                "recorded_clearance_m": float(np.median([r["min_clearance_m"] for _, r in pairs])),
                "collisions": int(sum(s["collision"] for s, _ in pairs)), "pedestrians": len(pairs)}
        return found

    def digest(self, groups: Sequence[str]) -> str:
        """SHA-256 of what a fit on the folders ``groups`` depends on: their experiments (names, the pedestrians and
        the vehicle on the 0.4 s grid, the intents) and the vehicle's body."""
        sha = hashlib.sha256(repr(dataclasses.astuple(self.body)).encode())
        for case in self.of(groups):
            sha.update(case.name.encode())
            for values in (case.grid.xy_m, case.grid.vehicle_xy_m, case.grid.vehicle_heading_rad, case.intent.xy_m):
                sha.update(np.ascontiguousarray(np.nan_to_num(values, nan=-1e9)).tobytes())
        return sha.hexdigest()

    def walks_digest(self, groups: Sequence[str], reaction: Model) -> str:
        """SHA-256 of the scores of every pedestrian of the folders ``groups`` walked with ``reaction``: how the code
        walks them."""
        rows = [self.rows(case, reaction) for case in self.of(groups)]
        return hashlib.sha256(strict_json.dumps(rows).encode()).hexdigest()


def loss(per_group: dict[str, dict[str, Any]], clearance_tolerance: float = 0.0) -> float:
    """The fit's loss (module docstring) from ``Scorer.figures``: relative clearance errors up to
    ``clearance_tolerance`` cost nothing."""
    terms = [g["ade_ratio"] + max(abs(g["clearance_m"] - g["recorded_clearance_m"]) / g["recorded_clearance_m"]
                                  - clearance_tolerance, 0.0) for g in per_group.values()]
    collisions = sum(g["collisions"] for g in per_group.values()) / sum(g["pedestrians"] for g in per_group.values())
    return float(np.mean(terms)) + COLLISION_WEIGHT * collisions


@dataclass(frozen=True)
class Procedure:
    """How a reaction is fitted: the ``variant`` (``VARIANTS``), the ``start``, the grids searched in order
    (``search``, names of ``GRIDS``), the most ``sweeps``, whether the grids are ``coarse`` (``axes``), and the
    loss's ``clearance_tolerance`` (``loss``)."""

    variant: str
    start: Reaction
    search: tuple[str, ...]
    sweeps: int
    coarse: bool = False
    clearance_tolerance: float = 0.0

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise ValueError(f"variant {self.variant!r}: expected one of {', '.join(VARIANTS)}")
        if not 0.0 <= self.clearance_tolerance < float("inf"):
            raise ValueError(f"clearance tolerance {self.clearance_tolerance}: expected a finite number >= 0")
        unknown = [name for name in self.search if name not in GRIDS]
        if unknown:
            raise ValueError(f"grid {unknown[0]!r}: expected one of {', '.join(GRIDS)}")

    @property
    def grids(self) -> list[str]:
        """The grids searched: ``search`` without those that touch a field the variant holds, and with the grids of
        the fields it ties searched once, as the first of them (``changes`` sets them all)."""
        variant = VARIANTS[self.variant]
        if variant.grids is not None:
            return list(variant.grids)
        kept = [name for name in self.search if not set(name.split("+")) & set(variant.holds)]
        tied = [name for name in kept if set(name.split("+")) & set(variant.ties)]
        return [name for name in kept if name not in tied or name == (variant.ties[0] if variant.ties else None)]

    def changes(self, name: str, values: tuple[float, ...]) -> dict[str, float]:
        """The fields a trial of grid ``name`` at ``values`` sets: each field of the name, and with the first tied
        field every field the variant ties."""
        ties = VARIANTS[self.variant].ties
        change = dict(zip(name.split("+"), values, strict=True))
        if ties and ties[0] in change:
            change.update({field: change[ties[0]] for field in ties})
        return change

    def axes(self, name: str) -> tuple[tuple[float, ...], ...]:
        """The values of grid ``name`` searched: ``GRIDS``', or, ``coarse``, every other value of an axis of more
        than three (its last kept)."""
        grids = VARIANTS[self.variant].grids or GRIDS
        if not self.coarse:
            return grids[name]
        return tuple(axis if len(axis) <= 3 else tuple(dict.fromkeys((*axis[::2], axis[-1]))) for axis in grids[name])

    @property
    def first(self) -> Model:
        """Where the search starts: ``start`` with the variant's fields held, and its tied fields at the mean of the
        start's values of them."""
        variant = VARIANTS[self.variant]
        if variant.start is not None:
            return variant.start
        tied = {field: float(np.mean([getattr(self.start, f) for f in variant.ties])) for field in variant.ties}
        return dataclasses.replace(self.start, **variant.holds, **tied)

    @property
    def name(self) -> str:
        """The variant and the clearance tolerance, as a fold fit's file names them."""
        return f"{self.variant}-clearance-tolerance-{self.clearance_tolerance:g}"

    def record(self) -> dict[str, Any]:
        """The procedure as JSON: what a fit file says it was fitted by."""
        start = self.first if VARIANTS[self.variant].start is not None else self.start  # (another model's own)
        return {"variant": self.variant, "start": dataclasses.asdict(start), "search": list(self.search),
                "sweeps": self.sweeps, "grids": {name: [list(axis) for axis in self.axes(name)] for name in self.grids},
                "clearance_tolerance": self.clearance_tolerance}


CV_PROCEDURE: Final[Procedure] = Procedure(  # the fitting procedure cross-validated by default: coarse grids, one
    "reactive", FIRST_GUESS, tuple(name for name in GRIDS if name != "delay_cost+aside_cost+crossing_s"),  # sweep,
    sweeps=1, coarse=True,  # so that its four folds take about 25 minutes of one core; the clearance tolerance
    clearance_tolerance=CLEARANCE_TOLERANCE)  # chosen over 0 by the CV criterion (fit_reaction.py --cross-validate)


@dataclass(frozen=True)
class Fit:
    """Where a search ended: the ``reaction``, its ``figures`` (``Scorer.figures``) and ``loss`` on the folders it
    was fitted on (``fitted_on``), and the ``evaluations`` it took."""

    reaction: Model
    figures: dict[str, dict[str, Any]]
    loss: float
    evaluations: int
    fitted_on: tuple[str, ...]

    def record(self) -> dict[str, Any]:
        """As JSON: ``params`` (what ``st_sim.reactive.reaction.read_reaction`` reads), ``figures`` with the loss,
        ``evaluations`` and ``fitted_on``."""
        return {"params": dataclasses.asdict(self.reaction), "figures": {**self.figures, "loss": self.loss},
                "evaluations": self.evaluations, "fitted_on": list(self.fitted_on)}

    @classmethod
    def from_record(cls, record: dict[str, Any]) -> Fit:
        """The fit ``record`` holds (``Fit.record``)."""
        figures = {key: value for key, value in record["figures"].items() if key != "loss"}
        return cls(model_of(record["params"]), figures, float(record["figures"]["loss"]), int(record["evaluations"]),
                   tuple(record["fitted_on"]))


def search(scorer: Scorer, groups: Sequence[str], procedure: Procedure, progress: bool = True,
           log: bool = True) -> Fit:
    """The coordinate descent of ``procedure`` on the folders ``groups`` of ``scorer`` (module docstring);
    deterministic. ``log``: print the loss after each grid."""
    groups = tuple(sorted(groups))
    best = procedure.first
    best_figures = scorer.figures(groups, best)
    best_loss, evaluations = loss(best_figures, procedure.clearance_tolerance), 1
    for sweep in range(procedure.sweeps):
        improved = False
        for name in procedure.grids:
            trials = list(itertools.product(*procedure.axes(name)))
            for values in tqdm(trials, desc=f"sweep {sweep + 1} {name}", leave=False, disable=not progress):
                change = procedure.changes(name, values)
                if all(getattr(best, key) == value for key, value in change.items()):
                    continue
                trial = dataclasses.replace(best, **change)
                trial_figures = scorer.figures(groups, trial)
                trial_loss, evaluations = loss(trial_figures, procedure.clearance_tolerance), evaluations + 1
                if trial_loss < best_loss - 1e-9:
                    best, best_figures, best_loss, improved = trial, trial_figures, trial_loss, True
            if log:
                chosen = ", ".join(f"{key} = {getattr(best, key)}" for key in name.split("+"))
                print(f"[{'+'.join(groups)}] sweep {sweep + 1} {chosen}: loss {best_loss:.4f}", flush=True)
        if not improved:
            break
    return Fit(best, best_figures, best_loss, evaluations, groups)


def fold_fit(scorer: Scorer, training: Sequence[str], procedure: Procedure, folder: Path | None,
             progress: bool = True) -> Fit:
    """``search`` on the folders ``training``, read from ``folder`` when a run of the same procedure on the same data
    wrote it there (``<Procedure.name>-on-<folders>.json``) and the pedestrians still walk as they did then (the start's
    walks on the training data, ``Scorer.walks_digest``: code that walks them otherwise is a new fit), else searched
    and written there atomically (None: not kept)."""
    training = tuple(sorted(training))
    key = {"procedure": procedure.record(), "fitted_on": list(training), "data": scorer.digest(training),
           "start_walks": scorer.walks_digest(training, procedure.first)}
    path = None if folder is None else Path(folder) / f"{procedure.name}-on-{'+'.join(training)}.json"
    if path is not None and path.is_file():
        try:
            kept = json.loads(path.read_text())
            if kept.get("key") == key:
                return Fit.from_record(kept)
        except (OSError, ValueError, KeyError, TypeError):
            pass  # unreadable or another run's: searched again and written over
    fit = search(scorer, training, procedure, progress)
    if path is not None:
        write_text_atomic(path, strict_json.dumps({"key": key, **fit.record()}, indent=1) + "\n")
    return fit


def cv_criterion(mean_ratio: float, worst_ratio: float) -> float:
    """How a fitting procedure's CV score compares (module docstring): max(mean / 0.8, worst / 0.9)."""
    return max(mean_ratio / CV_TARGETS[0], worst_ratio / CV_TARGETS[1])


def cv_score(held_out_ratios: dict[str, float]) -> dict[str, Any]:
    """The CV score of held-out ADE ratios (one per folder left out): ``held_out_ade_ratios``,
    ``mean_ade_ratio``, ``worst_ade_ratio``, ``worst_fold`` and ``criterion`` (``cv_criterion``)."""
    mean, worst = float(np.mean(list(held_out_ratios.values()))), max(held_out_ratios.values())
    return {"held_out_ade_ratios": dict(held_out_ratios), "mean_ade_ratio": mean, "worst_ade_ratio": worst,
            "worst_fold": max(held_out_ratios, key=held_out_ratios.__getitem__),
            "criterion": cv_criterion(mean, worst)}


def cross_validate(scorer: Scorer, procedure: Procedure, folder: Path | None,
                   progress: bool = True) -> dict[str, Fit]:
    """Leave one folder out: per folder of ``scorer``, the fit of ``procedure`` on all the others (``fold_fit``,
    kept in ``folder``), keyed by the folder left out."""
    if len(scorer.groups) < 2:
        raise ValueError(f"cross-validation needs at least two folders of experiments; found {scorer.groups}")
    return {held_out: fold_fit(scorer, [group for group in scorer.groups if group != held_out], procedure, folder,
                               progress) for held_out in scorer.groups}


def held_out_ratios(scorer: Scorer, fits: dict[str, Model]) -> dict[str, float]:
    """Per folder left out, the reactive ADE ratio of its fit (``fits``: folder -> reaction) on that folder."""
    return {held_out: scorer.figures([held_out], reaction)[held_out]["ade_ratio"]
            for held_out, reaction in fits.items()}
