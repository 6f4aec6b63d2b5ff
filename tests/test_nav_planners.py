"""Planners: each one avoids a single crossing pedestrian that the straight planner walks into."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from robot_obs import facing

from replays.constants import STEP_S, T_OBS, T_PRED
from replays.scenes import Scene
from st_sim.apps.navigation.planners import PLANNERS, make_planner
from st_sim.apps.navigation.world import NavWorld

GOAL = np.array([12.0, 0.0])
CROSSER_START = np.array([4.0, -2.7])  # walks north at 1 m/s and meets a full-speed straight ego at x = 4 m
CROSSER_VELOCITY = np.array([0.0, 1.0])
SAMPLES = 20


@pytest.fixture(scope="module")
def open_world() -> NavWorld:
    """A 30 m x 30 m walkable square (0.1 m per pixel) around the crossing; a point robot without inertia."""
    H = np.array([[0.1, 0.0, -10.0], [0.0, 0.1, -10.0], [0.0, 0.0, 1.0]])  # world = 0.1 * pixel - 10 m
    return NavWorld(Scene("open", H, np.ones((300, 300), bool)), (-4.0, -8.0, 16.0, 8.0))


def observation(ego_xy: np.ndarray, ego_v: np.ndarray, step: int) -> dict[str, np.ndarray]:
    """The crossing at env step ``step``: one pedestrian with 8 observed steps and 20 constant-velocity futures
    fanned out by +-10 degrees."""
    times = (step + np.arange(-T_OBS + 1, T_PRED + 1)) * STEP_S
    track = CROSSER_START + times[:, None] * CROSSER_VELOCITY  # (T_obs + 12, 2)
    obs = {"ego": np.array([*ego_xy, *ego_v, *GOAL, *facing(ego_xy, ego_v, GOAL), 0.0], np.float32),
           "history": np.zeros((2, T_OBS, 2), np.float32), "history_mask": np.zeros((2, T_OBS), bool),
           "futures": np.zeros((2, SAMPLES, T_PRED, 2), np.float32), "futures_mask": np.zeros(2, bool)}
    obs["history"][0], obs["history_mask"][0] = track[:T_OBS], True
    angles = np.radians(np.linspace(-10, 10, SAMPLES))
    ahead = np.arange(1, T_PRED + 1)[:, None] * STEP_S
    rotated = np.stack([np.cos(angles), np.sin(angles)], 1) @ np.array([[0.0, 1.0], [-1.0, 0.0]])  # fan around +y
    obs["futures"][0] = track[T_OBS - 1] + ahead[None] * rotated[:, None] * np.linalg.norm(CROSSER_VELOCITY)
    obs["futures_mask"][0] = True
    return obs


def closest_approach(planner_name: str, world: NavWorld, predictor: str) -> tuple[float, float]:
    """(least centre distance to the crosser [m], final distance to the goal [m]) over 30 steps."""
    planner = make_planner(planner_name, world, predictor)
    planner.reset()
    ego_xy, ego_v, closest = np.zeros(2), np.zeros(2), np.inf
    for step in range(30):
        command = np.asarray(planner.act(observation(ego_xy, ego_v, step)), np.float64)
        speed = np.linalg.norm(command)
        ego_v = command * min(1.0, world.max_speed_mps / speed) if speed > 0 else command
        for fraction in np.linspace(0.1, 1.0, 10):  # check between the steps too
            crosser = CROSSER_START + (step + fraction) * STEP_S * CROSSER_VELOCITY
            closest = min(closest, float(np.linalg.norm(ego_xy + fraction * STEP_S * ego_v - crosser)))
        ego_xy = ego_xy + STEP_S * ego_v
    return closest, float(np.linalg.norm(GOAL - ego_xy))


def test_straight_planner_walks_into_the_crosser(open_world: NavWorld) -> None:
    closest, _ = closest_approach("straight", open_world, "none")
    assert closest < open_world.contact_m, f"the scenario should make the straight planner collide ({closest:.2f} m)"


AVOIDERS = [("orca", "none"), ("mpc", "cvm"), ("mpc", "singular"), ("ppo", "singular"), ("ppo", "none"),
            ("ppo-reactive", "singular"), ("ppo-reactive", "none"), ("ppo-suite", "singular"), ("ppo-suite", "none"),
            ("ppo-suite-shield", "singular"), ("ppo-suite-2", "singular")]


@pytest.mark.parametrize(("planner", "predictor"), AVOIDERS,
                         ids=["orca-none", "mpc-cvm", "mpc-singular", "ppo-singular", "ppo-none",
                              "ppo-reactive-singular", "ppo-reactive-none", "ppo-suite-singular", "ppo-suite-none",
                              "ppo-suite-shield-singular", "ppo-suite-2-singular"])
def test_planner_avoids_the_crosser_and_moves_on(open_world: NavWorld, planner: str, predictor: str) -> None:
    if planner == "orca":
        pytest.importorskip("pyrvo", reason='ORCA needs the optional extra: pip install -e ".[orca]"')
    closest, to_goal = closest_approach(planner, open_world, predictor)
    assert closest >= open_world.contact_m, f"{planner}/{predictor} touched the crosser ({closest:.2f} m)"
    assert to_goal < 12.0 - 3.0, f"{planner}/{predictor} made no headway ({to_goal:.2f} m left)"


def test_every_planner_is_registered_and_unknown_names_fail(open_world: NavWorld) -> None:
    assert set(PLANNERS) == {"straight", "orca", "mpc", "ppo", "ppo-reactive", "ppo-suite", "ppo-suite-shield",
                             "ppo-suite-2"}
    with pytest.raises(ValueError, match="planner='teleport'"):
        make_planner("teleport", open_world, "none")
    with pytest.raises(ValueError, match="predictor='oracle'"):
        make_planner("mpc", open_world, "oracle")


def test_orca_without_pyrvo_names_the_extra(open_world: NavWorld, monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "pyrvo", None)  # import pyrvo now raises ImportError
    with pytest.raises(ImportError, match=r'pip install -e "\.\[orca\]"'):
        make_planner("orca", open_world, "none")


def test_mpc_weighs_samples_by_their_prior(open_world: NavWorld) -> None:
    """A pedestrian beside the path: its 15 likely samples stay put, 5 unlikely ones walk onto the path (the robot
    already drives along it at full speed)."""
    obs = observation(np.zeros(2), np.array([open_world.max_speed_mps, 0.0]), 0)
    stay = np.array([3.0, 1.5])
    obs["history"][0] = stay
    samples = np.repeat(stay[None, None], SAMPLES, axis=0).repeat(T_PRED, axis=1)  # (S, 12, 2)
    ahead = np.arange(1, T_PRED + 1) * STEP_S
    samples[15:, :, 1] = stay[1] - 0.75 * ahead  # crosses y = 0 at x = 3 m after 2 s, as the ego would
    obs["futures"][0] = samples
    prior = np.r_[np.full(15, 0.99 / 15), np.full(5, 0.01 / 5)]
    heading_deg = {}
    for name, world in (("prior", replace(open_world, sample_prior=prior)), ("uniform", open_world)):
        command = make_planner("mpc", world, "singular").act(obs)
        heading_deg[name] = np.degrees(np.arctan2(command[1], command[0]))
        assert np.linalg.norm(command) > 0.5, f"{name}: the ego should move"
    assert abs(heading_deg["prior"]) < 1.0, f"unlikely samples should not bend the path ({heading_deg})"
    assert abs(heading_deg["uniform"]) > 10.0, f"a quarter of equally likely samples on the path should ({heading_deg})"


def test_mpc_risk_counts_every_pedestrian_in_the_way(open_world: NavWorld) -> None:
    """The risk is the expected number of collisions: it does not saturate at 1, so of two paths that both meet
    pedestrians for certain, the one through fewer of them costs less."""
    from st_sim.apps.navigation.mpc import MpcPlanner
    from st_sim.apps.navigation.pedestrians import Pedestrians

    planner = make_planner("mpc", open_world, "singular")
    assert isinstance(planner, MpcPlanner)
    standing = np.array([[1.0, 0.0], [0.0, 3.0], [0.2, 3.0]])  # one on the path east, two on the path north
    peds = Pedestrians(standing, np.zeros((3, 2)), np.repeat(standing[:, None, None], SAMPLES, 1).repeat(8, 2),
                       np.ones(3, bool))
    checks = planner._check_steps[:, None] * STEP_S * open_world.max_speed_mps  # (J, 1) distance covered [m]
    paths = np.stack([checks * [1.0, 0.0], checks * [0.0, 1.0]])  # (2, J, 2): east, north
    risk, _ = planner._risk_terms(paths, np.zeros(2), peds)
    assert 0.5 < risk[0] <= 1.0, "the east path meets one standing pedestrian, soon"
    assert risk[1] > 1.0, "the north path meets two, later: two certain collisions count more than one"


def test_mpc_risk_limit_overrides_progress(open_world: NavWorld) -> None:
    """With the risk and clearance costs off, only the limit keeps the MPC off a path on which a pedestrian
    stands in 12 of 20 equally likely samples."""
    from st_sim.apps.navigation.mpc import MpcConfig

    obs = observation(np.zeros(2), np.zeros(2), 0)
    obs["history"][0] = np.array([2.0, 0.0])
    samples = np.full((SAMPLES, T_PRED, 2), [2.0, 0.0])
    samples[12:] = [2.0, 6.0]  # the other 8 samples are far off
    obs["futures"][0] = samples
    heading_deg = {}
    for limit in (np.inf, 0.3):
        cfg = MpcConfig(risk_weight=0.0, clearance_weight=0.0, risk_limit=limit)
        command = make_planner("mpc", open_world, "cvm-s", cfg=cfg).act(obs)
        heading_deg[limit] = abs(np.degrees(np.arctan2(command[1], command[0])))
    assert heading_deg[np.inf] < 1.0, f"without a limit nothing should bend the path ({heading_deg})"
    assert heading_deg[0.3] > 10.0, f"the limit should turn the ego off the pedestrian ({heading_deg})"


def test_mpc_brakes_when_every_command_is_above_the_risk_limit(open_world: NavWorld) -> None:
    """Surrounded by pedestrians who all head for the robot: no command stays within the limit, so it stops
    (a stopped robot is not at fault) instead of taking the least risky move; without safe_stop it moves."""
    from st_sim.apps.navigation.mpc import MpcConfig

    obs = observation(np.zeros(2), np.array([1.0, 0.0]), 0)
    ring = 1.2 * np.stack([np.cos(np.linspace(0, 2 * np.pi, 9)[:-1]), np.sin(np.linspace(0, 2 * np.pi, 9)[:-1])], 1)
    n = len(ring)
    obs["history"] = np.repeat(ring[:, None], T_OBS, axis=1).astype(np.float32)
    obs["history_mask"] = np.ones((n, T_OBS), bool)
    inward = -ring / np.linalg.norm(ring, axis=1, keepdims=True) * 0.6  # each walks to the centre at 0.6 m/s
    ahead = np.arange(1, T_PRED + 1)[None, :, None] * STEP_S
    obs["futures"] = np.repeat((ring[:, None] + ahead * inward[:, None])[:, None], SAMPLES, 1).astype(np.float32)
    obs["futures_mask"] = np.ones(n, bool)
    stop = make_planner("mpc", open_world, "cvm-s").act(obs)
    move = make_planner("mpc", open_world, "cvm-s", cfg=MpcConfig(safe_stop=False)).act(obs)
    assert np.linalg.norm(stop) == 0.0, f"every command is risky: the robot should stop, got {stop}"
    assert np.linalg.norm(move) > 0.0, "without safe_stop the least risky command is a move"


def test_the_sample_belief_follows_the_sample_a_pedestrian_walks() -> None:
    from st_sim.apps.navigation.modes import SampleBelief

    prior = np.full(4, 0.25)
    belief = SampleBelief(prior, sigma_m=0.2, floor=0.1)
    steps = np.array([[0.5, 0.0], [0.0, 0.5], [-0.5, 0.0], [0.0, -0.5]])  # sample k's next step
    xy = np.zeros(2)
    for _ in range(4):
        obs = {"history": np.zeros((1, T_OBS, 2), np.float32), "history_mask": np.ones((1, T_OBS), bool),
               "futures": np.zeros((1, 4, T_PRED, 2), np.float32), "futures_mask": np.ones(1, bool)}
        obs["history"][0, -1], obs["history"][0, -2] = xy, xy - steps[1]
        obs["futures"][0, :, 0] = xy + steps
        weights = belief.update(obs)[0]
        xy = xy + steps[1]  # the pedestrian walks as sample 1 said
    assert weights[1] > 0.8 and np.isclose(weights.sum(), 1.0), weights
    assert weights.min() >= 0.1 * 0.25 - 1e-12, "the floor keeps every sample possible"
    obs["history"][0, -2] = [50.0, 50.0]  # somebody else in that row now
    assert np.allclose(belief.update(obs)[0], prior), "a new pedestrian starts at the prior"


class Proposer:
    """A planner that always proposes the same command."""

    def __init__(self, command: np.ndarray):
        self.command, self.resets = np.asarray(command, np.float32), 0

    def reset(self) -> None:
        self.resets += 1

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return self.command


@pytest.mark.parametrize("heading_deg", [-150.0, -90.0, 90.0, 180.0])
def test_the_shield_keeps_a_command_that_stays_clear(open_world: NavWorld, heading_deg: float) -> None:
    from st_sim.apps.navigation.shield import ShieldedPlanner

    away = 0.8 * np.array([np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg))])
    inner = Proposer(away)
    shield = ShieldedPlanner(open_world, True, inner)
    shield.reset()
    np.testing.assert_array_equal(shield.act(observation(np.zeros(2), np.zeros(2), 0)), inner.command)
    assert (shield.vetoes, shield.decisions, inner.resets) == (0, 1, 1)


def test_the_shield_vetoes_walking_into_the_forecast_and_then_passes_clear(open_world: NavWorld) -> None:
    """The straight planner meets the crosser (its collision above): shielded, its commands are vetoed on the steps
    the forecast says so, and the robot never touches the crosser and still makes headway."""
    from st_sim.apps.navigation.shield import ShieldedPlanner

    shield = ShieldedPlanner(open_world, True, make_planner("straight", open_world, "none"))
    shield.reset()
    ego_xy, ego_v, closest = np.zeros(2), np.zeros(2), np.inf
    for step in range(30):
        command = np.asarray(shield.act(observation(ego_xy, ego_v, step)), np.float64)
        for fraction in np.linspace(0.1, 1.0, 10):
            crosser = CROSSER_START + (step + fraction) * STEP_S * CROSSER_VELOCITY
            closest = min(closest, float(np.linalg.norm(ego_xy + fraction * STEP_S * command - crosser)))
        ego_xy, ego_v = ego_xy + STEP_S * command, command
    assert 0 < shield.vetoes < shield.decisions
    assert closest >= open_world.contact_m, f"the shielded robot touched the crosser ({closest:.2f} m)"
    assert np.linalg.norm(GOAL - ego_xy) < 12.0 - 3.0, "it made no headway"


def test_the_shield_vetoes_a_command_into_a_wall_even_toward_the_goal() -> None:
    """A wall 1 m ahead between the robot and its goal, nobody about: full speed at it goes deeper into the wall
    within the MPC's horizon, so it is vetoed (however much progress it promises); along the wall it stands."""
    from st_sim.apps.navigation.shield import ShieldedPlanner

    H = np.array([[0.1, 0.0, -10.0], [0.0, 0.1, -10.0], [0.0, 0.0, 1.0]])
    walkable = np.ones((300, 300), bool)
    walkable[:, 110:120] = False  # a wall from x = 1 m to 2 m, the whole height
    world = NavWorld(Scene("wall", H, walkable), (-4.0, -8.0, 16.0, 8.0))
    obs = observation(np.zeros(2), np.zeros(2), 0)
    obs["history_mask"][:], obs["futures_mask"][:] = False, False  # nobody
    into = ShieldedPlanner(world, True, Proposer(np.array([1.5, 0.0])))
    command = into.act(obs)
    assert into.vetoes == 1 and command[0] < 1.5
    along = ShieldedPlanner(world, True, Proposer(np.array([0.0, 1.0])))
    np.testing.assert_array_equal(along.act(obs), [0.0, 1.0])
    assert along.vetoes == 0


def test_ppo_suite_2_without_forecasts_is_refused_naming_what_to_give(open_world: NavWorld) -> None:
    """It was trained with forecasts and ships no variant without: predictor none is one clear error."""
    with pytest.raises(ValueError, match=r"ppo-suite-2 was trained with forecasts .* give it a predictor"):
        make_planner("ppo-suite-2", open_world, "none")
