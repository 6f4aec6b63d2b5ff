"""CrowdSim: determinism, physical soundness, population turnover, the ego, recordings, crowds stepped together."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from envs.common.layouts import build_layout
from replays import read_recording
from replays.constants import FRAME_STRIDE, STEP_S
from st_sim.sim import CrowdConfig, CrowdSim, EgoConfig, PopulationConfig, PopulationError, make_layout
from st_sim.sim.config import WALL_RADIUS_M
from st_sim.sim.crowd import step_crowds
from st_sim.sim.diagnostics import max_overlap_m

SYNTHETIC = ["corridor", "crossing", "bottleneck"]


def test_crowd_same_seed_gives_same_positions() -> None:
    layout = make_layout("crossing")
    cfg = CrowdConfig(max_pedestrians=60, spawn_rate_hz=2.0)
    sim_a = CrowdSim(layout, cfg, np.random.default_rng(7), ego=EgoConfig())
    sim_b = CrowdSim(layout, cfg, np.random.default_rng(7), ego=EgoConfig())
    actions = np.random.default_rng(1).uniform(-1.5, 1.5, (100, 2))
    for t, action in enumerate(actions):
        sim_a.step(action)
        sim_b.step(action)
        assert np.array_equal(sim_a.ids, sim_b.ids), f"[step {t}] ids differ"
        assert np.array_equal(sim_a.positions_m, sim_b.positions_m), f"[step {t}] positions differ"
        assert np.array_equal(sim_a.ego_position_m, sim_b.ego_position_m), f"[step {t}] ego differs"


def test_crowd_other_seed_gives_other_crowd() -> None:
    layout = make_layout("corridor")
    sim_a = CrowdSim(layout, CrowdConfig(), np.random.default_rng(0))
    sim_b = CrowdSim(layout, CrowdConfig(), np.random.default_rng(1))
    assert not np.array_equal(sim_a.positions_m, sim_b.positions_m)


def test_crowd_spawns_and_removes_pedestrians_with_fresh_ids() -> None:
    sim = CrowdSim(make_layout("corridor"), CrowdConfig(max_pedestrians=30, spawn_rate_hz=3.0),
                   np.random.default_rng(0), n_initial=0)
    assert len(sim.ids) == 0
    seen: set[int] = set()
    gone: set[int] = set()
    for t in range(120):
        before = set(sim.ids.tolist())
        sim.step()
        now = set(sim.ids.tolist())
        assert not now & gone, f"[step {t}] an id came back"
        assert all(i > max(seen, default=-1) for i in now - before), f"[step {t}] a new id is not fresh"
        assert len(now) <= 30, f"[step {t}] {len(now)} pedestrians exceed the cap"
        gone |= before - now
        seen |= now
    assert len(seen) > 30 and len(gone) > 5, f"spawned {len(seen)}, removed {len(gone)}"


def test_crowd_pedestrians_leave_at_their_exit() -> None:
    layout = make_layout("bottleneck")
    sim = CrowdSim(layout, CrowdConfig(max_pedestrians=10, spawn_rate_hz=0.0), np.random.default_rng(0))
    last_xy = {}
    for _ in range(150):
        last_xy.update(zip(sim.ids.tolist(), sim.positions_m, strict=True))
        sim.step()
    assert len(sim.ids) == 0, "everybody should have walked through the door and out"
    east = layout.exits[0]
    assert all(np.linalg.norm(xy - east.centre_m) < 4.0 for xy in last_xy.values())


def test_crowd_initial_population_respects_cap_and_density() -> None:
    layout = make_layout("corridor")
    assert len(CrowdSim(layout, CrowdConfig(max_pedestrians=25), np.random.default_rng(0)).ids) == 25
    sim = CrowdSim(layout, CrowdConfig(density_per_m2=0.5), np.random.default_rng(0))
    assert sim.max_pedestrians == round(0.5 * layout.walkable_area_m2())
    assert len(sim.ids) == sim.max_pedestrians
    assert max_overlap_m(sim.positions_m, CrowdConfig().radius_m) == 0.0


def test_ego_follows_the_command_within_speed_and_acceleration_limits() -> None:
    ego, cfg = EgoConfig(), CrowdConfig(spawn_rate_hz=0.0)
    sim = CrowdSim(make_layout("corridor"), cfg, np.random.default_rng(0), ego=ego, n_initial=0)
    start = sim.ego_position_m
    dt_s = STEP_S / cfg.n_substeps
    command, expected_x = 0.0, start[0]
    for t in range(8):
        sim.step(np.array([5.0, 0.0]))  # asks for more than the top speed
        for _ in range(cfg.n_substeps):
            command = min(command + ego.robot.max_accel_mps2 * dt_s, ego.robot.max_speed_mps)
            expected_x += command * dt_s
        assert sim.ego_velocity_mps == pytest.approx([command, 0.0], abs=1e-9), f"[step {t}]"
        assert sim.ego_position_m == pytest.approx([expected_x, start[1]], abs=1e-9), f"[step {t}]"
        assert not sim.ego_collided, f"[step {t}]"
    assert command == ego.robot.max_speed_mps
    sim.step(None)  # no command = brake
    assert np.linalg.norm(sim.ego_velocity_mps) == pytest.approx(ego.robot.max_speed_mps
                                                                 - ego.robot.max_brake_mps2 * STEP_S)


def test_ego_reports_contact_with_a_wall() -> None:
    layout = make_layout("corridor")
    sim = CrowdSim(layout, CrowdConfig(spawn_rate_hz=0.0), np.random.default_rng(0), ego=EgoConfig(), n_initial=0)
    touched = []
    for _ in range(12):  # the wall at y = 8 m is 4 m north of the start
        sim.step(np.array([0.0, 1.5]))
        touched.append(sim.ego_collided)
    assert touched[-1] and not touched[0]
    assert sim.ego_position_m[1] == pytest.approx(8.0 - WALL_RADIUS_M - EgoConfig().radius_m, abs=0.01), \
        "the wall must stop the ego at contact"
    assert np.linalg.norm(sim.ego_velocity_mps) < 1e-6


def test_ego_reports_contact_with_a_pedestrian() -> None:
    cfg = CrowdConfig(max_pedestrians=1, spawn_rate_hz=0.0,
                      population=PopulationConfig(speed_mean_mps=0.0, speed_std_mps=0.0, speed_range_mps=(0.0, 0.0)))
    sim = CrowdSim(make_layout("corridor"), cfg, np.random.default_rng(0), ego=EgoConfig(), n_initial=1)
    target = sim.positions_m[0]
    collided = False
    for _ in range(60):
        to_target = target - sim.ego_position_m
        sim.step(1.5 * to_target / max(np.linalg.norm(to_target), 1e-9))
        collided |= sim.ego_collided
    assert collided, "driving the ego at a standing pedestrian must register a contact"


def test_history_round_trips_through_a_recording(tmp_path) -> None:
    sim = CrowdSim(make_layout("crossing"), CrowdConfig(max_pedestrians=20, spawn_rate_hz=2.0),
                   np.random.default_rng(2))
    for _ in range(30):
        sim.step()
    history = sim.history()
    assert set(np.unique(history.frame).tolist()) == {FRAME_STRIDE * t for t in range(31)}
    last = history.frame == FRAME_STRIDE * 30
    assert np.array_equal(history.agent[last], sim.ids) and np.array_equal(history.xy_m[last], sim.positions_m)
    back = read_recording(sim.save_recording(tmp_path / "crossing.txt"))
    order = np.lexsort((history.agent, history.frame))
    assert np.array_equal(back.frame, history.frame[order]) and np.array_equal(back.agent, history.agent[order])
    np.testing.assert_allclose(back.xy_m, history.xy_m[order], atol=1e-6)


def test_crowd_refuses_more_pedestrians_than_fit_and_says_how_many_do() -> None:
    layout = make_layout("corridor")
    with pytest.raises(PopulationError, match=r"1000 pedestrians asked for .* only (\d+) fit") as err:
        CrowdSim(layout, CrowdConfig(max_pedestrians=1000), np.random.default_rng(0))
    fit = int(re.search(r"only (\d+) fit", str(err.value)).group(1))
    assert 500 < fit < 1000
    assert len(CrowdSim(layout, CrowdConfig(max_pedestrians=fit), np.random.default_rng(0)).ids) == fit


def test_crowd_refuses_an_initial_count_above_the_cap() -> None:
    with pytest.raises(PopulationError, match="n_initial = 50"):
        CrowdSim(make_layout("corridor"), CrowdConfig(max_pedestrians=40), np.random.default_rng(0), n_initial=50)


def _ego_contacts(see: bool, seed: int) -> int:
    """Steps in which a standing ego in the middle of the two-way corridor was touched by a pedestrian."""
    sim = CrowdSim(make_layout("corridor"), CrowdConfig(max_pedestrians=60, spawn_rate_hz=2.0),
                   np.random.default_rng(seed), ego=EgoConfig(start_m=(10.0, 4.0), pedestrians_see_ego=see))
    touched = 0
    for _ in range(150):
        sim.step(np.zeros(2))
        touched += sim.ego_collided
    return touched


def test_pedestrians_who_see_the_ego_walk_around_it() -> None:
    seen = sum(_ego_contacts(True, seed) for seed in range(2))
    unseen = sum(_ego_contacts(False, seed) for seed in range(2))
    assert unseen > 0, "an invisible ego in the middle of the flow should be bumped into"
    assert seen < unseen / 4, f"pedestrians who see the ego touched it in {seen} steps (invisible: {unseen})"


@settings(max_examples=6, deadline=None)
@given(layout=st.sampled_from(["crossing", "bottleneck", "zara1"]), crowds=st.integers(2, 4), ego=st.booleans(),
       seed=st.integers(0, 10_000))
def test_crowds_stepped_together_move_exactly_as_alone(layout: str, crowds: int, ego: bool, seed: int) -> None:
    """``step_crowds``: arrivals, stops, groups, contacts and the egos of several crowds batched, every crowd bit for
    bit as it moves stepped alone (each draws from its own generator, in the order it would alone)."""
    geometry = build_layout(layout)
    cfg = CrowdConfig(population=PopulationConfig.fitted(layout)) if layout == "zara1" else CrowdConfig()

    def fresh() -> list[CrowdSim]:
        return [CrowdSim(geometry, cfg, np.random.default_rng(seed + k), ego=EgoConfig() if ego else None)
                for k in range(crowds)]

    together, alone = fresh(), fresh()
    rng = np.random.default_rng(seed)
    for t in range(40):
        velocities = [rng.uniform(-1.5, 1.5, 2) if ego else None for _ in range(crowds)]
        step_crowds(together, velocities)
        for sim, velocity in zip(alone, velocities, strict=True):
            sim.step(velocity)
        for k, (a, b) in enumerate(zip(together, alone, strict=True)):
            assert np.array_equal(a.ids, b.ids) and np.array_equal(a.positions_m, b.positions_m), f"step {t} crowd {k}"
            assert np.array_equal(a.groups, b.groups) and np.array_equal(a.standing, b.standing), f"step {t} crowd {k}"
            assert (a.ego_contact is None) == (b.ego_contact is None) and a.ego_nearest_m == b.ego_nearest_m
