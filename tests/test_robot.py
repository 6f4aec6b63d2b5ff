"""The robot model (st_sim.sim.robot): its limits hold under any command, a differential drive never moves sideways,
latency and noise do what they say, and every env and scenario drives one robot with one set of limits."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs.suite import load_suite, make_scenario_env
from replays.constants import STEP_S
from st_sim.sim.exact import atan2
from st_sim.sim.robot import (
    ROBOTS,
    SUBSTEPS,
    Motion,
    Robot,
    RobotSpec,
    RobotSpecError,
    command_toward,
    robot_spec,
)

TOL = 1e-9  # rounding allowance of a limit [m/s, rad/s]
COMMAND = st.floats(-1e6, 1e6, allow_nan=False)  # far over every limit, full reversals and spins included
SEQUENCES = st.lists(st.tuples(COMMAND, COMMAND), min_size=1, max_size=30)
EXTREMES = [(1e6, 0.0), (-1e6, 0.0)] * 5 + [(0.0, 1e6), (0.0, -1e6)] * 5  # full speed, reversals, spins


def step_motions(robot: Robot, command: tuple[float, float]) -> tuple[Motion, Motion]:
    """The robot's motion before and after one step of ``command``."""
    before = robot.motion
    moves = robot.drive(np.array(command))
    assert moves.shape == (SUBSTEPS, 2) and np.isfinite(moves).all()
    return before, robot.motion


@pytest.mark.parametrize("kind", list(ROBOTS))
@settings(max_examples=60, deadline=None)
@given(commands=SEQUENCES)
@example(commands=EXTREMES)
def test_limits_hold_under_any_command(kind: str, commands: list[tuple[float, float]]) -> None:
    spec = ROBOTS[kind]
    robot = Robot(spec, heading=(0.6, 0.8))
    for t, command in enumerate(commands):
        before, after = step_motions(robot, command)
        dv = float(np.linalg.norm(after.velocity_mps[0] - before.velocity_mps[0]))
        speed_now = float(np.linalg.norm(after.velocity_mps[0]))
        assert speed_now <= spec.max_speed_mps + TOL, f"[{t}] speed {speed_now}"
        assert abs(float(np.linalg.norm(after.heading[0])) - 1.0) < 1e-12, f"[{t}] heading not a unit vector"
        if kind == "holonomic":
            assert dv <= spec.max_brake_mps2 * STEP_S + TOL, f"[{t}] velocity changed by {dv} m/s in one step"
            continue
        forward_change = abs(float(after.speed_mps[0] - before.speed_mps[0]))
        assert forward_change <= spec.max_brake_mps2 * STEP_S + TOL, f"[{t}] forward speed changed by {forward_change}"
        turn_change = abs(float(after.yaw_rate_radps[0] - before.yaw_rate_radps[0]))
        assert turn_change <= spec.max_yaw_accel_radps2 * STEP_S + TOL, f"[{t}] turn rate changed by {turn_change}"
        assert abs(float(after.yaw_rate_radps[0])) <= spec.max_yaw_rate_radps + TOL
        assert -spec.max_reverse_mps - TOL <= float(after.speed_mps[0]) <= spec.max_speed_mps + TOL
        velocity, heading = after.velocity_mps[0], after.heading[0]
        sideways = abs(velocity[0] * heading[1] - velocity[1] * heading[0])
        assert sideways < 1e-12, f"[{t}] a differential drive moved sideways at {sideways} m/s"


@settings(max_examples=60, deadline=None)
@given(commands=SEQUENCES)
@example(commands=EXTREMES)
def test_differential_drive_moves_along_its_arc(commands: list[tuple[float, float]]) -> None:
    """The last substep's straight move is the chord of the arc the robot drove: along its heading turned back by half
    that substep's turn, never across it."""
    spec = ROBOTS["diff-drive"]
    robot = Robot(spec)
    for command in commands:
        chord = robot.drive(np.array(command))[-1]
        half = -0.5 * robot.yaw_rate_radps * STEP_S / SUBSTEPS  # back to the middle of the last substep [rad]
        h, cos, sin = robot.heading, math.cos(half), math.sin(half)
        middle = np.array([h[0] * cos - h[1] * sin, h[0] * sin + h[1] * cos])
        assert abs(chord[0] * middle[1] - chord[1] * middle[0]) < 1e-9, "the chord leaves the arc"
        assert np.linalg.norm(chord) <= spec.max_speed_mps + TOL


