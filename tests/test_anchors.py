from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from predictor.anchors import adapt_paths, nearest_walkable_field, prototype_anchors


def straight_paths(start_xy, velocity_xy, n_steps=12):
    steps = np.arange(1, n_steps + 1)[:, None]
    return np.asarray(start_xy) + steps * np.asarray(velocity_xy)


def test_nearest_walkable_field_points_to_walkable_pixels(toy_scene):
    rows, cols = nearest_walkable_field(toy_scene)  # over the padded canvas: image pixel (r, c) at (r + 50, c + 50)
    assert rows.shape == (200, 200)
    assert toy_scene.walkable[rows, cols].all()
    assert cols[10 + 50, 80 + 50] == 49 and rows[10 + 50, 80 + 50] == 10  # right half is wall: nearest column 49
    assert cols[0, 0] == 0 and rows[0, 0] == 0  # the canvas corner (off the image) points at the image corner


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


@pytest.mark.parametrize("bend", ["ramp", "scale"])
def test_end_points_beyond_the_image_are_pulled_to_a_walkable_pixel_inside_it(toy_scene, bend):
    leaving = straight_paths([1.0, 5.0], [-0.5, 0.0])  # ends at x = -5 m, left of the image (x < 0)
    far = straight_paths([1.0, 5.0], [-30.0, 4.0])  # ends beyond the padded canvas too
    paths = np.stack([leaving, far])[:, None]  # (N=2, S=1, 12, 2)
    origin = np.array([[1.5, 5.0], [31.0, 1.0]])
    adapted, moved = adapt_paths(paths, toy_scene, origin, bend=bend)
    assert moved.all()
    assert toy_scene.is_walkable(adapted[:, 0, -1]).all()
    assert adapted[0, 0, -1, 0] == pytest.approx(0.0, abs=0.06)  # the first image column, same row
    assert adapted[0, 0, -1, 1] == pytest.approx(5.0, abs=0.06)
    kept, kept_moved = adapt_paths(paths, toy_scene, origin, off_image="keep", bend=bend)
    assert not kept_moved.any()
    np.testing.assert_array_equal(kept, paths)


def test_scale_bend_stretches_the_path_about_the_last_observed_point(toy_scene):
    into_wall = straight_paths([3.0, 2.0], [0.4, 0.1])  # ends at (7.8, 3.2) m, in the wall
    origin = np.array([[2.6, 1.9]])
    adapted, moved = adapt_paths(into_wall[None, None], toy_scene, origin, bend="scale")
    assert moved.all()
    end = adapted[0, 0, -1]
    assert toy_scene.is_walkable(end) and end[0] == pytest.approx(4.9, abs=0.06)
    ratio = (end - origin[0]) / (into_wall[-1] - origin[0])  # per axis
    np.testing.assert_allclose(adapted[0, 0], origin[0] + (into_wall - origin[0]) * ratio, atol=1e-9)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.tuples(st.floats(-40, 40), st.floats(-40, 40), st.floats(-3, 3), st.floats(-3, 3)),
                min_size=1, max_size=8), st.sampled_from(["ramp", "scale"]))
def test_pulled_paths_end_walkable_and_walkable_ends_are_untouched(toy_scene, agents, bend):
    start, velocity = np.array(agents)[:, :2], np.array(agents)[:, 2:]
    paths = np.stack([straight_paths(s, v) for s, v in zip(start, velocity, strict=True)])[:, None]
    adapted, moved = adapt_paths(paths, toy_scene, start - velocity, bend=bend)
    np.testing.assert_array_equal(moved[:, 0], ~toy_scene.is_walkable(paths[:, 0, -1]))
    assert toy_scene.is_walkable(adapted[:, 0, -1]).all()
    np.testing.assert_array_equal(adapted[~moved], paths[~moved])
    assert np.isfinite(adapted).all()


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


def test_onto_walkable_moves_only_points_deeper_than_the_tolerance(toy_scene) -> None:
    """The toy scene's right half (x >= 5 m) is a wall: a point 1 m inside moves to the last walkable pixel, one
    7 cm from it stays with a 0.1 m tolerance, and points on walkable ground never move."""
    from predictor.anchors import onto_walkable

    points = np.array([[[2.0, 5.0], [6.0, 5.0], [4.97, 5.0], [25.0, 5.0]]])  # (1, 4, 2) metres; pixel 50 is wall
    moved_points, moved = onto_walkable(points, toy_scene, tolerance_m=0.1)
    assert moved.tolist() == [[False, True, False, True]]
    assert np.allclose(moved_points[0, [0, 2]], points[0, [0, 2]])
    assert toy_scene.is_walkable(moved_points[0, [1, 3]]).all()
    assert np.all(moved_points[0, [1, 3], 0] < 5.0) and np.all(moved_points[0, [1, 3], 0] > 4.8)
    strict, moved_strict = onto_walkable(points, toy_scene)
    assert moved_strict.tolist() == [[False, True, True, True]] and toy_scene.is_walkable(strict[0]).all()
