from __future__ import annotations

import numpy as np
import pytest

from replays import SCENES, DataFormatError, data_root, load_scene, read_recording, scene_of_recording
from replays.scenes import read_homography

RECORDINGS = [r for info in SCENES.values() for r in info.train_recordings]


@pytest.mark.parametrize("recording", RECORDINGS, ids=RECORDINGS)
def test_annotated_positions_land_on_walkable_pixels(recording):
    rec = read_recording(data_root() / "raw" / "all_data" / f"{recording}.txt")
    scene = load_scene(scene_of_recording(recording).name)
    share = scene.is_walkable(rec.xy_m).mean()
    assert share > (0.88 if recording == "uni_examples" else 0.96), f"{recording}: {share:.3f}"


@pytest.mark.parametrize("name", list(SCENES), ids=list(SCENES))
def test_world_pixel_round_trip(name):
    scene = load_scene(name)
    xy = np.random.default_rng(0).uniform(0, 10, size=(50, 2))
    np.testing.assert_allclose(scene.pixel_to_world(scene.world_to_pixel(xy)), xy, atol=1e-8)
    assert scene.photo.shape[:2] == scene.walkable.shape


def test_scene_lookup_by_letter_and_errors():
    assert load_scene("D").name == "zara1"
    with pytest.raises(KeyError, match="unknown scene"):
        load_scene("mars")


def test_bad_homography_names_file(tmp_path):
    path = tmp_path / "bad_H.txt"
    path.write_text("1 0\n0 1\n")
    with pytest.raises(DataFormatError, match=r"bad_H\.txt"):
        read_homography(path)


def test_points_off_image_are_not_walkable(toy_scene):
    assert toy_scene.is_walkable(np.array([[1.0, 1.0], [7.0, 1.0], [-3.0, 1.0], [1.0, 50.0]])).tolist() == [
        True, False, False, False]
