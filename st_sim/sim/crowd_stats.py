"""Statistics of a crowd recording, real or simulated: step speeds, standing spells, walkers' speeds, groups,
nearest-neighbour distances, and the two halves of a recording.

Speeds are displacements between consecutive annotated frames of the same person (frame ids FRAME_STRIDE
apart) divided by 0.4 s. ``benchmarks/fit_populations.py`` turns these statistics of the ETH/UCY recordings
into ``PopulationConfig``s; ``benchmarks/realism.py`` compares simulated and real crowds with them.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise
from typing import Final

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from replays.constants import FRAME_STRIDE, STEP_S
from replays.recording import Recording
from st_sim.sim.diagnostics import nearest_neighbour_m

STAND_MPS: Final[float] = 0.25  # a step slower than this is a standing step [m/s]
STAND_MIN_STEPS: Final[int] = 3  # standing steps in a row that make a standing spell (1.2 s) [-]
GROUP_DISTANCE_M: Final[float] = 1.2  # two walkers this close on average walk together ... [m]
GROUP_SPEED_DIFF_MPS: Final[float] = 0.3  # ... if their velocities differ by less than this on average ... [m/s]
GROUP_MIN_STEPS: Final[int] = 5  # ... over at least this many common steps (2 s) [-]


@dataclass(frozen=True)
class Steps:
    """Consecutive-frame steps of every person, sorted by person then frame.

    Attributes:
        agent: (M,) int64 person of each step.  frame: (M,) int64 frame at the start of the step.
        xy_m: (M, 2) position at the start [m].  velocity_mps: (M, 2) displacement / 0.4 s [m/s].
        speed_mps: (M,) its norm [m/s].
    """

    agent: np.ndarray
    frame: np.ndarray
    xy_m: np.ndarray
    velocity_mps: np.ndarray
    speed_mps: np.ndarray

    @classmethod
    def of(cls, rec: Recording) -> Steps:
        order = np.lexsort((rec.frame, rec.agent))
        f, a, p = rec.frame[order], rec.agent[order], rec.xy_m[order]
        consecutive = (a[1:] == a[:-1]) & (f[1:] - f[:-1] == FRAME_STRIDE)
        velocity = (p[1:] - p[:-1])[consecutive] / STEP_S
        return cls(a[:-1][consecutive], f[:-1][consecutive], p[:-1][consecutive], velocity,
                   np.linalg.norm(velocity, axis=1))


def standing_steps(steps: Steps) -> tuple[np.ndarray, np.ndarray]:
    """Standing spells: runs of at least STAND_MIN_STEPS steps slower than STAND_MPS of one person, with no
    frame missing between them.

    Returns:
        standing: (M,) bool, True for the steps inside a spell.  spells: (S,) int spell lengths [steps].
    """
    slow = steps.speed_mps < STAND_MPS
    new_run = np.r_[True, (steps.agent[1:] != steps.agent[:-1]) | (steps.frame[1:] - steps.frame[:-1] != FRAME_STRIDE)
                    | (slow[1:] != slow[:-1])]
    run_id = np.cumsum(new_run) - 1
    length = np.bincount(run_id)
    standing = slow & (length[run_id] >= STAND_MIN_STEPS)
    starts = np.flatnonzero(new_run)
    spell_starts = starts[standing[starts]]
    return standing, length[run_id[spell_starts]]


def walker_speeds_mps(steps: Steps, standing: np.ndarray, min_steps: int = 3) -> np.ndarray:
    """(P,) median speed [m/s] of the walking (not standing) steps of each person with at least min_steps."""
    agent, speed = steps.agent[~standing], steps.speed_mps[~standing]
    _, inverse, count = np.unique(agent, return_inverse=True, return_counts=True)
    order = np.argsort(inverse, kind="stable")
    groups = np.split(speed[order], np.cumsum(count)[:-1])
    return np.array([np.median(g) for g, c in zip(groups, count, strict=True) if c >= min_steps])


def walking_groups(steps: Steps, standing: np.ndarray) -> tuple[float, float]:
    """Share of walkers who walk in a group, and the share of groups with three or more members.

    Two people walk together when, over at least GROUP_MIN_STEPS common walking steps, they are on average
    closer than GROUP_DISTANCE_M and their velocities differ on average by less than GROUP_SPEED_DIFF_MPS;
    groups are the connected sets of such pairs. Walkers are people with at least GROUP_MIN_STEPS walking steps.
    """
    walking = ~standing
    agent, frame, xy, vel = steps.agent[walking], steps.frame[walking], steps.xy_m[walking], steps.velocity_mps[walking]
    people, person = np.unique(agent, return_inverse=True)
    walkers = np.bincount(person, minlength=len(people)) >= GROUP_MIN_STEPS
    order = np.argsort(frame, kind="stable")
    frame, person, xy, vel = frame[order], person[order], xy[order], vel[order]
    starts = np.flatnonzero(np.r_[True, frame[1:] != frame[:-1], True])
    n = len(people)
    common, close, alike = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
    for a, b in pairwise(starts):
        if b - a < 2:
            continue
        p = person[a:b]
        i, j = np.triu_indices(b - a, k=1)
        dist = np.linalg.norm(xy[a:b][i] - xy[a:b][j], axis=1)
        diff = np.linalg.norm(vel[a:b][i] - vel[a:b][j], axis=1)
        near = dist < 3 * GROUP_DISTANCE_M  # far pairs can never average below the threshold often enough
        np.add.at(common, (p[i][near], p[j][near]), 1)
        np.add.at(close, (p[i][near], p[j][near]), dist[near])
        np.add.at(alike, (p[i][near], p[j][near]), diff[near])
    count = np.maximum(common, 1)
    together = ((common >= GROUP_MIN_STEPS) & (close / count < GROUP_DISTANCE_M)
                & (alike / count < GROUP_SPEED_DIFF_MPS) & walkers[:, None] & walkers[None, :])
    together |= together.T
    _, label = connected_components(coo_matrix(together), directed=False)
    size = np.bincount(label)[label]
    grouped = walkers & (size > 1)
    sizes = np.bincount(label[grouped])
    sizes = sizes[sizes > 0]
    return float(grouped.sum() / max(walkers.sum(), 1)), float((sizes >= 3).mean()) if sizes.size else 0.0


def frame_nearest_neighbours_m(rec: Recording) -> np.ndarray:
    """Distance [m] from every person of every frame with at least two people to the nearest other one."""
    order = np.argsort(rec.frame, kind="stable")
    frame, xy = rec.frame[order], rec.xy_m[order]
    starts = np.flatnonzero(np.r_[True, frame[1:] != frame[:-1]])
    return np.concatenate([nearest_neighbour_m(g) for g in np.split(xy, starts[1:])] + [np.zeros(0)])


def people_per_frame(rec: Recording) -> float:
    """Mean number of people per annotated frame."""
    return float(len(rec.frame) / max(len(np.unique(rec.frame)), 1))


def halves(rec: Recording) -> tuple[Recording, Recording]:
    """The recording split at its middle frame (frames before it, and from it on)."""
    middle = np.median(np.unique(rec.frame))
    first = rec.frame < middle
    return (Recording(f"{rec.name}_first", rec.frame[first], rec.agent[first], rec.xy_m[first]),
            Recording(f"{rec.name}_second", rec.frame[~first], rec.agent[~first], rec.xy_m[~first]))


def merged(recs: list[Recording], name: str) -> Recording:
    """Recordings as one (their frames and agent ids must not collide)."""
    return Recording(name, *(np.concatenate([getattr(r, k) for r in recs]) for k in ("frame", "agent", "xy_m")))


def scene_recordings(scene: str) -> list[Recording]:
    """An ETH/UCY scene's test recordings (``raw/all_data``, data root from ``replays.data_root``), agent ids
    made distinct across files and the files' frames kept apart, so that they can be ``merged``."""
    from replays import SCENES, data_root, read_recording

    out, frame_offset, agent_offset = [], 0, 0
    for name in SCENES[scene].recordings:
        rec = read_recording(data_root() / "raw" / "all_data" / f"{name}.txt")
        out.append(Recording(name, rec.frame + frame_offset, rec.agent + agent_offset, rec.xy_m))
        frame_offset += int(rec.frame.max()) + 10 * FRAME_STRIDE
        agent_offset += int(rec.agent.max()) + 1
    return out
