"""Reactive replays: recorded pedestrians keep their logs until the robot is in their way, then walk round it; and
the at-fault rule of robot-pedestrian collisions."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import example, given, settings
from hypothesis import strategies as st

import envs  # noqa: F401  (registers the ids)
from envs import REPLAY_SCENES
from envs.common.errors import EnvInputError
from replays.scenes import Scene
from st_sim.reactive.footprint import ROBOT_MARGIN_M, Body
from st_sim.reactive.reaction import Reaction, Spread
from st_sim.reactive.reactive import ReactiveCrowd
from st_sim.sim.map_depth import MapDepth
from st_sim.sim.sweep import closest_approach

REPLAY_IDS = [f"STCrowd-{scene}-v0" for scene in REPLAY_SCENES]
CONTACT_M = 0.55  # the replays' robot-pedestrian contact distance (0.3 m + 0.25 m)
ROBOT = Body(radius_m=0.3)  # the replays' robot; a pedestrian touches it within 0.25 m of its body


@pytest.mark.parametrize("env_id", REPLAY_IDS, ids=REPLAY_IDS)
def test_reactive_replay_passes_check_env(env_id: str) -> None:
    env = gym.make(env_id, pedestrians="reactive", predictor="cvm")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
        check_env(env.unwrapped)
    env.close()


def test_an_unknown_pedestrian_mode_is_refused() -> None:
    with pytest.raises(EnvInputError, match="pedestrians='sheep'"):
        gym.make("STCrowd-Zara1-v0", pedestrians="sheep")


@pytest.mark.parametrize("kwargs, message", [
    ({"pedestrians": "reactive", "reaction_traits": "random"}, "reaction_traits='random'"),
    ({"pedestrians": "reactive", "reaction_traits": 1}, "reaction_traits=1"),
    ({"reaction_traits": "drawn"}, "needs pedestrians='reactive'")], ids=["unknown", "not-text", "log"])
def test_bad_reaction_traits_are_refused(kwargs: dict, message: str) -> None:
    with pytest.raises(EnvInputError, match=message):
        gym.make("STCrowd-Zara1-v0", predictor="none", **kwargs)


def _crowd_walk(env: gym.Env, seed: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The traits the crowd drew at reset with ``seed`` and its positions over ``steps`` steps of a robot heading
    for its goal at 1 m/s."""
    env.reset(seed=seed)
    core = env.unwrapped
    path = []
    for _ in range(steps):
        toward = core.goal_m - core.ego_xy_m
        _, _, terminated, truncated, _ = env.step(toward / max(np.linalg.norm(toward), 1e-9))
        path.append(np.nan_to_num(core.reactive.state.xy_m, nan=-1e3))
        if terminated or truncated:
            break
    return core.reactive.state.traits.copy(), np.array(path)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drawn_traits_follow_the_seed_and_a_spread_of_zeros_walks_as_the_fitted_pedestrians(
        seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each pedestrian draws its own traits from the reset's seed: the same seed, the same people and the same walk;
    another seed, other people. With every sigma 0 the drawn crowd walks bit for bit as the fitted one."""
    monkeypatch.setattr("envs.replay_env.fitted_spread", lambda: Spread.even(0.5))
    drawn = gym.make("STCrowd-Zara1-v0", predictor="none", pedestrians="reactive", reaction_traits="drawn")
    traits, walk = _crowd_walk(drawn, seed, 30)
    again, walk_again = _crowd_walk(drawn, seed, 30)
    other, _ = _crowd_walk(drawn, seed + 100, 30)
    assert np.array_equal(traits, again) and np.array_equal(walk, walk_again)
    assert not np.array_equal(traits, other) and (np.log(traits).std(axis=0) > 0.3).all()  # people differ
    fitted = gym.make("STCrowd-Zara1-v0", predictor="none", pedestrians="reactive")
    typical, fitted_walk = _crowd_walk(fitted, seed, 30)
    assert np.array_equal(typical, np.ones_like(typical))
    monkeypatch.setattr("envs.replay_env.fitted_spread", lambda: Spread())
    zero = gym.make("STCrowd-Zara1-v0", predictor="none", pedestrians="reactive", reaction_traits="drawn")
    none_drawn, zero_walk = _crowd_walk(zero, seed, 30)
    assert np.array_equal(none_drawn, typical) and np.array_equal(zero_walk, fitted_walk)


def _far_from_everybody(env: gym.Env, frames: int) -> np.ndarray:
    """The walkable arena point farthest from every pedestrian of the next ``frames`` frames."""
    replay, index = env.unwrapped.replay, env.unwrapped.index
    recorded = replay.xy_m[index:index + frames][replay.present[index:index + frames]]
    candidates = env.unwrapped.candidates_m
    gap = np.linalg.norm(candidates[:, None] - recorded[None], axis=-1).min(axis=1)
    assert gap.max() > 3.0, "no quiet spot in this stretch of the recording"
    return candidates[np.argmax(gap)].copy()


def test_with_the_robot_out_of_reach_a_reactive_replay_is_the_log() -> None:
    log, reactive = (gym.make("STCrowd-Zara1-v0", predictor="cvm", pedestrians=mode) for mode in ("log", "reactive"))
    for start in (20, 300, 600):
        log.reset(seed=0, options={"start_index": start})
        reactive.reset(seed=0, options={"start_index": start})
        reactive.unwrapped.ego_xy_m = log.unwrapped.ego_xy_m = _far_from_everybody(log, 40)
        for t in range(40):
            step_a, step_b = log.step(np.zeros(2)), reactive.step(np.zeros(2))
            for key in step_a[0]:  # reactive mode has spare rows for pedestrians late for their logs' ends: empty
                rows = len(step_a[0][key]) if key != "ego" else None
                assert np.array_equal(step_a[0][key], step_b[0][key][:rows]), f"[start {start}, step {t}] {key} differs"
                assert rows is None or not step_b[0][key][rows:].any(), f"[start {start}, step {t}] spare {key} rows"
            assert step_b[4]["off_log"] == 0 and step_b[4]["log_deviation_m"] == 0.0, f"[start {start}, step {t}]"
            if step_a[2] or step_a[3]:
                break


def _walker_and_robot(mode: str):
    """A replay env whose robot stands on the recorded path of a walker, 2 m ahead of it; returns the env, the
    walker's id and the steps until the walker passes the robot's spot."""
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm", pedestrians=mode)
    env.reset(seed=0, options={"start_index": 100})
    replay = env.unwrapped.replay
    index = env.unwrapped.index
    for col in np.flatnonzero(replay.present[index]):  # a walker present for the next 12 frames, moving >= 0.8 m/s
        path = replay.xy_m[index:index + 12, col]
        if replay.present[index:index + 12, col].all() and np.linalg.norm(path[1] - path[0]) > 0.32:
            walked = np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))
            ahead = int(np.searchsorted(walked, 2.0)) + 1
            others = np.delete(replay.xy_m[index], col, axis=0)
            if np.nanmin(np.linalg.norm(others - path[ahead], axis=1)) > 1.0:  # nobody else stands there
                env.unwrapped.ego_xy_m = path[ahead].copy()
                return env, int(replay.agents[col]), ahead + 3
    raise AssertionError("no walker found in ZARA1 from frame index 100")


def test_a_pedestrian_walks_round_a_robot_standing_on_its_path() -> None:
    env, walker, steps = _walker_and_robot("reactive")
    least = np.inf
    for _ in range(steps):
        _obs, _, terminated, _, info = env.step(np.zeros(2))
        assert not terminated, f"the walker hit the standing robot ({info['termination']})"
        frame = env.unwrapped.tracks.now
        if walker in frame.ids:
            least = min(least, float(np.linalg.norm(frame.xy_m[frame.ids == walker][0] - env.unwrapped.ego_xy_m)))
    assert CONTACT_M < least < 1.2, f"the walker passed {least:.2f} m from the robot's centre"


@settings(max_examples=6, deadline=None)
@given(warm=st.integers(0, 2), turn=st.floats(-np.pi, np.pi))
def test_pedestrians_see_the_robots_last_move_not_its_command(warm: int, turn: float) -> None:
    """Two robots standing on a walker's path, told different things in one step: the pedestrians move alike (they
    expect each robot to hold its last velocity, zero), and only the robots differ."""
    pair = [_walker_and_robot("reactive")[0] for _ in range(2)]
    for _ in range(warm):
        for env in pair:
            env.step(np.zeros(2, np.float32))
    commands = [np.zeros(2, np.float32), 1.5 * np.array([np.cos(turn), np.sin(turn)], np.float32)]
    for env, command in zip(pair, commands, strict=True):
        env.step(command)
    now = [env.unwrapped.tracks.now for env in pair]
    assert np.array_equal(now[0].ids, now[1].ids) and np.array_equal(now[0].xy_m, now[1].xy_m)


def test_in_log_mode_the_same_pedestrian_walks_into_the_robot() -> None:
    env, _, steps = _walker_and_robot("log")
    ends = []
    for _ in range(steps):
        _, _, terminated, _, info = env.step(np.zeros(2))
        ends.append(info["termination"])
        if terminated:
            break
    assert "pedestrian_collision" in ends
    assert info["at_fault"] is False, "a standing robot is never at fault"


def _open_square(half_m: float = 12.0, wall: tuple[float, float] | None = None) -> MapDepth:
    """The depth map of an open square of side 2 ``half_m`` round the origin at 5 cm per pixel, optionally with a
    non-walkable band between x = wall[0] and x = wall[1] (a traced wall that logs may cross)."""
    size = int(2 * half_m / 0.05)
    walkable = np.ones((size, size), bool)
    if wall is not None:
        walkable[:, int((wall[0] + half_m) / 0.05):int((wall[1] + half_m) / 0.05)] = False
    H = np.array([[0.05, 0.0, -half_m], [0.0, 0.05, -half_m], [0.0, 0.0, 1.0]])
    return MapDepth(Scene("square", H, walkable))


def _straight_logs(seed: int, walkers: int, speed: float, frames: int = 80) -> np.ndarray:
    """(F, W, 2) straight logs through and around the origin at ``speed`` [m/s], then a wait at their ends; no two
    logs start or end within a metre of each other."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(5, 8, (walkers, 2)) * rng.choice([-1, 1], (walkers, 2))
    end = -start + rng.normal(0, 0.5, (walkers, 2))
    keep = [0]
    for k in range(1, walkers):
        if all(np.linalg.norm(start[k] - start[j]) > 1 and np.linalg.norm(end[k] - end[j]) > 1 for j in keep):
            keep.append(k)
    start, end = start[keep], end[keep]
    walked = np.arange(frames)[:, None] * 0.4 * speed / np.linalg.norm(end - start, axis=1)  # (F, W) share
    return start + (end - start) * np.minimum(walked, 1.0)[..., None]


