"""The peers (other projects' planners, ``st_sim.apps.navigation.peers``): commands in the world frame, walls seen,
pedestrians avoided, a real env's observation taken, the target on the walkable path, the settings reaching the
libraries and changing what the robot does, and the libraries imported only when a peer is built."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from robot_obs import facing

import envs  # noqa: F401  (registers the ids)
from replays.constants import STEP_S, T_OBS
from replays.scenes import Scene
from st_sim.apps.navigation.peers import (
    HLSettings,
    HrvoSettings,
    NavgroundHL,
    NavgroundHrvo,
    NavgroundOrca,
    NavgroundPlanner,
    NavgroundSocialForce,
    OrcaSettings,
    PySocialForcePlanner,
    PySocialForceSettings,
    SocialForceSettings,
    near_walls,
    wall_points,
)
from st_sim.apps.navigation.planners import PEERS, make_planner
from st_sim.apps.navigation.policies import load_policy
from st_sim.apps.navigation.world import NavWorld, world_of

REPO = Path(__file__).resolve().parents[1]
H = np.array([[0.1, 0.0, -10.0], [0.0, 0.1, -10.0], [0.0, 0.0, 1.0]])  # world = 0.1 * pixel - 10 m
WALL_X_M = (4.8, 5.2)  # the hand-made wall's columns [m]


@pytest.fixture(scope="module")
def open_world() -> NavWorld:
    """A 30 m x 30 m walkable square; the robot starts near its middle."""
    return NavWorld(Scene("open", H, np.ones((300, 300), bool)), (-10.0, -10.0, 20.0, 20.0))


@pytest.fixture(scope="module")
def half_walled_world() -> NavWorld:
    """The open square with a wall at x = 4.8 .. 5.2 m from its south edge up to y = 0: the way east goes round
    the wall's end."""
    walkable = np.ones((300, 300), bool)
    walkable[:100, 148:152] = False
    return NavWorld(Scene("half-walled", H, walkable), (-10.0, -10.0, 20.0, 20.0), wall_clearance_m=0.3)


@pytest.fixture(scope="module")
def walled_world() -> NavWorld:
    """The open square cut in two by a wall from its south edge to its north edge at x = 4.8 .. 5.2 m."""
    walkable = np.ones((300, 300), bool)
    walkable[:, 148:152] = False
    return NavWorld(Scene("walled", H, walkable), (-10.0, -10.0, 20.0, 20.0), wall_clearance_m=0.3)


def observation(ego_xy: np.ndarray, ego_v: np.ndarray, goal: np.ndarray,
                people: list[tuple[np.ndarray, np.ndarray]] = ()) -> dict[str, np.ndarray]:
    """An STCrowd observation: the robot, its goal, and each (position, velocity) person with T_obs frames."""
    rows = max(2, len(people))
    obs = {"ego": np.array([*ego_xy, *ego_v, *goal, *facing(ego_xy, ego_v, goal), 0.0], np.float32),
           "history": np.zeros((rows, T_OBS, 2), np.float32), "history_mask": np.zeros((rows, T_OBS), bool),
           "futures": np.zeros((rows, 1, 12, 2), np.float32), "futures_mask": np.zeros(rows, bool)}
    for row, (xy, velocity) in enumerate(people):
        obs["history"][row] = xy + STEP_S * np.arange(-T_OBS + 1, 1)[:, None] * velocity
        obs["history_mask"][row] = True
    return obs


def drive(planner, world: NavWorld, start: np.ndarray, goal: np.ndarray, steps: int,
          people: list[tuple[np.ndarray, np.ndarray]] = ()) -> tuple[np.ndarray, float]:
    """(robot positions (steps + 1, 2) [m], least centre distance to a person [m]) of ``steps`` env steps: the
    robot moves at its (speed-limited) command, people at their constant velocities."""
    xy, velocity, path, closest = np.array(start, float), np.zeros(2), [np.array(start, float)], np.inf
    for step in range(steps):
        now = [(p + step * STEP_S * v, v) for p, v in people]
        command = np.asarray(planner.act(observation(xy, velocity, goal, now)), np.float64)
        speed = np.linalg.norm(command)
        velocity = command * min(1.0, world.max_speed_mps / speed) if speed > 0 else command
        for fraction in np.linspace(0.1, 1.0, 10):
            for p, v in people:
                where = p + (step + fraction) * STEP_S * v
                closest = min(closest, float(np.linalg.norm(xy + fraction * STEP_S * velocity - where)))
        xy = xy + STEP_S * velocity
        path.append(xy)
    return np.array(path), closest


