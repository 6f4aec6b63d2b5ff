"""When a reactive pedestrian notices the robot, when it reacts, and how much room it then keeps: the fitted part of
the reactive pedestrians (``st_sim.reactive.reactive`` does the walking).

- **Noticing.** A pedestrian notices the robot when the nearest point of the robot's body lies within its field of
  view (``fov_deg`` either side of its walking direction, at any distance) or within ``hearing_m`` of it, whatever
  the bearing. One that stops noticing it keeps it in mind for ``MEMORY_S``, then forgets it.
- **Reacting.** It reacts ``reaction_s`` after it first noticed the robot, fractions of a 0.4 s step by
  interpolation: its reaction's weight grows from 0 to 1 over the step in which that time passes.
- **Room.** A reacting pedestrian keeps ``clearance_m`` from the robot's body, plus, while the robot comes toward it,
  the robot's speed times ``head_on_s`` (the robot's heading opposite to its own walking direction), ``behind_s``
  (the same direction) or ``crossing_s`` (square to it), blended by the cosine of the angle between the two; it looks
  ``anticipation_s`` ahead along its route and the robot's expected course.
- **Yielding or stepping aside.** Off its log, each step it weighs ``delay_cost`` per 0.4 s frame it falls behind
  its log against ``aside_cost`` per metre it stands to the side of its route: the dearer the side, the more it slows
  or waits and passes behind the robot rather than stepping round it in front.
- **People differ.** Each pedestrian carries four traits (``TRAITS``, one row of an (A, 4) array), factors on the
  fitted reaction: its noticing distance (``hearing_m``), its reaction time (``reaction_s``), the room it keeps and
  how dear standing aside is to it (``aside_cost``: the dearer, the more it waits). ``typical`` (every factor 1) is
  the fitted pedestrian, bit for bit; ``draw_traits`` draws each factor from exp(N(0, sigma)) with the sigmas of a
  ``Spread`` (``fitted_spread``: the sigma whose rollouts score the highest realism with the shipped reaction on
  CITR, ``benchmarks/fit_spread.py``, which also measures what it is worth cross-validated: nothing measurable).

The values are fitted on CITR's pedestrians reacting to a golf cart (``benchmarks/fit_reaction.py``, written to
``reaction_fit.json`` beside this module, which ``fitted_reaction`` reads); they are not a safety rule. The safety
rules (nobody walks into the robot's body, noticed or not) are in ``st_sim.reactive.reactive`` and
``st_sim.reactive.candidates``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from functools import cache
from pathlib import Path
from typing import Any, Final

import numpy as np

from replays.constants import STEP_S
from st_sim.errors import ConfigError
from st_sim.sim.exact import dot, exp, length

FIT_PATH: Final[Path] = Path(__file__).with_name("reaction_fit.json")
SPREAD_PATH: Final[Path] = Path(__file__).with_name("spread_fit.json")
MEMORY_S: Final[float] = 2.0  # a pedestrian that stops noticing the robot keeps it in mind this long [s]
MOVING_MPS: Final[float] = 0.2  # walking direction: its velocity when faster than this, else its route's [m/s]
TRAITS: Final[tuple[str, ...]] = ("noticing", "reaction", "room", "patience")
"""the columns of a traits array: factors on ``hearing_m``, ``reaction_s``, the room kept and ``aside_cost``"""
NOTICING, REACTION_TIME, ROOM, PATIENCE = range(len(TRAITS))
TRAIT_RANGE: Final[tuple[float, float]] = (0.25, 4.0)  # a drawn factor is kept within this [-]


@dataclass(frozen=True)
class Reaction:
    """How reactive pedestrians notice and keep clear of the robot (module docstring); every field is fitted."""

    fov_deg: float
    """half-angle of the field of view round the walking direction [deg]"""
    hearing_m: float
    """the robot is noticed within this gap of its body whatever its bearing [m]"""
    reaction_s: float
    """from noticing the robot to reacting to it [s]"""
    anticipation_s: float
    """how far ahead a reacting pedestrian checks its route against the robot's expected course [s]"""
    clearance_m: float
    """room kept from the body of a robot that stands or moves away [m]"""
    head_on_s: float
    """more room per m/s of a robot coming head-on [s]"""
    behind_s: float
    """more room per m/s of a robot coming from behind [s]"""
    crossing_s: float
    """more room per m/s of a robot crossing the pedestrian's way [s]"""
    delay_cost: float
    """cost of falling a 0.4 s frame behind its log, off its log [1/frame]"""
    aside_cost: float
    """cost of standing a metre to the side of its route, off its log [1/m]"""

    @property
    def anticipation_steps(self) -> int:
        """``anticipation_s`` in whole 0.4 s steps (at least 1)."""
        return max(1, round(self.anticipation_s / STEP_S))

    def weight(self, noticed_s: np.ndarray, traits: np.ndarray) -> np.ndarray:
        """(...) how far each pedestrian reacts over this step, in [0, 1], from the time ``noticed_s`` (...) it has had
        the robot in mind at the end of the step [s] and its ``traits`` (..., 4)."""
        return np.clip((noticed_s - self.reaction_s * traits[..., REACTION_TIME]) / STEP_S, 0.0, 1.0)

    def room_m(self, robot_velocity_mps: np.ndarray, robot_heading: np.ndarray, walking: np.ndarray,
               coming: np.ndarray) -> np.ndarray:
        """(A,) room each pedestrian keeps from the robot's body [m].

        Args:
            robot_velocity_mps: (2,) the robot's expected velocity [m/s].  robot_heading: (2,) its unit heading.
            walking: (A, 2) unit walking directions.  coming: (A,) bool, the robot comes toward the pedestrian.
        """
        cosine = dot(walking, robot_heading)  # -1 head-on, +1 from behind, 0 crossing
        per_mps = (self.head_on_s * np.maximum(-cosine, 0.0) + self.behind_s * np.maximum(cosine, 0.0)
                   + self.crossing_s * (1.0 - np.abs(cosine)))
        return self.clearance_m + np.where(coming, length(robot_velocity_mps) * per_mps, 0.0)


