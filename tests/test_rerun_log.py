from __future__ import annotations

import importlib
import os
import subprocess
import sys

import numpy as np
import pytest
from rrd_files import read_blueprint, read_rrd, rrd_reader

from replays import load_scene, load_windows
from replays.scenes import Scene
from st_sim.rerun_log import BLOCKED, METRIC_VIEWS, OFF_PHOTO, WALKABLE, RerunLogger, metric_unit, scene_raster

S = 4  # predicted futures per agent in the synthetic steps


def synthetic_step(step: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Three agents; agents 3 and 8 are predicted except at step 2, where only agent 3 is."""
    ids = np.array([3, 8, 11])
    prediction_ids = np.array([3, 8]) if step < 2 else np.array([3])
    trails = rng.uniform(0, 5, size=(3, 6, 2))
    trail_mask = np.ones((3, 6), bool)
    trail_mask[1, :4] = False  # agent 8 appeared two steps ago
    return {
        "positions_m": rng.uniform(0, 5, size=(3, 2)), "ids": ids, "trails": trails, "trail_mask": trail_mask,
        "predictions": rng.uniform(0, 5, size=(len(prediction_ids), S, 12, 2)), "prediction_ids": prediction_ids,
        "prototype_anchors": rng.uniform(0, 5, size=(len(prediction_ids), S, 12, 2)),
        "adapted_anchors": rng.uniform(0, 5, size=(len(prediction_ids), S, 12, 2)),
        "ego_xy_m": np.array([1.0, 1.0 + step]), "ego_goal_m": np.array([4.0, 4.0]),
        "metrics": {"ade_m": 0.5 * step, "collisions": float(step == 1)},
    }


@pytest.fixture
def toy_recording(tmp_path, toy_scene):
    """A three-step recording of the toy scene; returns (path, logged steps)."""
    rng = np.random.default_rng(0)
    steps = [synthetic_step(step, rng) for step in range(3)]
    path = tmp_path / "toy.rrd"
    with RerunLogger(path, toy_scene) as log:
        for step, kwargs in enumerate(steps):
            kwargs = dict(kwargs)
            log.log_step(step, kwargs.pop("positions_m"), kwargs.pop("ids"), **kwargs)
    return path, steps


def test_recording_has_the_design_entity_paths(toy_recording):
    path, _ = toy_recording
    entities = read_rrd(path)
    expected = {"/world", "/world/scene", "/world/scene/photo", "/world/scene/walkable", "/world/agents",
                "/world/trails", "/world/predictions/3", "/world/predictions/8", "/world/anchors/prototype",
                "/world/anchors/adapted", "/world/ego", "/world/ego/goal", "/metrics/metres/ade_m",
                "/metrics/count/collisions"}
    assert expected <= set(entities), f"missing {expected - set(entities)}"
    assert not path.with_name(f".{path.name}.part").exists(), "temporary file left behind"


def test_recording_holds_the_logged_values(toy_recording):
    path, steps = toy_recording
    entities = read_rrd(path)
    for step, logged in enumerate(steps):
        agents = entities["/world/agents"][step]
        np.testing.assert_allclose(agents["Points2D:positions"], logged["positions_m"], rtol=1e-6,
                                   err_msg=f"[step {step}] agent positions")
        assert agents["Points2D:labels"] == ["3", "8", "11"], f"[step {step}]"
        strips = entities["/world/predictions/3"][step]["LineStrips2D:strips"]
        np.testing.assert_allclose(strips, logged["predictions"][0], rtol=1e-6, err_msg=f"[step {step}] agent 3")
        adapted = entities["/world/anchors/adapted"][step]["LineStrips2D:strips"]
        assert len(adapted) == len(logged["prediction_ids"]) * S, f"[step {step}] adapted anchor strips"
        assert entities["/metrics/metres/ade_m"][step]["Scalars:scalars"] == [0.5 * step], f"[step {step}]"
    trail_lengths = [len(strip) for strip in entities["/world/trails"][1]["LineStrips2D:strips"]]
    assert trail_lengths == [6, 2, 6], "masked trail points must be dropped"
    np.testing.assert_allclose(entities["/world/ego"][2]["Points2D:positions"], [[1.0, 3.0]])


def test_recording_clears_agents_no_longer_predicted(toy_recording):
    path, _ = toy_recording
    entities = read_rrd(path)
    assert "LineStrips2D:strips" in entities["/world/predictions/8"][1]
    assert entities["/world/predictions/8"][2] == {"Clear:is_recursive": [False]}, "agent 8 left at step 2"
    assert "LineStrips2D:strips" in entities["/world/predictions/3"][2]


def test_recording_time_timeline_counts_seconds(toy_recording):
    path, _ = toy_recording
    for chunk in rrd_reader(path).stream():
        if chunk.entity_path == "/world/agents":
            batch = chunk.to_record_batch()
            steps = batch.column("step").to_pylist()
            time_ns = batch.column("time").cast("int64").to_pylist()
            assert time_ns == [round(step * 0.4e9) for step in steps]
            return
    pytest.fail("no /world/agents chunk")


def test_blueprint_puts_each_unit_in_its_own_time_series_beside_the_world(toy_recording):
    path, steps = toy_recording
    parts = read_blueprint(path)
    views = {key: part for key, part in parts.items() if "class_identifier" in part}
    time_series = {part["space_origin"][0]: (key, part["display_name"][0]) for key, part in views.items()
                   if part["class_identifier"] == ["TimeSeries"]}
    assert time_series.keys() == {f"/metrics/{unit}" for unit in METRIC_VIEWS}, time_series
    assert {name for _, name in time_series.values()} == set(METRIC_VIEWS.values())
    world = [key for key, part in views.items() if part["class_identifier"] == ["2D"]]
    assert len(world) == 1 and parts[f"{world[0]}/ViewContents"]["query"] == ["/world/**"]
    containers = {key.removeprefix("/"): part["contents"] for key, part in parts.items() if "contents" in part}
    root = next(contents for contents in containers.values() if f"{world[0].removeprefix('/')}" in contents)
    column = containers[next(c for c in root if c.startswith("container/"))]
    assert sorted(column) == sorted(key.removeprefix("/") for key, _ in time_series.values()), \
        "the time series share one column beside the world view"
    logged = {f"/metrics/{metric_unit(name)}/{name}" for step in steps for name in step["metrics"]}
    for entity in logged:
        origins = [origin for origin in time_series if entity.startswith(origin + "/")]
        assert len(origins) == 1, f"{entity} is shown in {origins}"
    assert logged <= set(read_rrd(path)), "metrics are logged where the blueprint looks"


@pytest.mark.parametrize(("name", "unit"), [
    ("reward", "reward"), ("ade_m", "metres"), ("fde_m", "metres"), ("min_ego_ped_distance_m", "metres"),
    ("map_violation", "share"), ("discomfort_share", "share"), ("collision_rate", "share"), ("matured", "count"),
    ("ego_collisions", "count")], ids=lambda value: str(value))
def test_metric_unit_groups_metrics_by_what_they_measure(name: str, unit: str) -> None:
    assert metric_unit(name) == unit


def test_affine_scene_photo_is_placed_by_its_homography(tmp_path):
    # a rotated, sheared, y-flipped affine homography: the logged 3x3 must be read back in the same order
    H = np.array([[0.03, 0.01, 2.0], [0.005, -0.04, 7.0], [0.0, 0.0, 1.0]])
    walkable = np.ones((30, 50), bool)
    scene = Scene("sheared", H, walkable)
    path = tmp_path / "sheared.rrd"
    RerunLogger(path, scene).close()
    transform = read_rrd(path)["/world/scene"][None]
    matrix = np.array(transform["Transform3D:mat3x3"][0]).reshape(3, 3).T  # stored column-major
    translation = np.array(transform["Transform3D:translation"][0])
    pixels = np.array([[0, 0], [49, 0], [10, 29], [25, 14]], dtype=np.float64)
    image_coords = np.c_[pixels + 0.5, np.zeros(4)]  # Rerun: pixel (c, r) spans [c, c+1] x [r, r+1]
    placed = image_coords @ matrix.T + translation
    np.testing.assert_allclose(placed[:, :2], scene.pixel_to_world(pixels), atol=1e-5)


def test_real_scene_recording_has_photo_map_and_window_agents(tmp_path):
    scene, windows = load_scene("zara1"), load_windows("stochastic", "zara1", "test")
    first = windows.group == 0
    path = tmp_path / "zara1.rrd"
    with RerunLogger(path, scene) as log:
        for t in range(3):
            log.log_step(t, windows.obs[first, t], windows.agent[first], trails=windows.obs[first, : t + 1])
    entities = read_rrd(path)
    photo = entities["/world/scene/photo"][None]
    assert photo["Image:format"][0]["width"] == 720 and photo["Image:format"][0]["height"] == 576
    assert len(entities["/world/scene/walkable"][None]["SegmentationImage:buffer"][0]) == 720 * 576
    np.testing.assert_allclose(entities["/world/agents"][2]["Points2D:positions"], windows.obs[first, 2], rtol=1e-6)


@pytest.mark.parametrize("name", ["zara1", "eth"], ids=["zara1-affine", "eth-projective"])
def test_scene_raster_map_agrees_with_scene_walkability(name):
    scene = load_scene(name)
    raster = scene_raster(scene)
    assert raster.warped == (name == "eth")
    height, width = scene.walkable.shape
    rng = np.random.default_rng(1)
    pixels = rng.uniform([0, 0], [width - 1, height - 1], size=(2000, 2))
    xy_m = scene.pixel_to_world(pixels)
    coords = np.c_[xy_m, np.ones(len(xy_m))] @ np.linalg.inv(raster.world_from_raster).T  # image coordinates
    index = np.floor(coords[:, :2]).astype(int)
    classes = raster.classes[index[:, 1], index[:, 0]]
    assert not (classes == OFF_PHOTO).any(), "points on the photo fell outside the raster"
    agreement = ((classes == WALKABLE) == scene.is_walkable(xy_m)).mean()
    assert agreement > 0.97, f"{name}: raster and map agree on {agreement:.3f} of points"
    assert set(np.unique(raster.classes)) <= {WALKABLE, BLOCKED, OFF_PHOTO}


def test_two_loggers_write_separate_recordings(tmp_path, toy_scene):
    paths = [tmp_path / "a.rrd", tmp_path / "b.rrd"]
    loggers = [RerunLogger(p, toy_scene) for p in paths]
    for step in range(2):
        for k, log in enumerate(loggers):
            log.log_step(step, np.full((1, 2), 10.0 * k + step), [k])
    for log in loggers:
        log.close()
    for k, path in enumerate(paths):
        agents = read_rrd(path)["/world/agents"]
        assert agents[1]["Points2D:positions"] == [[10.0 * k + 1, 10.0 * k + 1]], f"[logger {k}]"
        assert agents[1]["Points2D:labels"] == [str(k)], f"[logger {k}]"


@pytest.mark.parametrize("bad", [
    {"positions_m": np.zeros((3, 3))},
    {"ids": np.arange(4)},
    {"predictions": np.zeros((2, S, 12, 2)), "prediction_ids": np.array([1])},
    {"predictions": np.zeros((1, S, 12, 2))},
    {"adapted_anchors": np.zeros((1, S, 12)), "prediction_ids": np.array([1])},
    {"trails": [np.zeros((4, 2))] * 2},
    {"positions_m": np.full((3, 2), np.nan)},
], ids=["positions-3d", "ids-length", "predictions-vs-ids", "no-prediction-ids", "anchors-shape", "trail-count",
        "nan-position"])
def test_log_step_rejects_bad_inputs(tmp_path, toy_scene, bad):
    kwargs = {"positions_m": np.zeros((3, 2)), "ids": np.arange(3), **bad}
    with RerunLogger(tmp_path / "bad.rrd", toy_scene) as log, pytest.raises(ValueError, match="log_step"):
        log.log_step(0, kwargs.pop("positions_m"), kwargs.pop("ids"), **kwargs)


def test_missing_rerun_gives_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)  # makes `import rerun` fail
    monkeypatch.delitem(sys.modules, "st_sim.rerun_log")
    with pytest.raises(ImportError, match="pip install rerun-sdk"):
        importlib.import_module("st_sim.rerun_log")


QUIET_WRITER = """
import os, sys
import numpy as np
from st_sim.rerun_log import RerunLogger
assert "RUST_LOG" not in os.environ, "the log filter leaked into the environment"
with RerunLogger(sys.argv[1], None) as log:
    log.log_step(0, np.zeros((1, 2)), [0])
"""


def test_recording_prints_no_footer_warning_and_leaves_the_environment_alone(tmp_path) -> None:
    env = {key: value for key, value in os.environ.items() if key != "RUST_LOG"}
    proc = subprocess.run([sys.executable, "-c", QUIET_WRITER, str(tmp_path / "quiet.rrd")], env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "write_footer" not in proc.stderr, proc.stderr[-2000:]
    assert (tmp_path / "quiet.rrd").stat().st_size > 0