def _walk_past_a_standing_robot(seed: int, walkers: int, speed: float, depth: MapDepth | None = None,
                                robot: np.ndarray | None = None, body: Body = ROBOT, reaction: Reaction | None = None,
                                heading: float = 0.0) -> tuple[ReactiveCrowd, np.ndarray, np.ndarray]:
    """Straight logs past a robot (``body``, turned to ``heading``) standing at ``robot`` (default the origin);
    returns the crowd, every frame's positions (F, W, 2) and the logs (F, W, 2)."""
    log = _straight_logs(seed, walkers, speed)
    robot = np.zeros(2) if robot is None else robot
    crowd = ReactiveCrowd(log, np.ones(log.shape[:2], bool), depth or _open_square(), body, 0.25, reaction)
    path = [crowd.reset(0).copy()]
    for index in range(1, len(log)):
        path.append(crowd.step(index, robot, robot, heading).copy())
    return crowd, np.array(path), log


def _frozen(path: np.ndarray, log: np.ndarray) -> list[tuple[int, int]]:
    """(frame, walker) where a walker has moved under 2 cm per step for 10 steps while its log moved over 1 m."""
    moved = np.linalg.norm(np.diff(path, axis=0), axis=-1)  # (F - 1, W)
    logged = np.linalg.norm(np.diff(log, axis=0), axis=-1)
    found = []
    for t in range(10, len(moved) + 1):
        still = (moved[t - 10:t] < 0.02).all(axis=0) & (logged[t - 10:t].sum(axis=0) > 1.0)
        found += [(t, int(w)) for w in np.flatnonzero(still)]
    return found