def test_reversal_and_braking_take_their_time() -> None:
    """From full speed forward, a full reversal takes 1.5 s of braking to stop (2 m/s^2), then speeds up backward."""
    robot = Robot(ROBOTS["holonomic"])
    for _ in range(10):
        robot.drive(np.array([9.0, 0.0]))
    assert robot.velocity_mps.tolist() == [1.5, 0.0]
    speeds = []
    for _ in range(5):
        robot.drive(np.array([-1.5, 0.0]))
        speeds.append(robot.velocity_mps[0])
    assert speeds == pytest.approx([0.7, -0.1, -0.9, -1.5, -1.5])
    assert robot.last.clipped is False, "a command the robot reached is not clipped"


def test_a_spin_in_place_turns_within_its_limits_and_does_not_move() -> None:
    """Turn rate 0.8, 1.6, then 2.0 rad/s over the 0.2 s substeps (4 rad/s^2 up to 2 rad/s): 7.68 rad in 4 s."""
    spec = ROBOTS["diff-drive"]
    robot = Robot(spec)
    for _ in range(10):
        moves = robot.drive(np.array([0.0, 100.0]))
        assert np.abs(moves).max() == 0.0, "spinning in place moves nothing"
    assert robot.yaw_rate_radps == spec.max_yaw_rate_radps
    assert robot.last.clipped and robot.last.gap[1] == pytest.approx(100.0 - spec.max_yaw_rate_radps)
    angle = math.atan2(robot.heading[1], robot.heading[0])
    assert math.isclose(math.remainder(angle - 7.68, 2 * math.pi), 0.0, abs_tol=1e-9)


def test_latency_delays_the_command_by_whole_steps() -> None:
    robot = Robot(RobotSpec(latency_steps=2))
    speeds = []
    for _ in range(4):
        robot.drive(np.array([1.5, 0.0]))
        speeds.append(robot.velocity_mps[0])
    assert speeds == pytest.approx([0.0, 0.0, 0.8, 1.5])
    assert robot.last.applied == (1.5, 0.0)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), noise=st.floats(0.01, 1.0))
def test_actuation_noise_comes_from_the_robots_own_generator(seed: int, noise: float) -> None:
    spec = RobotSpec(actuation_noise=noise)
    runs = []
    for _ in range(2):
        robot = Robot(spec, rng=np.random.default_rng(seed))
        runs.append([robot.drive(np.array([1.0, 0.5])).tolist() for _ in range(5)])
    assert runs[0] == runs[1], "the same generator seed gives the same noise"
    with pytest.raises(RobotSpecError, match="generator"):
        Robot(spec)


@settings(max_examples=200, deadline=None)
@given(field=st.sampled_from(["max_speed_mps", "max_reverse_mps", "max_accel_mps2", "max_brake_mps2",
                              "max_yaw_rate_radps", "max_yaw_accel_radps2", "latency_steps", "actuation_noise",
                              "kind"]),
       value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-100, 100), st.booleans(),
                       st.text(max_size=5), st.none(), st.lists(st.integers(), max_size=2)))
def test_a_spec_refuses_any_bad_field_naming_it(field: str, value: object) -> None:
    try:
        spec = RobotSpec(**{"kind": "diff-drive", "max_reverse_mps": 0.5, "max_yaw_rate_radps": 2.0,
                            "max_yaw_accel_radps2": 4.0, field: value})
    except RobotSpecError as err:
        assert "RobotSpec" in str(err)
        return
    assert getattr(spec, field) == value and isinstance(value, int | float | str)


def test_robot_names_resolve_and_others_are_refused() -> None:
    assert robot_spec(None) == ROBOTS["holonomic"] == robot_spec("holonomic")
    assert robot_spec("diff-drive").kind == "diff-drive"
    for bad in ("tank", 3, ["holonomic"]):
        with pytest.raises(RobotSpecError, match="robot="):
            robot_spec(bad)


