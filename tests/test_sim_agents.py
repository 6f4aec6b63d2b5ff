"""The WOSAC-style realism score (``st_sim.apps.sim_agents``) on hand-made traces: rollouts like the log score higher
than rollouts far from it, values on and beyond the bins' edges, the contact and non-walkable flags, time to
collision, minADE, and a meta score in [0, 1] whatever the rollouts."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from replays.constants import STEP_S
from st_sim.apps.sim_agents import (
    FLAGS,
    HISTOGRAMS,
    PSEUDOCOUNT,
    TTC_MAX_S,
    WEIGHTS,
    Bins,
    Scene,
    features,
    log_likelihoods,
    min_ade_m,
    realism,
)
from st_sim.reactive.footprint import Body
from st_sim.reactive.routes import OpenGround

CART = Body(2.4, 1.2)
DRAWS = settings(max_examples=30, deadline=None)


class WallBeyond:
    """Ground that is not walkable beyond ``x_m`` (depth: how far beyond)."""

    def __init__(self, x_m: float):
        self.x_m = x_m

    def at(self, xy_m: np.ndarray) -> np.ndarray:
        return np.maximum(np.asarray(xy_m)[..., 0] - self.x_m, 0.0)


def scene(walkers: int, steps: int, vehicle_xy: tuple[float, float] = (0.0, -20.0), speed: float = 0.0,
          depth: object | None = None) -> Scene:
    """A vehicle standing (or driving along +x at ``speed``) and ``walkers`` scored pedestrians, all scored over
    every step."""
    t = np.arange(steps) * STEP_S
    xy = np.array(vehicle_xy) + np.c_[speed * t, np.zeros(steps)]
    return Scene(xy, np.zeros(steps), np.full(steps, speed), CART, np.arange(walkers), np.zeros(walkers, int),
                 np.full(walkers, steps - 1), np.full(walkers, steps - 1), OpenGround() if depth is None else depth)


def walks(seed: int, walkers: int, steps: int) -> np.ndarray:
    """(T, W, 2) walkers along +x at 1-1.5 m/s with a little sway, 1.5 m apart."""
    rng = np.random.default_rng(seed)
    t = np.arange(steps)[:, None] * STEP_S
    x = rng.uniform(-5, 0, walkers) + rng.uniform(1.0, 1.5, walkers) * t
    y = 1.5 * np.arange(walkers) + 0.1 * np.sin(t + rng.uniform(0, 6, walkers))
    return np.stack([x, y], axis=-1)


def meta(scene_: Scene, log: np.ndarray, rollouts: np.ndarray) -> dict:
    return realism(log_likelihoods(scene_, log, rollouts), min_ade_m(scene_, log, rollouts))


@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(2, 4), k=st.integers(2, 8), shift=st.floats(3.0, 20.0))
def test_rollouts_like_the_log_score_higher_than_rollouts_far_from_it(seed: int, walkers: int, k: int,
                                                                     shift: float) -> None:
    log = walks(seed, walkers, 30)
    here = scene(walkers, 30)
    rng = np.random.default_rng(seed + 1)
    near = log[None] + rng.normal(0, 0.01, (k, *log.shape))
    spread_out = log[0] * np.array([1.0, 0.0]) + np.c_[np.zeros(walkers), shift * np.arange(walkers)]
    far = np.broadcast_to(spread_out, (k, *log.shape))  # standing where they started, ``shift`` apart
    close, away = meta(here, log, near), meta(here, log, far)
    assert close["meta"] > away["meta"], (close, away)
    assert close["min_ade_m"] < away["min_ade_m"]
    for name in ("speed_mps", "nearest_pedestrian_m"):
        assert close["features"][name] > away["features"][name], name


def test_copies_of_the_log_score_a_steady_feature_almost_one_and_a_varying_one_by_its_spread() -> None:
    """K copies of a log of walkers at a steady pace: speed, acceleration and heading rate take one value each, which
    scores all but the pseudocounts of the other bins; the gap to the vehicle changes bin along the walk, so even
    the log's own copies score it below 1 (WOSAC's caveat: the log does not score 1)."""
    steps, k = 25, 8
    log = np.stack([np.c_[np.linspace(-10, 10, steps), np.full(steps, y)] for y in (0.0, 1.5)], axis=1)
    score = meta(scene(2, steps, vehicle_xy=(0.0, -3.0)), log, np.stack([log] * k))
    assert score["min_ade_m"] == 0.0
    for name in ("speed_mps", "acceleration_mps2", "heading_rate_radps", "nearest_pedestrian_m"):
        values = k * (steps - 2)  # at least this many per histogram (acceleration: from the third step)
        assert score["features"][name] >= (values + PSEUDOCOUNT) / (values + HISTOGRAMS[name].count * PSEUDOCOUNT)
    assert score["features"]["vehicle_contact"] == pytest.approx((k + PSEUDOCOUNT) / (k + 2 * PSEUDOCOUNT))
    assert score["features"]["vehicle_gap_m"] < 0.5


@DRAWS
@given(seed=st.integers(0, 2**31), walkers=st.integers(1, 4), k=st.integers(1, 6), spread=st.floats(0.0, 10.0))
def test_the_meta_score_and_every_feature_score_lie_in_0_1(seed: int, walkers: int, k: int, spread: float) -> None:
    log = walks(seed, walkers, 20)
    rng = np.random.default_rng(seed)
    rollouts = log[None] + rng.normal(0, spread + 1e-9, (k, *log.shape)).cumsum(axis=1)
    score = meta(scene(walkers, 20), log, rollouts)
    assert 0.0 <= score["meta"] <= 1.0
    assert set(score["features"]) == set(WEIGHTS) == {*HISTOGRAMS, *FLAGS}
    assert all(0.0 < value <= 1.0 for name, value in score["features"].items()
               if name != "nearest_pedestrian_m" or walkers > 1), score
    assert (score["features"]["nearest_pedestrian_m"] is None) == (walkers == 1), "alone: no nearest pedestrian"
    assert np.isclose(sum(WEIGHTS.values()), 1.0) and max(WEIGHTS, key=WEIGHTS.__getitem__) == "vehicle_contact"


def test_values_on_and_beyond_the_edges_fall_in_their_bins() -> None:
    bins = Bins(0.0, 4.0, 8)  # edges every 0.5, exact in binary
    values = np.array([-1e9, -0.5, 0.0, 0.25, 0.5, 3.5, 3.75, 4.0, 4.5, 1e9])
    assert bins.index(values).tolist() == [0, 0, 0, 0, 1, 7, 7, 7, 7, 7]
    on_inner_edges = bins.edges[1:-1]
    assert bins.index(on_inner_edges).tolist() == list(range(1, 8)), "an inner edge belongs to the bin above it"
    assert bins.index(np.nextafter(on_inner_edges, -np.inf)).tolist() == list(range(0, 7))


@settings(max_examples=50, deadline=None)
@given(low=st.floats(-10, 10), width=st.floats(0.1, 10), count=st.integers(1, 20),
       values=st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=30))
def test_every_value_falls_in_a_bin_whose_range_holds_it_or_the_end_bin(low: float, width: float, count: int,
                                                                       values: list[float]) -> None:
    bins = Bins(low, low + width, count)
    index = bins.index(np.array(values))
    assert ((index >= 0) & (index < count)).all()
    edges = bins.edges
    for value, i in zip(values, index, strict=True):
        inside = edges[0] <= value <= edges[-1]
        assert not inside or edges[i] <= value <= edges[i + 1]
        assert inside or i == (0 if value < edges[0] else count - 1)


def test_a_logged_value_beyond_the_range_is_scored_in_the_end_bin() -> None:
    """A recorded speed of 10 m/s (beyond the 3 m/s range) scores as well as the rollouts' 3.5 m/s: both the end bin."""
    here = scene(1, 3)
    log = np.array([[[0.0, 0.0]], [[4.0, 0.0]], [[8.0, 0.0]]])  # 10 m/s
    rollouts = np.array([[[[0.0, 0.0]], [[1.4, 0.0]], [[2.8, 0.0]]]] * 4)  # 3.5 m/s
    speed = log_likelihoods(here, log, rollouts)["speed_mps"]
    count = 4 * 2  # rollouts x steps with a speed
    assert np.allclose(speed, np.log((count + PSEUDOCOUNT) / (count + HISTOGRAMS["speed_mps"].count * PSEUDOCOUNT)))


