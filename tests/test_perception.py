"""What the robot senses (st_sim.perception): occlusion hides exactly who is behind a body or a wall, the oracle sees
everything exactly, sensing never changes the world, the tracker keeps identities it can, and the tracking figures
are right on cases worked by hand."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import envs  # registers the ids
from replays.scenes import Scene
from st_sim.perception import SENSING_LEVELS, MotAccumulator, SensingSpec, SensingSpecError, Tracker, detect
from st_sim.perception.sensor import poisson

H_IDENTITY = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 1.0]])  # pixel = 10 x metres


def open_scene(wall: tuple[slice, slice] | None = None) -> Scene:
    """A 40 m x 40 m walkable map (0.1 m pixels, world origin at pixel (0, 0)), with a wall block if given."""
    walkable = np.ones((400, 400), bool)
    if wall is not None:
        walkable[wall] = False
    return Scene("open", np.linalg.inv(H_IDENTITY), walkable)


def segment_gap_m(a: np.ndarray, b: np.ndarray, p: np.ndarray) -> float:
    """Distance from point ``p`` to the segment a -> b [m]."""
    ab, ap = b - a, p - a
    t = min(max(float(ap @ ab) / max(float(ab @ ab), 1e-12), 0.0), 1.0)
    return float(np.linalg.norm(ap - t * ab))


PEOPLE = st.lists(st.tuples(st.floats(5.0, 35.0), st.floats(5.0, 35.0)), min_size=1, max_size=25)


@settings(max_examples=150, deadline=None)
@given(people=PEOPLE, rx=st.floats(10.0, 30.0), ry=st.floats(10.0, 30.0), angle=st.floats(-math.pi, math.pi))
def test_occlusion_hides_exactly_those_behind_a_body_or_a_wall(people: list, rx: float, ry: float,
                                                               angle: float) -> None:
    """Detected: in range and view, no nearer body on the line of sight, no wall on it. Not detected, though clear of
    every such thing by a margin (1 cm from bodies, 0.15 m from walls, 1 cm and 0.1 degree from the field's edge):
    never."""
    scene = open_scene((slice(180, 220), slice(250, 260)))  # a wall 1 m thick at x = 25-26 m, y = 18-22 m
    spec = SensingSpec(range_m=12.0, fov_deg=270.0, occlusion=True)
    robot, heading, radius = np.array([rx, ry]), np.array([math.cos(angle), math.sin(angle)]), 0.25
    xy = np.array(people, np.float64)
    ids = np.arange(len(xy)) + 100
    seen = detect(spec, robot, heading, ids, xy, scene, radius, 0.3, np.random.default_rng(0))
    assert (seen.source >= 0).all() and np.array_equal(seen.xy_m, xy[seen.source - 100]), "no noise: exact"
    assert np.array_equal(np.sort(seen.source), seen.visible_ids), "no misses: every visible person detected"
    fractions = np.linspace(0.0, 1.0, 2000)
    for i in range(len(xy)):
        offset = xy[i] - robot
        distance = float(np.linalg.norm(offset))
        off_axis = math.degrees(math.acos(max(-1.0, min(1.0, float(offset @ heading) / max(distance, 1e-12)))))
        nearer = [j for j in range(len(xy)) if j != i and np.linalg.norm(xy[j] - robot) < distance]
        gaps = [segment_gap_m(robot, xy[i], xy[j]) for j in nearer]
        from_robot = fractions * distance
        line = robot + fractions[:, None] * offset
        wall = ~scene.is_walkable(line)
        if ids[i] in seen.source:
            assert distance <= 12.0 and off_axis <= 135.0 + 1e-6, f"person {i} detected outside the field"
            assert all(gap >= radius - 1e-9 for gap in gaps), f"person {i} detected behind a body"
            assert not (wall & (from_robot > 0.3 + 0.15) & (from_robot < distance - radius - 0.15)).any(), \
                f"person {i} detected behind a wall"
        else:
            clear = (distance < 12.0 - 0.01 and off_axis < 135.0 - 0.1 and all(gap > radius + 0.01 for gap in gaps)
                     and not (wall & (from_robot > 0.3 - 0.15) & (from_robot < distance - radius + 0.15)).any())
            assert not clear, f"person {i} in plain sight was not detected"


def test_a_person_behind_another_is_hidden_and_one_beside_is_seen() -> None:
    spec = SensingSpec(range_m=10.0, occlusion=True)
    robot, heading = np.array([10.0, 10.0]), np.array([1.0, 0.0])
    xy = np.array([[12.0, 10.0], [15.0, 10.1], [15.0, 11.0]])  # the second right behind the first
    seen = detect(spec, robot, heading, np.array([1, 2, 3]), xy, open_scene(), 0.25, 0.3, np.random.default_rng(0))
    assert seen.source.tolist() == [1, 3]
    behind_wall = detect(spec, robot, heading, np.array([1]), np.array([[30.0, 20.0]]), open_scene(
        (slice(140, 260), slice(200, 210))), 0.25, 0.3, np.random.default_rng(0))
    assert behind_wall.source.tolist() == [], "a wall between them hides the person"


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), mean=st.floats(0.0, 20.0))
def test_poisson_draws_are_bounded_and_reproducible(seed: int, mean: float) -> None:
    a, b = poisson(np.random.default_rng(seed), mean), poisson(np.random.default_rng(seed), mean)
    assert a == b and 0 <= a <= 10 * int(mean) + 50


def test_poisson_draws_have_their_mean() -> None:
    rng = np.random.default_rng(1)
    draws = np.array([poisson(rng, 0.2) for _ in range(20000)])
    assert draws.mean() == pytest.approx(0.2, abs=0.01)


@settings(max_examples=200, deadline=None)
@given(field=st.sampled_from(["range_m", "fov_deg", "noise_m", "noise_per_m", "miss_rate", "false_per_step",
                              "latency_steps", "occlusion", "oracle"]),
       value=st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-100, 1000), st.booleans(),
                       st.text(max_size=4), st.none()))
def test_a_sensing_spec_refuses_any_bad_field_naming_it(field: str, value: object) -> None:
    try:
        spec = SensingSpec(**{"range_m": 10.0, field: value})
    except SensingSpecError as err:
        assert f"SensingSpec.{field}" in str(err) or "SensingSpec." in str(err)
        return
    assert getattr(spec, field) == value


# ---------------------------------------------------------------- the tracker and its figures


def test_tracks_keep_their_people_when_they_walk_apart() -> None:
    tracker = Tracker(capacity=10)
    starts = np.array([[0.0, 0.0], [0.0, 3.0], [5.0, 6.0]])
    velocity = np.array([[1.2, 0.0], [1.0, 0.2], [-0.8, 0.5]])
    mot = MotAccumulator()
    for step in range(20):
        truth = starts + step * 0.4 * velocity
        tracks = tracker.step(truth, np.full(3, 0.05), np.array([7, 8, 9]))
        mot.update(np.array([7, 8, 9]), truth, tracks.ids, tracks.xy_m)
        if step >= 1:
            assert sorted(tracks.source.tolist()) == [7, 8, 9]
    summary = mot.summary()
    assert summary["id_switches"] == 0 and summary["false_tracks"] == 0
    assert summary["misses"] == 3, "only the first step, before the tracks are confirmed"
    assert summary["mota"] == pytest.approx(1 - 3 / 60)
    assert summary["idf1"] == pytest.approx(2 * 57 / (60 + 57)), "57 tracked of 60 true, 57 tracks"


def test_a_lost_person_ends_their_track_and_comes_back_under_a_new_id() -> None:
    tracker = Tracker(capacity=10)
    ids_seen = []
    for step in range(12):
        xy = np.array([[0.4 * step, 0.0]])
        detections = xy if not 4 <= step < 9 else np.zeros((0, 2))  # lost for 5 steps (longer than 3 misses)
        tracks = tracker.step(detections, np.full(len(detections), 0.05), np.full(len(detections), 1))
        ids_seen.append(tracks.ids.tolist())
    assert ids_seen[0] == [] and ids_seen[3] == ids_seen[2] == ids_seen[1] == [0], "confirmed at its second hit"
    assert ids_seen[4] == ids_seen[5] == ids_seen[6] == [0], "a confirmed track coasts through three misses"
    assert ids_seen[7] == ids_seen[8] == ids_seen[9] == [], "then it ends; the new one is tentative for a step"
    assert ids_seen[10] == [1], "the person comes back under a new id"


def test_clear_mot_counts_a_swap_once_and_idf1_pairs_identities() -> None:
    """Two people, two tracks; the tracks swap after 3 of 6 steps: one switch each, MOTA = 1 - 2/12, IDF1 = 6/12."""
    mot = MotAccumulator()
    truth = np.array([[0.0, 0.0], [5.0, 0.0]])
    for step in range(6):
        tracks = np.array([10, 11]) if step < 3 else np.array([11, 10])
        mot.update(np.array([1, 2]), truth, tracks, truth + 0.1)
    summary = mot.summary()
    assert summary["id_switches"] == 2
    assert summary["mota"] == pytest.approx(1 - 2 / 12)
    assert summary["motp_m"] == pytest.approx(math.hypot(0.1, 0.1))
    assert summary["idf1"] == pytest.approx(2 * 6 / 24)


def test_clear_mot_counts_misses_and_false_tracks() -> None:
    mot = MotAccumulator()
    mot.update(np.array([1, 2]), np.array([[0.0, 0.0], [3.0, 0.0]]), np.array([5, 6]),
               np.array([[0.2, 0.0], [9.0, 9.0]]))  # one match, one miss, one false track
    mot.update(np.array([], np.int64), np.zeros((0, 2)), np.array([5]), np.array([[0.0, 0.0]]))
    summary = mot.summary()
    assert (summary["misses"], summary["false_tracks"], summary["true_people"]) == (1, 2, 2)
    assert summary["mota"] == pytest.approx(1 - 3 / 2)
    assert math.isnan(MotAccumulator().summary()["mota"])


# ---------------------------------------------------------------- in the envs


def goal_seeking(obs: dict[str, np.ndarray]) -> np.ndarray:
    """A policy that reads only the robot's own state: full speed toward the goal."""
    way = obs["ego"][4:6].astype(np.float64) - obs["ego"][:2]
    return 1.5 * way / max(float(np.linalg.norm(way)), 1e-9)


@pytest.mark.parametrize("env_id", ["STCrowd-SimCrossing-v1", "STCrowd-Univ-v0:reactive", "STCrowd-Zara1-v0"])
def test_a_blind_policy_meets_the_same_episode_at_every_level(env_id: str) -> None:
    name, _, mode = env_id.partition(":")
    kwargs = {"pedestrians": mode} if mode else {}
    worlds = {}
    for level in SENSING_LEVELS:
        env = gym.make(name, predictor="cvm", sensing=level, **kwargs)
        obs, info = env.reset(seed=4)
        ego, truth = [obs["ego"][:4].copy()], []
        for _ in range(25):
            obs, _, terminated, truncated, info = env.step(goal_seeking(obs))
            ego.append(obs["ego"][:4].copy())
            truth.append((env.unwrapped.tracks.now.ids.copy(), env.unwrapped.tracks.now.xy_m.copy()))
            if terminated or truncated:
                break
        worlds[level] = (np.array(ego), truth)
        if level != "oracle":
            assert {"true_ids", "true_xy_m", "detected_xy_m", "detected_from", "track_ids"} <= set(info["perception"])
            assert np.array_equal(np.sort(info["perception"]["true_ids"]), env.unwrapped.tracks.now.ids)
        env.close()
    reference = worlds["oracle"]
    for level, (ego, truth) in worlds.items():
        assert np.array_equal(ego, reference[0]), f"{level}: the robot moved otherwise"
        for (ids, xy), (ref_ids, ref_xy) in zip(truth, reference[1], strict=True):
            assert np.array_equal(ids, ref_ids) and np.array_equal(xy, ref_xy), f"{level}: the crowd moved otherwise"


def test_the_oracle_sees_every_pedestrian_exactly_and_others_see_tracks() -> None:
    env = gym.make("STCrowd-Zara1-v0", predictor="cvm")
    obs, info = env.reset(seed=1)
    now = env.unwrapped.tracks.now
    rows = np.flatnonzero(obs["history_mask"][:, -1])
    assert np.array_equal(np.sort(info["agent_ids"][rows]), now.ids)
    assert np.allclose(obs["history"][rows, -1], now.xy_m[np.searchsorted(now.ids, info["agent_ids"][rows])],
                       atol=1e-6)
    assert "perception" not in info
    sensed = gym.make("STCrowd-Zara1-v0", predictor="cvm", sensing="realistic")
    obs, info = sensed.reset(seed=1)
    rows = np.flatnonzero(obs["history_mask"][:, -1])
    assert set(info["agent_ids"][rows].tolist()) <= set(info["perception"]["track_ids"].tolist())


def test_sensing_needs_a_robot_and_a_known_level() -> None:
    with pytest.raises(ValueError, match="sensing"):
        gym.make("STCrowd-Zara1-v0", predictor="cvm", ego=False, sensing="noisy")
    with pytest.raises(ValueError, match="sensing="):
        gym.make("STCrowd-SimCrossing-v1", predictor="cvm", sensing="x-ray")


@pytest.mark.parametrize("mode", ["native", "sync"])
def test_vector_envs_sense_as_single_envs_do(mode: str) -> None:
    """A gymnasium vector env keeps each sub-env's perception (arrays of their own lengths), and a native vector env
    perceives each sub-env's crowd as the single env does."""
    kwargs = {} if mode == "native" else {"vectorization_mode": "sync"}
    vector = gym.make_vec("STCrowd-SimCrossing-v1", num_envs=2, predictor="cvm", sensing="realistic", **kwargs)
    single = gym.make("STCrowd-SimCrossing-v1", predictor="cvm", sensing="realistic")
    vobs, vinfo = vector.reset(seed=[6, 7])
    obs, info = single.reset(seed=7)
    for t in range(6):
        vobs, _, _, _, vinfo = vector.step(np.tile([0.3, 0.0], (2, 1)))
        obs, _, terminated, truncated, info = single.step(np.array([0.3, 0.0]))
        assert np.array_equal(vobs["history"][1], obs["history"]), f"step {t}"
        assert np.array_equal(vinfo["perception"][1]["track_ids"], info["perception"]["track_ids"]), f"step {t}"
        if terminated or truncated:
            break
    vector.close()
    single.close()


def judged(env_id: str, level: str, seed: int, **kwargs) -> list[tuple]:
    """What the env judged at each step of a goal-seeking episode at sensing ``level``: the reward, the end, the
    fault, the impact's time and the ego's metrics."""
    env = gym.make(env_id, predictor="cvm", sensing=level, **kwargs)
    obs, _ = env.reset(seed=seed)
    steps = []
    for _ in range(60):
        obs, reward, terminated, truncated, info = env.step(goal_seeking(obs))
        metrics = info["metrics"]
        steps.append((reward, info["termination"], info["at_fault"], info["contact_time_s"],
                      metrics["ego_collisions"], metrics["min_ego_ped_distance_m"]))
        if terminated or truncated:
            break
    env.close()
    return steps


@pytest.mark.parametrize(("env_id", "kwargs"), [("STCrowd-SimCrossing-v1", {"pedestrians_see_ego": False}),
                                               ("STCrowd-Zara1-v0", {})], ids=["sim", "replay"])
def test_collisions_and_fault_are_judged_on_the_truth_at_every_level(env_id: str, kwargs: dict) -> None:
    """docs/sensing.md: collisions and fault are always judged on the truth, and every figure but the tracking and
    forecast ones is measured on it, whatever the robot saw: a goal-seeking robot that runs into someone is judged
    alike at every sensing level, step for step."""
    for seed in range(1, 12):  # the first episode that ends in a collision, so that there is one to judge
        reference = judged(env_id, "oracle", seed, **kwargs)
        if reference[-1][1] == "pedestrian_collision":
            break
    else:
        pytest.fail("no goal-seeking episode ran into anybody: nothing was judged")
    for level in SENSING_LEVELS:
        assert judged(env_id, level, seed, **kwargs) == reference, f"{level}: judged otherwise than the truth"


@pytest.mark.parametrize("task", ["stochastic", "momentary"])
def test_a_track_gets_a_forecast_only_once_it_is_as_long_as_the_task_observes(task: str) -> None:
    """docs/sensing.md: the forecast needs T_obs consecutive steps of a track (8, or 2 for the momentary task), so a
    younger track gets no forecast, and every track that old gets one."""
    env = gym.make("STCrowd-Univ-v0", predictor="cvm", sensing="realistic", task=task)
    young = checked = 0
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        for t in range(15):
            full = obs["history_mask"].all(axis=1)
            assert np.array_equal(obs["futures_mask"], full), f"[seed {seed} step {t}] {obs['futures_mask']}"
            young += int((obs["history_mask"][:, -1] & ~full).sum())
            checked += int(full.sum())
            obs, _, terminated, truncated, _ = env.step(np.zeros(2))
            if terminated or truncated:
                break
    assert young and checked, f"{young} young and {checked} full tracks: nothing was checked"


def test_the_suite_env_senses_as_the_crowd_envs_do() -> None:
    """docs/sensing.md: every env id, the vector envs and the suite env take ``sensing=``."""
    env = gym.make(envs.SUITE_ID, scenarios=["sim-corridor"], predictor="cvm", sensing="realistic")
    _, info = env.reset(seed=1)
    _, _, _, _, info = env.step(np.array([1.0, 0.0], np.float32))
    assert {"true_ids", "detected_xy_m", "track_ids", "mot"} <= set(info["perception"])
    env.close()