@settings(max_examples=200, deadline=None)
@given(hx=st.floats(-1, 1), hy=st.floats(-1, 1), vx=st.floats(-5, 5), vy=st.floats(-5, 5))
def test_command_toward_a_wished_velocity_is_within_the_limits(hx: float, hy: float, vx: float, vy: float) -> None:
    spec = ROBOTS["diff-drive"]
    heading = np.array([hx, hy])
    if np.linalg.norm(heading) < 1e-3:
        heading = np.array([1.0, 0.0])
    heading = heading / np.linalg.norm(heading)
    v, w = command_toward(spec, heading[None], np.array([[vx, vy]]))[0]
    assert 0.0 <= v <= spec.max_speed_mps and abs(w) <= spec.max_yaw_rate_radps
    along = heading @ [vx, vy]
    across = heading[0] * vy - heading[1] * vx
    if along <= 0:
        assert v == 0.0, "it turns on the spot before it drives toward something behind it"
    if abs(across) > 1e-6 and math.hypot(vx, vy) > 1e-3:
        assert np.sign(w) == np.sign(across), "it turns toward the wished direction"


@settings(max_examples=300, deadline=None)
@given(y=st.floats(-1e6, 1e6), x=st.floats(-1e6, 1e6))
def test_exact_atan2_is_within_one_ulp_of_numpy(y: float, x: float) -> None:
    ours, theirs = float(atan2(y, x)), float(np.arctan2(y, x))
    assert abs(ours - theirs) <= np.spacing(abs(theirs)) + 1e-300


# ---------------------------------------------------------------- in the envs


SUITE = load_suite()


def check_step_limits(spec: RobotSpec, before: np.ndarray, after: np.ndarray, where: str) -> None:
    """The change between two ``obs["ego"]`` rows is one the robot may make in a step: a holonomic robot's velocity
    within the acceleration limit; a unicycle's forward speed and turn rate within theirs, and no sideways motion."""
    if spec.kind == "holonomic":
        dv = float(np.linalg.norm(after[2:4] - before[2:4]))
        assert dv <= spec.max_brake_mps2 * STEP_S + 1e-5, f"{where}: {dv} m/s in one step"
        return
    forward = [float(ego[2:4] @ ego[6:8]) for ego in (before, after)]
    assert abs(forward[1] - forward[0]) <= spec.max_brake_mps2 * STEP_S + 1e-5, where
    assert abs(after[8] - before[8]) <= spec.max_yaw_accel_radps2 * STEP_S + 1e-5, where
    sideways = abs(after[2] * after[7] - after[3] * after[6])
    assert sideways < 1e-5, f"{where}: moved sideways at {sideways} m/s"


@pytest.mark.parametrize("kind", list(ROBOTS))
def test_every_scenario_drives_the_same_robot_within_its_limits(kind: str) -> None:
    """Each suite scenario's env has the kind's spec, its action space, and moves the robot within the limits under
    commands far over them (from the observation's step-end velocity, heading and turn rate)."""
    spec = ROBOTS[kind]
    rng = np.random.default_rng(7)
    for scenario in SUITE.scenarios:
        env = make_scenario_env(scenario, "none", robot=kind)
        try:
            assert env.unwrapped.robot == spec, scenario.name
            assert env.action_space.low.tolist() == spec.command_low.tolist(), scenario.name
            obs, _ = env.reset(seed=SUITE.seeds["val"][0])
            for t in range(12):
                command = rng.choice([-1e3, 1e3], 2) * rng.random(2)
                before = obs["ego"].astype(np.float64)
                obs, _, terminated, truncated, info = env.step(command)
                after = obs["ego"].astype(np.float64)
                assert list(info["robot"].command) == command.tolist()
                check_step_limits(spec, before, after, f"{scenario.name} [{t}]")
                if terminated or truncated:
                    break
        finally:
            env.close()