@pytest.mark.parametrize("name", sorted(PEERS))
@pytest.mark.parametrize("heading_deg", [45.0, 135.0, -100.0])
def test_a_peers_command_is_in_the_world_frame(open_world: NavWorld, name: str, heading_deg: float) -> None:
    """The robot moves along ``heading_deg`` at 1 m/s, its goal 2.5 m east: the command points at the goal, whatever
    the heading (a command in the robot's own frame would be turned by the heading)."""
    heading = np.radians(heading_deg)
    planner = make_planner(name, open_world, "none")
    command = np.asarray(planner.act(observation(np.zeros(2), np.array([np.cos(heading), np.sin(heading)]),
                                                 np.array([2.5, 0.0]))), np.float64)
    speed = float(np.linalg.norm(command))
    assert command.shape == (2,) and speed > 0.3, f"{name} should move toward the goal ({command})"
    if heading_deg == 45.0:  # the reachable turn in one step: the command leans east of the current velocity
        assert command[0] > 0.5 * speed, f"{name}: {command} does not point east"
    else:
        assert command[0] > np.cos(heading) * speed + 0.1, f"{name}: {command} did not turn toward the goal"


@pytest.mark.parametrize("name", sorted(PEERS))
def test_a_peer_sees_the_wall_between_robot_and_goal(walled_world: NavWorld, name: str) -> None:
    """A wall from edge to edge stands between the robot (x = 2 m) and its goal (x = 8 m): the robot never reaches
    the wall; with the walls taken away the same planner walks through where it stood."""
    start, goal = np.array([2.0, 0.0]), np.array([8.0, 0.0])
    planner = make_planner(name, walled_world, "none")
    path, _ = drive(planner, walled_world, start, goal, 25)
    assert path[:, 0].max() < WALL_X_M[0] - 0.1, f"{name} walked into the wall (x up to {path[:, 0].max():.2f} m)"
    planner.walls_m = planner.walls_m[:0]
    blind, _ = drive(planner, walled_world, start, goal, 25)
    assert blind[:, 0].max() > WALL_X_M[1], f"{name} without walls should cross (x up to {blind[:, 0].max():.2f} m)"


SOCIAL_FORCES = ("navground-sf", "pysocialforce")
"""peers whose repulsion acts on centre distances, not on the bodies' gap: they swerve but may brush a body"""


@pytest.mark.parametrize("name", sorted(PEERS))
def test_a_peer_steps_round_a_pedestrian_standing_in_its_way(open_world: NavWorld, name: str) -> None:
    """Someone stands on the straight line 4 m ahead (a straight walk passes 0.05 m from their centre): the robot
    swerves and gets past; the velocity-obstacle and HL planners without touching them."""
    person = (np.array([4.0, 0.05]), np.zeros(2))
    path, closest = drive(make_planner(name, open_world, "none"), open_world, np.zeros(2), np.array([8.0, 0.0]), 30,
                          [person])
    least_m = 0.3 if name in SOCIAL_FORCES else open_world.contact_m
    assert closest >= least_m, f"{name} came {closest:.2f} m near the pedestrian's centre"
    assert path[-1, 0] > 4.5, f"{name} did not get past the pedestrian (x = {path[-1, 0]:.2f} m)"


@pytest.mark.parametrize("name", sorted(PEERS))
def test_every_peer_runs_from_a_real_envs_observation_as_a_policy(name: str) -> None:
    env = gym.make("STCrowd-SimCrossing-v1", predictor="none")
    policy = load_policy(name, world_of(env), "none")
    obs, _ = env.reset(seed=3)
    policy.reset()
    for _ in range(3):
        obs, *_ = env.step(policy.act(obs))
    env.close()