def read_reaction(path: Path) -> Reaction:
    """The reaction in a fit file (``{"params": {field: number, ...}}``, as ``benchmarks/fit_reaction.py`` writes);
    ``ConfigError`` naming the file and the field when it cannot be read."""
    try:
        fit = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such reaction fit file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ConfigError(f"{path}: not a readable JSON reaction fit ({err})") from err
    if not isinstance(fit, dict) or "params" not in fit:
        raise ConfigError(f"{path}: no params (a reaction fit names every field of Reaction)")
    return reaction_of(fit["params"], str(path), "params")


def reaction_of(params: Any, source: str, key: str) -> Reaction:
    """The reaction of ``params`` (``{field: number, ...}``, found at ``key`` in ``source``); ``ConfigError`` naming
    the source, the key and the field when a field is missing or not a finite number >= 0."""
    try:
        values = {field.name: float(params[field.name]) for field in fields(Reaction)}
    except KeyError as err:
        raise ConfigError(f"{source}: no {key}.{err.args[0]} (a reaction fit names every field of Reaction)") from None
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{source}: {key} must map every field of Reaction to a number ({err})") from err
    bad = [name for name, value in values.items() if not np.isfinite(value) or value < 0]
    if bad:
        raise ConfigError(f"{source}: {key}.{bad[0]} = {values[bad[0]]}: expected a finite number >= 0")
    return Reaction(**values)


def read_fitted_on(path: Path) -> tuple[str, ...] | None:
    """The folders of experiments a fit file says it was fitted on (its ``fitted_on``), None where it does not say;
    ``ConfigError`` naming the file when that is not a list of names."""
    try:
        folders = json.loads(Path(path).read_text()).get("fitted_on")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError) as err:
        raise ConfigError(f"{path}: not a readable JSON reaction fit ({err})") from err
    if folders is not None and not (isinstance(folders, list) and all(isinstance(f, str) for f in folders)):
        raise ConfigError(f"{path}: fitted_on = {folders!r}: expected a list of folder names")
    return None if folders is None else tuple(folders)