REACTIVE_DRAWS = settings(max_examples=25, deadline=None)
walk = {"seed": st.integers(0, 2**32 - 1), "walkers": st.integers(1, 12), "speed": st.floats(0.5, 2.0)}
reactions = st.builds(Reaction, fov_deg=st.floats(0.0, 180.0), hearing_m=st.floats(0.0, 6.0),
                      reaction_s=st.floats(0.0, 2.0), anticipation_s=st.floats(0.4, 4.0),
                      clearance_m=st.floats(0.0, 1.5), head_on_s=st.floats(0.0, 1.5), behind_s=st.floats(0.0, 1.5),
                      crossing_s=st.floats(0.0, 1.5), delay_cost=st.floats(0.25, 1.0),
                      aside_cost=st.floats(0.5, 2.0))  # standing aside dear enough that they rejoin their logs
# notices nothing: only the safety rule moves it
UNAWARE = Reaction(fov_deg=0.0, hearing_m=0.0, reaction_s=0.0, anticipation_s=1.2, clearance_m=0.3, head_on_s=0.3,
                   behind_s=0.3, crossing_s=0.3, delay_cost=1.0, aside_cost=0.5)


@REACTIVE_DRAWS
@given(**walk)
def test_reactive_pedestrians_never_touch_a_standing_robot(seed: int, walkers: int, speed: float) -> None:
    _, path, _ = _walk_past_a_standing_robot(seed, walkers, speed)
    gap, _ = closest_approach(path[:-1], path[1:])  # robot at the origin; straight lines between frames
    assert gap.min() >= CONTACT_M, f"a pedestrian came {gap.min():.3f} m from the robot's centre"