def test_walls_are_picked_by_distance_and_sampled_along(walled_world: NavWorld) -> None:
    walls = np.array([[[0.0, -1.0], [0.0, 1.0]], [[10.0, 0.0], [12.0, 0.0]], [[-3.0, 3.0], [3.0, 3.0]]])
    np.testing.assert_array_equal(near_walls(walls, np.array([1.0, 0.0]), 2.5), walls[[0]])
    np.testing.assert_array_equal(near_walls(walls, np.array([1.0, 0.0]), 3.0), walls[[0, 2]])
    points = wall_points(walls[:1], 0.2)
    assert np.allclose(points[[0, -1]], walls[0]) and np.allclose(points[:, 0], 0.0)
    assert np.diff(points[:, 1]).max() <= 0.2 + 1e-9


def test_the_peers_need_their_extra_only_when_built(open_world: NavWorld, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "navground", None)  # import navground now raises ImportError
    monkeypatch.setitem(sys.modules, "navground.core", None)
    with pytest.raises(ImportError, match=r'pip install -e "\.\[peers\]"'):
        make_planner("navground-orca", open_world, "none")
    monkeypatch.setitem(sys.modules, "pysocialforce", None)
    with pytest.raises(ImportError, match=r'pip install -e "\.\[peers\]"'):
        make_planner("pysocialforce", open_world, "none")


def test_pysocialforce_is_imported_without_its_log_file_and_debug_logging(tmp_path: Path) -> None:
    """PySocialForce's import sets the root logger to DEBUG and opens ``file.log`` where it runs; the adapter undoes
    both (in a fresh interpreter, where the import really happens)."""
    code = ("import logging; from st_sim.apps.navigation import peers; root = logging.getLogger(); "
            "before = (root.level, list(root.handlers)); peers._pysocialforce(); "
            "assert (root.level, list(root.handlers)) == before, (root.level, root.handlers); print('ok')")
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                            env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin", "OMP_NUM_THREADS": "1"})
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr[-2000:]
    assert "DEBUG" not in result.stderr, result.stderr[-2000:]
    assert not (tmp_path / "file.log").exists(), "the import left file.log behind"


def test_the_target_lies_along_the_walkable_path_round_a_corner(half_walled_world: NavWorld) -> None:
    """The robot stands west of the wall's end, its goal east of it: the target 3 m ahead is 3 m along the shortest
    walkable path (2.7 m or more nearer the goal by that path) and clear of the wall, not 3 m along the path's first
    direction (north, 3 m past the wall's end); with an infinite waypoint distance it is the goal."""
    world, start, goal = half_walled_world, np.array([4.2, -1.0]), np.array([6.0, -1.0])
    planner = make_planner("navground-hl", world, "none", settings=HLSettings(waypoint_m=3.0))
    target = planner.target_of(start, goal)
    terrain, body_m = world.terrain, world.wall_clearance_m
    progress_m = terrain.cost_to_go(start[None], goal, body_m)[0] - terrain.cost_to_go(target[None], goal, body_m)[0]
    assert progress_m >= 2.7, f"the target {target} is only {progress_m:.2f} m along the path"
    assert terrain.clearance_at(target[None])[0] >= body_m
    direct = make_planner("navground-hl", world, "none", settings=HLSettings(waypoint_m=math.inf))
    np.testing.assert_array_equal(direct.target_of(start, goal), goal)


NAVGROUND_SETTINGS = [
    (NavgroundHL, HLSettings(aperture_rad=1.0, resolution=31, tau_s=0.3, eta_s=1.7),
     {"aperture": 1.0, "resolution": 31, "tau": 0.3, "eta": 1.7}),
    (NavgroundOrca, OrcaSettings(time_horizon_s=3.5, static_time_horizon_s=0.6),
     {"time_horizon": 3.5, "static_time_horizon": 0.6}),
    (NavgroundHrvo, HrvoSettings(uncertainty_offset_mps=0.3), {"uncertainty_offset": 0.3}),
    (NavgroundSocialForce, SocialForceSettings(tau_s=0.7, step_duration_s=1.5, people_strength_m2ps2=4.0,
                                               people_range_m=0.8, wall_strength_m2ps2=12.0, wall_range_m=0.5),
     {"tau": 0.7, "step_duration": 1.5, "v_a": 4.0, "v_r": 0.8, "u_a": 12.0, "u_r": 0.5}),
]