def test_a_pedestrian_walking_into_the_vehicle_raises_the_contact_flag_even_between_two_steps() -> None:
    """Walking into the cart, through it between two steps (never inside at a step), and past it 1 m clear."""
    here = scene(3, 6, vehicle_xy=(0.0, 0.0))
    x = np.linspace(-7.5, 7.5, 6)  # 3 m a step: from x = -1.5 to 1.5 in one step, over the 2.4 m long cart
    into = np.c_[np.linspace(-6.0, 0.0, 6), np.zeros(6)]
    through = np.c_[x, np.zeros(6)]
    past = np.c_[x, np.full(6, 1.6)]
    crowd = np.stack([into, through, past], axis=1)[None]
    assert CART.gap_m(through - 0.0, 0.0).min() > 0, "the hand-made walk should never stand inside the cart"
    _, flags = features(here, crowd)
    assert flags["vehicle_contact"][0].tolist() == [True, True, False]
    assert not flags["non_walkable"].any()


def test_the_contact_flag_scores_the_share_of_rollouts_that_agree_with_the_log() -> None:
    here = scene(2, 6, vehicle_xy=(0.0, 0.0))
    clear = np.stack([np.c_[np.linspace(-6, 6, 6), np.full(6, 2.0)], np.c_[np.linspace(-6, 6, 6), np.full(6, -2.0)]],
                     axis=1)
    hit = clear.copy()
    hit[:, 0, 1] = 0.0  # the first walks through the cart
    rollouts = np.stack([hit, hit, hit, clear])  # 3 of 4 rollouts hit, the log does not
    contact = log_likelihoods(here, clear, rollouts)["vehicle_contact"]
    assert np.allclose(contact, np.log([(1 + PSEUDOCOUNT) / (4 + 2 * PSEUDOCOUNT),
                                        (4 + PSEUDOCOUNT) / (4 + 2 * PSEUDOCOUNT)]))