@REACTIVE_DRAWS
@given(**walk)
def test_reactive_pedestrians_go_round_a_standing_robot_and_rejoin_their_logs(seed: int, walkers: int,
                                                                             speed: float) -> None:
    """Nobody freezes while there is room round the robot, nobody presses into anybody where the logs do not, and
    everybody is back on its log by the end (the deadlock of two pedestrians detouring from both sides included)."""
    crowd, path, log = _walk_past_a_standing_robot(seed, walkers, speed)
    assert not _frozen(path, log), f"frozen (frame, walker): {_frozen(path, log)[:5]}"
    gap = np.linalg.norm(path[:, :, None] - path[:, None], axis=-1)
    logged = np.linalg.norm(log[:, :, None] - log[:, None], axis=-1)
    pressed = (gap < 0.3) & (logged >= 0.3)
    assert not pressed.any(), f"{pressed.sum() // 2} pair-frames overlap by more than 10 cm"
    assert not crowd.state.off_log.any(), f"{crowd.state.off_log.sum()} pedestrians never rejoined their logs"
    assert np.array_equal(path[-1], log[-1])


def test_two_pedestrians_detouring_round_a_standing_robot_from_both_sides_rejoin_their_logs() -> None:
    crowd, _, _ = _walk_past_a_standing_robot(9, 9, 1.1)  # the deadlock that a CI draw found on 2026-11-25
    assert not crowd.state.off_log.any(), f"{crowd.state.off_log.sum()} pedestrians never rejoined their logs"


@REACTIVE_DRAWS
@given(**walk, wall_x=st.floats(1.5, 3.5), side=st.sampled_from([-1, 1]), thickness=st.floats(0.1, 0.6))
@example(seed=404072, walkers=9, speed=0.55078125, wall_x=1.75, side=1, thickness=0.5)  # slid along the band
@example(seed=404073, walkers=9, speed=0.5511564525973631, wall_x=1.6875, side=-1, thickness=0.5)
def test_a_log_across_a_traced_wall_traps_nobody_and_nobody_goes_deeper_than_its_log(
        seed: int, walkers: int, speed: float, wall_x: float, side: int, thickness: float) -> None:
    """A non-walkable band across the logs (a wall traced where people did walk), beside the standing robot: the
    pedestrians stepping round the robot still cross it near where their logs do, and none stands deeper in it than its
    log ever does."""
    depth = _open_square(wall=(side * wall_x, side * wall_x + thickness))
    crowd, path, log = _walk_past_a_standing_robot(seed, walkers, speed, depth)
    assert not _frozen(path, log), f"frozen (frame, walker): {_frozen(path, log)[:5]}"
    assert not crowd.state.off_log.any(), "a pedestrian stayed off its log (trapped behind the band?)"
    shares = np.linspace(0.0, 1.0, 9)[:, None, None, None]
    traced = depth.at(log[:-1] + shares * np.diff(log, axis=0)).max(axis=(0, 1))  # (W,) deepest along each log
    assert (depth.at(path) <= traced + 1e-9).all(), "deeper in the band than its log ever was"


