from __future__ import annotations

import numpy as np

from predictor.anchors import adapt_paths, nearest_walkable_field, prototype_anchors


def straight_paths(start_xy, velocity_xy, n_steps=12):
    steps = np.arange(1, n_steps + 1)[:, None]
    return np.asarray(start_xy) + steps * np.asarray(velocity_xy)


def test_nearest_walkable_field_points_to_walkable_pixels(toy_scene):
    rows, cols = nearest_walkable_field(toy_scene)
    assert toy_scene.walkable[rows, cols].all()
    assert cols[10, 80] == 49 and rows[10, 80] == 10  # right half is wall: nearest walkable column is 49


def test_paths_ending_in_walls_are_pulled_back_and_others_untouched(toy_scene):
    into_wall = straight_paths([3.0, 2.0], [0.4, 0.0])  # ends at x = 7.8 m, inside the wall (x >= 5 m)
    free = straight_paths([1.0, 1.0], [0.0, 0.3])
    paths = np.stack([np.stack([into_wall, free])])  # (N=1, S=2, 12, 2)
    adapted, moved = adapt_paths(paths, toy_scene)
    assert moved.tolist() == [[True, False]]
    assert toy_scene.is_walkable(adapted[0, 0, -1])
    np.testing.assert_allclose(adapted[0, 1], free)
    assert abs(adapted[0, 0, -1, 0] - 4.9) < 0.1  # lands on the last walkable column
    np.testing.assert_allclose(adapted[0, 0, 0], into_wall[0] + (adapted[0, 0, -1] - into_wall[-1]) / 12)


def test_adaptation_is_vectorised_over_agents_and_prototypes(toy_scene):
    rng = np.random.default_rng(0)
    paths = rng.uniform(0, 9.9, size=(50, 20, 1, 2)) + np.zeros((1, 1, 12, 1))  # all inside the image
    adapted, moved = adapt_paths(paths, toy_scene)
    assert adapted.shape == paths.shape
    assert toy_scene.is_walkable(adapted[:, :, -1])[moved].all()
    assert moved.sum() == (~toy_scene.is_walkable(paths[:, :, -1])).sum()


def test_prototype_anchors_are_seeded_and_ordered_by_cluster_size():
    rng = np.random.default_rng(0)
    data = np.concatenate([rng.normal(0, 0.1, (300, 4)), rng.normal(5, 0.1, (100, 4))])
    a, b = prototype_anchors(data, 2, seed=3), prototype_anchors(data, 2, seed=3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(a[0], 0, atol=0.05)  # the larger cluster first
    np.testing.assert_allclose(prototype_anchors(data, 1), data.mean(0, keepdims=True))
