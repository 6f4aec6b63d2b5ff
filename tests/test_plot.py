from __future__ import annotations

import cv2
import numpy as np
import pytest

from predictor.baselines import ConstantVelocitySampler
from replays import load_scene, load_windows
from st_sim.plot import GT_RGB, agent_colors, plot_prediction


def read_rgb(path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert image is not None, f"{path} is not a readable image"
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def toy_paths(n: int = 2, s: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Agents walking along +y in the walkable left half of the toy scene: history, futures, ground truth."""
    x = np.linspace(1.0, 4.0, n)[:, None]
    history = np.stack([np.broadcast_to(x, (n, 8)), np.linspace(1.0, 3.0, 8)[None].repeat(n, 0)], -1)
    gt = np.stack([np.broadcast_to(x, (n, 12)), np.linspace(3.3, 6.6, 12)[None].repeat(n, 0)], -1)
    spread = np.linspace(-0.3, 0.3, s)[None, :, None, None] * np.linspace(0, 1, 12)[None, None, :, None]
    futures = gt[:, None] + spread * np.array([1.0, 0.0])
    return history, futures, gt


def test_plot_draws_paths_over_the_photo(tmp_path, toy_scene):
    history, futures, gt = toy_paths()
    path = plot_prediction(toy_scene, history, futures, tmp_path / "toy.png", gt_m=gt,
                           prototype_anchors_m=futures + 0.5, adapted_anchors_m=futures + 0.2, title="toy")
    image = read_rgb(path)
    scale = image.shape[0] // toy_scene.walkable.shape[0]
    assert scale > 1 and image.shape[:2] == (100 * scale, 100 * scale), "small photos are upscaled"

    def pixel(xy_m):
        u, v = np.rint((toy_scene.world_to_pixel(np.asarray(xy_m)) + 0.5) * scale - 0.5).astype(int)
        return image[v, u].astype(int)

    background = (255, 255, 255)  # the toy photo is white where walkable
    assert np.abs(pixel(history[1, -2]) - background).sum() > 100, "history not drawn"
    np.testing.assert_allclose(pixel(gt[1, 8]), GT_RGB, atol=40, err_msg="ground truth is drawn in green")
    assert tuple(pixel([2.5, 8.0])) == background, "an empty walkable spot stays untouched"
    assert pixel([8.0, 8.0])[0] > pixel([8.0, 8.0])[1] + 30, "non-walkable pixels are tinted red"


def test_plot_of_real_windows_differs_from_photo_only_near_paths(tmp_path):
    scene = load_scene("zara1")
    windows = load_windows("stochastic", "zara1", "test")
    first = windows.group == 0
    obs, fut = windows.obs[first], windows.fut[first]
    futures = ConstantVelocitySampler().predict(obs, windows.group[first], scene, 20)
    path = plot_prediction(scene, obs, futures, tmp_path / "zara1.png", gt_m=fut)
    image = read_rgb(path)
    scale = image.shape[0] // scene.photo.shape[0]
    photo = cv2.resize(scene.photo, None, fx=scale, fy=scale, interpolation=cv2.INTER_CUBIC).astype(int)
    walkable = cv2.resize(scene.walkable.astype(np.uint8), None, fx=scale, fy=scale,
                          interpolation=cv2.INTER_NEAREST).astype(bool)
    changed = np.abs(image.astype(int) - photo).sum(-1) > 30
    u, v = np.rint((scene.world_to_pixel(obs[:, -1]) + 0.5) * scale - 0.5).astype(int).T
    assert changed[v, u].all(), "every agent's last position is marked"
    assert changed[~walkable].mean() > 0.9, "the non-walkable area is tinted"
    assert changed[walkable].mean() < 0.2, "most walkable pixels show the bare photo"


def test_plot_replaces_the_file_atomically(tmp_path, toy_scene):
    history, futures, _ = toy_paths()
    target = tmp_path / "figure.png"
    target.write_bytes(b"old")
    plot_prediction(toy_scene, history, futures, target)
    assert read_rgb(target).ndim == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.png"], "no temporary file left behind"


@pytest.mark.parametrize("bad, message", [
    ({"history_m": np.zeros((2, 8, 3))}, "history_m must be"),
    ({"futures_m": np.zeros((2, 12, 2))}, "futures_m must be"),
    ({"futures_m": np.zeros((3, 3, 12, 2))}, "futures_m has 3 agents"),
    ({"gt_m": np.zeros((2, 11, 2))}, "gt_m has 11 steps"),
    ({"adapted_anchors_m": np.zeros((2, 3, 12))}, "adapted_anchors_m must be"),
    ({"history_m": np.full((2, 8, 2), np.nan)}, "NaN"),
], ids=["history-xyz", "futures-3d", "futures-agents", "gt-steps", "anchors-shape", "nan-history"])
def test_plot_rejects_wrong_shapes(tmp_path, toy_scene, bad, message):
    history, futures, gt = toy_paths()
    kwargs = {"history_m": history, "futures_m": futures, "gt_m": gt, **bad}
    with pytest.raises(ValueError, match=message):
        plot_prediction(toy_scene, path=tmp_path / "bad.png", **kwargs)
    assert not (tmp_path / "bad.png").exists()


def test_agent_colors_are_stable_per_id():
    first, again = agent_colors(np.array([0, 7, 123])), agent_colors(np.array([123, 0]))
    assert first.shape == (3, 3) and first.dtype == np.uint8
    np.testing.assert_array_equal(first[[2, 0]], again)
    assert len({tuple(c) for c in agent_colors(np.arange(10))}) == 10, "neighbouring ids get distinct colours"