def test_a_log_that_ends_where_the_robot_stands_leaves_beside_it() -> None:
    """Logs that end at the robot's spot: their pedestrians leave the scene beside the robot, not far away."""
    log = _straight_logs(4, 6, 1.2, frames=30)
    robot = log[-1, 0].copy()  # on the end of walker 0's log
    crowd = ReactiveCrowd(log, np.ones(log.shape[:2], bool), _open_square(), ROBOT, 0.25)
    present = np.ones(log.shape[:2], bool)
    present[-5:, 0] = False  # walker 0's log ends 5 frames before the others'
    crowd = ReactiveCrowd(np.where(present[..., None], log, np.nan), present, _open_square(), ROBOT, 0.25)
    crowd.reset(0)
    last_seen = None
    for index in range(1, len(log)):
        xy = crowd.step(index, robot, robot)
        if crowd.state.present[0]:
            last_seen = xy[0].copy()
    assert not crowd.state.present[0], "walker 0 never left"
    assert np.linalg.norm(last_seen - log[-6, 0]) <= 1.0 + 1e-9


@REACTIVE_DRAWS
@given(**walk, reaction=reactions, length=st.floats(0.0, 3.0), width=st.floats(0.0, 1.5), heading=st.floats(-3.2, 3.2))
def test_whatever_they_notice_nobody_walks_into_a_standing_robot_or_a_box(seed: int, walkers: int, speed: float,
                                                                          reaction: Reaction, length: float,
                                                                          width: float, heading: float) -> None:
    """The safety rule: with any reaction (blind and deaf ones included) and a disc or a vehicle's box, the
    pedestrians stay ``ROBOT_MARGIN_M`` clear of touching a standing body along every step, nobody freezes, nobody
    presses into anybody where the logs do not, and all are back on their logs by the end."""
    body = Body(length, width, 0.3 if length == width == 0 else 0.0)
    crowd, path, log = _walk_past_a_standing_robot(seed, walkers, speed, body=body, reaction=reaction,
                                                   heading=heading)
    gap = body.swept_gap_m(path[:-1], path[1:], heading)  # the body at the origin
    assert gap.min() >= 0.25 + ROBOT_MARGIN_M - 1e-9, f"a pedestrian came {gap.min():.3f} m from the body"
    assert not _frozen(path, log), f"frozen (frame, walker): {_frozen(path, log)[:5]}"
    apart = np.linalg.norm(path[:, :, None] - path[:, None], axis=-1)
    logged = np.linalg.norm(log[:, :, None] - log[:, None], axis=-1)
    assert not ((apart < 0.3) & (logged >= 0.3)).any(), "a pair overlaps by more than 10 cm where its logs do not"
    assert not crowd.state.off_log.any(), f"{crowd.state.off_log.sum()} pedestrians never rejoined their logs"


