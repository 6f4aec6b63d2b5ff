"""The checkpoints shipped inside the package load by name, stay small and predict sensibly."""

from __future__ import annotations

import numpy as np
import pytest

import predictor
from predictor.checkpoint import CheckpointError, pretrained_manifest
from replays import load_scene, load_windows
from st_sim.metrics import ade_fde

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")
TASKS = ("stochastic", "deterministic", "momentary")
NAMES = [f"{task}/{s}" for task in TASKS for s in SCENES] + ["universal", "momentary/universal"]


def test_manifest_lists_every_shipped_checkpoint_with_its_numbers():
    entries = pretrained_manifest()["checkpoints"]
    assert sorted(entries) == sorted(NAMES)
    for name, entry in entries.items():
        assert entry["size_bytes"] <= 4_000_000, name
        assert entry["command"].startswith("python -m predictor train"), name
        assert all(len(digest) == 64 for digest in entry["data_checksums"].values()), name


def test_a_scenes_leave_one_out_models_never_saw_its_test_recordings():
    """docs/environments.md: a replay gets its scene's leave-one-out model, trained and selected without that scene's
    test recordings (by content, and under no name of theirs: ``biwi_eth.txt`` rules out ``biwi_eth_train.txt``)."""
    from pathlib import Path

    from replays.data_root import expected_sums

    sums = expected_sums()
    for name, entry in pretrained_manifest()["checkpoints"].items():
        scene = name.rpartition("/")[2]
        if scene not in SCENES:
            continue  # the universal models saw every scene's train and val portions
        seen = entry["data_checksums"]
        assert seen and all(path.startswith(f"{scene}/") for path in seen), f"{name}: not its scene's folder"
        for test_file in (path for path in sums if path.startswith(f"{scene}/test/")):
            stem = Path(test_file).stem
            assert sums[test_file] not in seen.values(), f"{name} was trained on {test_file}"
            assert not [p for p in seen if Path(p).stem in (stem, f"{stem}_train", f"{stem}_val")], name


@pytest.mark.parametrize("name", NAMES, ids=NAMES)
def test_pretrained_loads_by_name_and_beats_its_manifest_bound(name):
    model = predictor.load_pretrained(name)
    task = {"universal": "stochastic", "momentary/universal": "momentary"}.get(name, name.split("/")[0])
    scene = "zara1" if name.endswith("universal") else name.split("/")[1]
    test = load_windows(task, scene, "test")
    keep = test.group < 40  # a slice of whole windows keeps the test fast
    samples = 1 if task == "deterministic" else 20
    pred = model.predict(test.obs[keep], test.group[keep], load_scene(scene), samples)
    assert pred.shape == (keep.sum(), samples, 12, 2)
    ade, fde = ade_fde(pred, test.fut[keep])
    bound_ade, bound_fde = (1.0, 2.5) if samples == 1 else (0.6, 1.2)  # metres, far above the manifest's numbers
    assert ade.mean() < bound_ade and fde.mean() < bound_fde, (ade.mean(), fde.mean())


def test_manifest_numbers_are_reproduced_on_zara1():
    entry = pretrained_manifest()["checkpoints"]["stochastic/zara1"]
    test = load_windows("stochastic", "zara1", "test")
    pred = predictor.load_pretrained("stochastic/zara1").predict(test.obs, test.group, load_scene("zara1"), 20)
    ade, fde = ade_fde(pred, test.fut)
    assert ade.mean() == pytest.approx(entry["test"]["zara1"]["ade"], abs=1e-4)
    assert fde.mean() == pytest.approx(entry["test"]["zara1"]["fde"], abs=1e-4)


def test_universal_predicts_without_a_map_and_for_fewer_samples():
    model = predictor.load_pretrained("universal")
    obs = np.cumsum(np.full((3, 8, 2), 0.5, np.float32), axis=1)
    pred = model.predict(obs, np.zeros(3), None, 5)
    assert pred.shape == (3, 5, 12, 2) and np.isfinite(pred).all()
    assert (pred[:, :, -1] - obs[:, None, -1]).mean(axis=(0, 1)) @ np.array([1.0, 1.0]) > 0  # keeps walking on


def test_unknown_pretrained_name_lists_the_available_ones():
    with pytest.raises(CheckpointError, match="stochastic/eth"):
        predictor.load_pretrained("stochastic/mars")