def test_standing_on_non_walkable_ground_raises_its_flag() -> None:
    here = scene(2, 5, depth=WallBeyond(3.0))
    crowd = np.stack([np.c_[np.linspace(0, 5, 5), np.zeros(5)], np.c_[np.linspace(0, 2, 5), np.full(5, 3.0)]],
                     axis=1)
    _, flags = features(here, crowd[None])
    assert flags["non_walkable"][0].tolist() == [True, False]


@pytest.mark.parametrize("start_x, speed, expected", [(4.25, -1.5, None), (4.2, 1.5, TTC_MAX_S),
                                                      (12.2, -1.0, TTC_MAX_S), (1.0, 0.0, 0.0)],
                         ids=["toward", "away", "too-far", "inside"])
def test_time_to_collision_holds_both_velocities(start_x: float, speed: float, expected: float | None) -> None:
    """A pedestrian on the cart's axis walking toward its front (1.2 m from its centre), away, too far to reach it in
    5 s, and standing inside it."""
    here = scene(1, 3, vehicle_xy=(0.0, 0.0))
    xy = np.c_[start_x + speed * STEP_S * np.arange(3), np.zeros(3)][:, None]
    ttc = features(here, xy[None])[0]["time_to_collision_s"][0, :, 0]
    assert np.isnan(ttc[0]), "no velocity at the first step of the window"
    first = expected if expected is not None else (start_x + speed * STEP_S - 1.2) / -speed
    assert first <= ttc[1] + 1e-9 <= first + 0.1 + 2e-9, "the first 0.1 s sample at or after the entry"


def test_time_to_collision_counts_the_vehicles_motion() -> None:
    """A pedestrian standing 4.25 m ahead of a cart's centre at step 1, the cart driving at it at 2 m/s: its front
    (1.2 m ahead of its centre) reaches the pedestrian in 1.525 s."""
    here = scene(1, 3, vehicle_xy=(0.0, 0.0), speed=2.0)
    xy = np.tile([[4.25 + 2.0 * STEP_S, 0.0]], (3, 1))[:, None]  # stands; the cart's centre is at x = 0.8 at step 1
    ttc = features(here, xy[None])[0]["time_to_collision_s"][0, :, 0]
    assert ttc[1] == pytest.approx(1.6), "the first 0.1 s sample at or after the entry"


def test_min_ade_is_the_best_rollout_over_the_ade_window() -> None:
    here = scene(1, 5)
    log = np.zeros((5, 1, 2))
    rollouts = np.stack([log + 3.0, log + np.array([0.0, 1.0]), log + 2.0])
    assert min_ade_m(here, log, rollouts).tolist() == [1.0]