def _walker_and_moving_robot(lateral_m: float, robot_speed: float, start_m: float, reaction: Reaction,
                             frames: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One walker along +x at 1.2 m/s from the origin; a robot on a line ``lateral_m`` to its side, starting at
    x = ``start_m`` and driving toward the walker's side of it (head-on from ahead, along from behind) at
    ``robot_speed`` [m/s]. Returns the walker's path (F, 2), its log (F, 2) and the robot's positions (F, 2); at
    every step the crowd sees the robot's true move."""
    log = np.c_[np.arange(frames) * 0.4 * 1.2, np.zeros(frames)][:, None]  # (F, 1, 2)
    direction = -np.sign(start_m)
    robot = np.array([start_m, lateral_m]) + direction * robot_speed * 0.4 * np.c_[np.arange(frames), np.zeros(frames)]
    crowd = ReactiveCrowd(log, np.ones((frames, 1), bool), _open_square(30.0), ROBOT, 0.25, reaction)
    path = [crowd.reset(0)[0].copy()]
    for index in range(1, frames):
        path.append(crowd.step(index, robot[index - 1], robot[index])[0].copy())
    return np.array(path), log[:, 0], robot


@REACTIVE_DRAWS
@given(lateral=st.floats(0.0, 0.4), robot_speed=st.floats(1.3, 3.0), fov=st.floats(0.0, 80.0),
       hearing=st.floats(0.0, 3.0))
def test_a_robot_coming_from_behind_is_noticed_only_within_hearing(lateral: float, robot_speed: float, fov: float,
                                                                    hearing: float) -> None:
    """Field of view and hearing: a robot closing in from behind, outside the walker's field of view, is noticed only
    within hearing; until then the walker keeps to its log exactly (but for the safety rule, once the robot's body
    is within a log step of its log)."""
    reaction = Reaction(fov_deg=fov, hearing_m=hearing, reaction_s=0.0, anticipation_s=1.6, clearance_m=0.5,
                        head_on_s=0.5, behind_s=0.5, crossing_s=0.5, delay_cost=1.0, aside_cost=0.5)
    path, log, robot = _walker_and_moving_robot(lateral, robot_speed, -8.0, reaction)
    gap = np.linalg.norm(log - robot, axis=1) - 0.3
    heard = np.flatnonzero(gap <= max(hearing, 0.25 + ROBOT_MARGIN_M + 0.48))  # 0.48 m: a step of its log
    quiet = int(heard[0]) if heard.size else len(path) - 1  # steps up to here start with the robot unheard
    assert np.array_equal(path[:quiet + 1], log[:quiet + 1]), "the walker left its log before it heard the robot"


def test_a_robot_driving_along_the_log_of_a_walker_that_notices_nothing_reaches_it() -> None:
    """Inattention has a price: nothing keeps a fast robot from behind off a walker that neither sees nor hears it."""
    path, _, robot = _walker_and_moving_robot(0.0, 2.5, -8.0, UNAWARE)
    assert (np.linalg.norm(path - robot, axis=1) < CONTACT_M).any()


@REACTIVE_DRAWS
@given(lateral=st.floats(1.0, 2.0), robot_speed=st.floats(0.5, 2.0), reaction_s=st.floats(0.0, 2.0))
def test_a_walker_reacts_no_sooner_than_a_reaction_time_after_it_notices_the_robot(lateral: float,
                                                                                    robot_speed: float,
                                                                                    reaction_s: float) -> None:
    """Reaction time: a robot coming head-on beside the walker's log (which never touches the robot's body) is in
    view from the first step; the walker keeps to its log until ``reaction_s`` has passed (to the 0.4 s step it falls
    in), and then makes room."""
    reaction = Reaction(fov_deg=90.0, hearing_m=0.0, reaction_s=reaction_s, anticipation_s=4.0, clearance_m=1.5,
                        head_on_s=0.5, behind_s=0.5, crossing_s=0.5, delay_cost=1.0, aside_cost=0.5)
    path, log, _ = _walker_and_moving_robot(lateral, robot_speed, 10.0, reaction)
    strayed = np.flatnonzero(np.linalg.norm(path - log, axis=1) > 1e-9)
    assert strayed.size, "the walker never made room for the robot"
    assert 0.4 * strayed[0] > reaction_s - 1e-9, f"left its log at step {strayed[0]}, reaction time {reaction_s} s"


def test_a_walker_blind_and_deaf_still_goes_round_a_robot_standing_on_its_log() -> None:
    """The safety rule needs no attention: a robot standing on the log is gone round by a walker that notices
    nothing, just clear of touching it."""
    _, path, _ = _walk_past_a_standing_robot(3, 6, 1.2, reaction=UNAWARE)
    gap, _ = closest_approach(path[:-1], path[1:])
    assert CONTACT_M + ROBOT_MARGIN_M - 1e-9 <= gap.min() < CONTACT_M + 0.3, f"closest {gap.min():.3f} m"


def _pocket(wall_x: float, half_m: float = 8.0) -> MapDepth:
    """An open square with the non-walkable area y >= 0.5 m, x <= ``wall_x`` [m]: a robot standing at the origin
    leaves no room between its body and that wall, and a pocket between the two on the wall's open side."""
    size = int(2 * half_m / 0.05)
    walkable = np.ones((size, size), bool)
    walkable[int((0.5 + half_m) / 0.05):, :int((wall_x + half_m) / 0.05)] = False
    H = np.array([[0.05, 0.0, -half_m], [0.0, 0.05, -half_m], [0.0, 0.0, 1.0]])
    return MapDepth(Scene("pocket", H, walkable))


@REACTIVE_DRAWS
@given(lateral=st.floats(0.0, 0.45), wall_x=st.floats(-0.5, 1.0), speed=st.floats(0.6, 1.8))
def test_a_walker_in_a_pocket_between_a_standing_robot_and_a_wall_walks_back_out_and_round(
        lateral: float, wall_x: float, speed: float) -> None:
    """A log along y = ``lateral`` from x = 6 m to x = -6 m, through a robot standing at the origin whose far side a
    wall closes: the walker may step into the pocket above the robot first, but it comes out and goes round below,
    never freezes and is back on its log by the end (a pedestrian froze so beside a robot at ZARA1's busiest spot)."""
    frames = 70
    x = np.maximum(6.0 - np.arange(frames) * 0.4 * speed, -6.0)
    log = np.stack([x, np.full(frames, lateral)], axis=-1)[:, None]  # (F, 1, 2)
    depth = _pocket(wall_x)
    crowd = ReactiveCrowd(log, np.ones((frames, 1), bool), depth, ROBOT, 0.25)
    path = [crowd.reset(0).copy()]
    for index in range(1, frames):
        path.append(crowd.step(index, np.zeros(2), np.zeros(2)).copy())
    path = np.array(path)
    assert not _frozen(path, log), f"frozen (frame, walker): {_frozen(path, log)[:5]}"
    gap, _ = closest_approach(path[:-1], path[1:])
    assert gap.min() >= CONTACT_M, f"came {gap.min():.3f} m from the robot's centre"
    assert not crowd.state.off_log.any(), f"still off its log at the end, at {path[-1, 0]}"


@pytest.mark.parametrize("cross_at, robot_speed", [(4.0, 0.8), (4.0, 1.2), (5.0, 0.8), (5.0, 1.2)])
def test_a_walker_that_finds_the_side_dear_yields_to_a_crossing_robot_instead_of_stepping_round(
        cross_at: float, robot_speed: float) -> None:
    """``Reaction.aside_cost`` against ``delay_cost``: a robot crosses the walker's way ahead of it, from 3 m to its
    right; a walker for whom standing aside is cheap steps round in front of it, one for whom it is dear slows or
    waits and passes behind, so it strays less to the side and falls farther behind its log; neither touches it."""
    frames = 40
    log = np.c_[np.arange(frames) * 0.4 * 1.2, np.zeros(frames)][:, None]  # along +x at 1.2 m/s
    robot = np.c_[np.full(frames, cross_at), -3.0 + robot_speed * 0.4 * np.arange(frames)]  # along +y, across
    aside_m, behind_m = {}, {}
    for aside_cost in (0.05, 4.0):
        reaction = Reaction(fov_deg=90.0, hearing_m=4.0, reaction_s=0.0, anticipation_s=1.6, clearance_m=0.5,
                            head_on_s=0.5, behind_s=0.5, crossing_s=0.5, delay_cost=1.0, aside_cost=aside_cost)
        crowd = ReactiveCrowd(log, np.ones((frames, 1), bool), _open_square(30.0), ROBOT, 0.25, reaction)
        path = [crowd.reset(0)[0].copy()]
        for index in range(1, frames):
            path.append(crowd.step(index, robot[index - 1], robot[index])[0].copy())
        path = np.array(path)
        assert (np.linalg.norm(path - robot, axis=1) - ROBOT.radius_m > 0.25).all(), "the walker touched the robot"
        aside_m[aside_cost], behind_m[aside_cost] = np.abs(path[:, 1]).max(), (log[:, 0, 0] - path[:, 0]).max()
    assert aside_m[4.0] < aside_m[0.05], aside_m
    assert behind_m[4.0] > behind_m[0.05], behind_m