@cache
def fitted_reaction() -> Reaction:
    """The shipped fitted reaction (``reaction_fit.json``), read once per process."""
    return read_reaction(FIT_PATH)


def notices(reaction: Reaction, gap_m: np.ndarray, bearing_rad: np.ndarray, traits: np.ndarray) -> np.ndarray:
    """(...) bool: pedestrians that notice the robot, from the gap to its body (...) [m], the angle (...) [rad]
    between their walking direction and the direction to the body's nearest point, and their ``traits`` (..., 4)."""
    return ((gap_m <= reaction.hearing_m * traits[..., NOTICING])
            | (np.abs(bearing_rad) <= np.radians(reaction.fov_deg)))


def attend(noticed_s: np.ndarray, unseen_s: np.ndarray, noticing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Advance each pedestrian's attention by one step: (time it has had the robot in mind, time since it last
    noticed it) [s], both (A,), after a step in which it does or does not notice it (``noticing``, (A,) bool)."""
    unseen = np.where(noticing, 0.0, unseen_s + STEP_S)
    kept = noticing | ((noticed_s > 0) & (unseen <= MEMORY_S))
    return np.where(kept, noticed_s + STEP_S, 0.0), np.where(kept, unseen, 0.0)


def typical(agents: int) -> np.ndarray:
    """(agents, 4) the traits of the fitted pedestrian: every factor 1."""
    return np.ones((agents, len(TRAITS)))


@dataclass(frozen=True)
class Spread:
    """How much pedestrians differ: the sigma of the log of each trait's factor (``draw_traits``); all 0: everybody
    the fitted pedestrian."""

    noticing: float = 0.0
    reaction: float = 0.0
    room: float = 0.0
    patience: float = 0.0

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value <= 2:
                raise ConfigError(f"Spread.{field.name} = {value!r}: expected a number in [0, 2]")

    @classmethod
    def even(cls, sigma: float) -> Spread:
        """The same sigma for every trait."""
        return cls(*(sigma,) * len(TRAITS))

    def sigmas(self) -> np.ndarray:
        """(4,) the sigmas in ``TRAITS``' order."""
        return np.array([getattr(self, name) for name in TRAITS], np.float64)


def draw_traits(rng: np.random.Generator, agents: int, spread: Spread) -> np.ndarray:
    """(agents, 4) traits drawn from ``rng``: each factor exp(N(0, sigma)) (``st_sim.sim.exact.exp``: the same bits on
    every CPU), kept within ``TRAIT_RANGE``; a spread of zeros draws nothing and gives ``typical``."""
    sigmas = spread.sigmas()
    if not sigmas.any():
        return typical(agents)
    return np.clip(exp(rng.normal(0.0, 1.0, (agents, len(TRAITS))) * sigmas), *TRAIT_RANGE)


def read_spread(path: Path) -> Spread:
    """The spread in a file (``{"spread": {trait: sigma, ...}}``, as ``benchmarks/fit_spread.py`` writes);
    ``ConfigError`` naming the file and the field when it cannot be read."""
    try:
        values = json.loads(Path(path).read_text())["spread"]
        return Spread(**{name: values[name] for name in TRAITS})
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such spread file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, TypeError) as err:
        raise ConfigError(f"{path}: not a readable JSON spread ({err})") from err
    except KeyError as err:
        raise ConfigError(f"{path}: no spread.{err.args[0]} (a spread names every trait: "
                          f"{', '.join(TRAITS)})") from None
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None


@cache
def fitted_spread() -> Spread:
    """The shipped spread (``spread_fit.json``), read once per process."""
    return read_spread(SPREAD_PATH)