@pytest.mark.parametrize(("cls", "settings", "properties"), NAVGROUND_SETTINGS,
                         ids=[cls.__name__ for cls, _, _ in NAVGROUND_SETTINGS])
def test_navground_settings_reach_the_behaviour(open_world: NavWorld, cls, settings, properties) -> None:
    settings = replace(settings, speed_share=0.6, horizon_m=7.0, safety_margin_m=0.15)
    planner = cls(open_world, False, settings=settings)
    agent = planner.agent
    assert {name: getattr(agent, name) for name in properties} == pytest.approx(properties)
    assert (agent.optimal_speed, agent.horizon, agent.safety_margin) == pytest.approx(
        (0.6 * open_world.max_speed_mps, 7.0, 0.15))
    assert planner.fingerprint() == repr(settings) != cls(open_world, False).fingerprint()


def test_pysocialforce_settings_reach_its_forces(open_world: NavWorld) -> None:
    settings = PySocialForceSettings(relaxation_time_s=0.3, social_factor=7.0, social_gamma=0.5,
                                     obstacle_factor=15.0, obstacle_sigma_m=0.4, target_tolerance_m=0.35)
    config = make_planner("pysocialforce", open_world, "none", settings=settings).config
    assert (config.sub_config("desired_force")("relaxation_time"), config.sub_config("desired_force")("goal_threshold"),
            config.sub_config("social_force")("factor"), config.sub_config("social_force")("gamma"),
            config.sub_config("obstacle_force")("factor"), config.sub_config("obstacle_force")("sigma")) == (
        0.3, 0.35, 7.0, 0.5, 15.0, 0.4)
    assert config.sub_config("social_force")("n_prime") == 3  # the entries not set keep PySocialForce's defaults


@pytest.mark.parametrize("name", sorted(PEERS))
def test_a_slower_optimal_speed_slows_every_peer(open_world: NavWorld, name: str) -> None:
    """The robot stands, its goal 6 m east, nobody near: a speed share of 0.4 keeps its command at 0.4 of the speed
    limit, where the tuned settings go faster."""
    settings = replace(make_planner(name, open_world, "none").settings, speed_share=0.4)
    obs = observation(np.zeros(2), np.zeros(2), np.array([6.0, 0.0]))
    slow = float(np.linalg.norm(make_planner(name, open_world, "none", settings=settings).act(obs)))
    fast = float(np.linalg.norm(make_planner(name, open_world, "none").act(obs)))
    assert 0.0 < slow <= 0.4 * open_world.max_speed_mps + 1e-6 < fast


def test_a_peer_refuses_another_peers_settings(open_world: NavWorld) -> None:
    with pytest.raises(TypeError, match="NavgroundHL takes HLSettings, not OrcaSettings"):
        NavgroundHL(open_world, False, settings=OrcaSettings())
    with pytest.raises(TypeError, match="PySocialForcePlanner takes PySocialForceSettings"):
        PySocialForcePlanner(open_world, False, settings=HLSettings())


def test_navground_sf_stops_where_its_social_force_is_nan(open_world: NavWorld) -> None:
    """A person walks nearly straight at the robot, where navground 0.7's distance to a neighbour takes the root of
    a negative number after rounding: its command is NaN, the adapter's a stop."""
    planner = make_planner("navground-sf", open_world, "none")
    person = (np.array([4.505524, -2.0664103]), np.array([0.05055428, -1.7375124]))
    obs = observation(np.array([4.52074051, -2.58249354]), np.array([-0.13303399, 0.16544758]),
                      np.array([4.90998174, 0.37435427]), [person])
    with np.errstate(invalid="ignore", divide="ignore"):
        raw = NavgroundPlanner.act(planner, obs)
    assert np.isnan(raw).all(), "the library no longer fails here: the test does not exercise the stop"
    np.testing.assert_array_equal(planner.act(obs), np.zeros(2))