@pytest.mark.parametrize("env_id", ["STCrowd-SimCrossing-v1", "STCrowd-Eth-v0"])
def test_single_and_vector_env_drive_the_diff_drive_robot_alike(env_id: str) -> None:
    single = gym.make(env_id, predictor="cvm", robot="diff-drive")
    vector = gym.make_vec(env_id, num_envs=2, predictor="cvm", robot="diff-drive")
    rng = np.random.default_rng(3)
    obs, _ = single.reset(seed=11)
    vobs, _ = vector.reset(seed=[11, 12])
    for t in range(15):
        command = rng.uniform([-0.5, -2.0], [1.5, 2.0])
        obs, _, terminated, truncated, _ = single.step(command)
        vobs, *_ = vector.step(np.stack([command, command]))
        assert np.array_equal(obs["ego"], vobs["ego"][0]), f"step {t}"
        assert np.array_equal(obs["history"], vobs["history"][0]), f"step {t}"
        if terminated or truncated:
            break
    single.close()
    vector.close()


@pytest.mark.parametrize("env_id", ["STCrowd-SimCrossing-v1", "STCrowd-Zara1-v0"])
def test_actuation_noise_never_changes_the_crowd(env_id: str) -> None:
    """The noise is the robot's own stream: a robot commanded to stand (zero stays zero under relative noise) meets
    the crowd a noiseless one meets, and a noisy one moves otherwise than the noiseless one."""
    crowds, paths = [], []
    for spec in (ROBOTS["holonomic"], RobotSpec(actuation_noise=0.3)):
        env = gym.make(env_id, predictor="cvm", robot=spec)
        obs, _ = env.reset(seed=5)
        kept = [obs["history"][:, -1].copy()]
        for _ in range(6):
            obs, *_ = env.step(np.zeros(2))
            kept.append(obs["history"][:, -1].copy())
        crowds.append(np.array(kept))
        obs, _ = env.reset(seed=5)
        for _ in range(3):
            obs, *_ = env.step(np.array([1.0, 0.5]))
        paths.append(obs["ego"][:2].copy())
        env.close()
    assert np.array_equal(crowds[0], crowds[1])
    assert not np.array_equal(paths[0], paths[1])


@pytest.mark.parametrize("policy", ["mpc", "straight", "orca"])
def test_every_planner_drives_a_differential_drive_within_its_commands(policy: str) -> None:
    """The MPC gives the robot's own (v, w); the others' velocities are turned into it (``NavWorld.command_for``):
    every command lies in the action space, and the robot gets to its goal in the open encounter."""
    from st_sim.apps.navigation.episodes import run_episode
    from st_sim.apps.navigation.policies import load_policy
    from st_sim.apps.navigation.world import world_of

    env = gym.make("STCrowd-SimCrossingAngle-v1", predictor="cvm", robot="diff-drive")
    world = world_of(env)
    checked = load_policy(policy, world, "cvm")
    obs, _ = env.reset(seed=3)
    checked.reset()
    for _ in range(5):
        command = checked.act(obs)
        assert env.action_space.contains(command.astype(np.float32)) or np.allclose(
            np.clip(command, env.action_space.low, env.action_space.high), command, atol=1e-6), command
        obs, *_ = env.step(command)
    trace, _ = run_episode(env, checked, world, seed=3)
    assert trace.outcome.value in ("goal", "pedestrian collision"), trace.outcome
    env.close()


@pytest.mark.parametrize("kind", list(ROBOTS))
@pytest.mark.parametrize("env_id", ["STCrowd-SimCrossing-v1", "STCrowd-SimDoorway-v1", "STCrowd-Eth-v0"])
def test_every_episode_starts_at_rest_facing_the_goal(env_id: str, kind: str) -> None:
    """docs/robot.md: both kinds start every episode at rest, facing their goal (``obs["ego"]``: velocity, heading,
    turn rate), in a simulated crowd, an encounter and a replay, whatever the episode before did."""
    env = gym.make(env_id, predictor="none", robot=kind)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        ego = obs["ego"].astype(np.float64)
        toward = (ego[4:6] - ego[:2]) / np.linalg.norm(ego[4:6] - ego[:2])
        assert not ego[2:4].any() and ego[8] == 0.0, f"seed {seed}: not at rest: {ego}"
        np.testing.assert_allclose(ego[6:8], toward, atol=1e-6, err_msg=f"seed {seed}: not facing the goal")
        for _ in range(4):  # leave it moving and turning for the next reset
            obs, _, terminated, truncated, _ = env.step(env.action_space.high)
            if terminated or truncated:
                break
        assert obs["ego"][2:4].any(), f"seed {seed}: the robot never moved, so the next reset proves little"
    env.close()
