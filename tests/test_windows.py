from __future__ import annotations

import numpy as np
import pytest

from replays import data_root, load_windows, read_recording
from replays.windows import cut_windows

SCENES = ["eth", "hotel", "univ", "zara1", "zara2"]
TEST_COUNTS = {  # Social-GAN loader, min_ped = 1 (windows with one agent dropped)
    8: {"eth": 181, "hotel": 1053, "univ": 24334, "zara1": 2253, "zara2": 5833},
    2: {"eth": 1069, "hotel": 2137, "univ": 28926, "zara1": 3183, "zara2": 7028},
}


@pytest.mark.parametrize("scene", SCENES, ids=SCENES)
def test_test_split_counts_match_social_gan_loader(scene):
    assert len(load_windows("stochastic", scene, "test")) == TEST_COUNTS[8][scene]
    assert len(load_windows("deterministic", scene, "test")) == TEST_COUNTS[8][scene]
    assert len(load_windows("momentary", scene, "test")) == TEST_COUNTS[2][scene]


def reference_loader(path, obs_len, pred_len=12):
    """A plain re-statement of the Social-GAN loop (per window, per agent), for cross-checking."""
    data = np.loadtxt(path)
    frames = np.unique(data[:, 0]).tolist()
    frame_rows = [data[data[:, 0] == f] for f in frames]
    seq_len = obs_len + pred_len
    samples = []
    for idx in range(0, len(frames) - seq_len + 1):
        window = np.concatenate(frame_rows[idx:idx + seq_len])
        kept = []
        for ped in np.unique(window[:, 1]):
            rows = np.around(window[window[:, 1] == ped], 4)
            first, last = frames.index(rows[0, 0]) - idx, frames.index(rows[-1, 0]) - idx + 1
            if last - first == seq_len:
                kept.append((frames[idx], ped, rows[:, 2:4]))
        if len(kept) > 1:
            samples.extend(kept)
    return samples


@pytest.mark.parametrize("obs_len", [8, 2])
def test_windows_equal_reference_loader_sample_by_sample(obs_len):
    path = data_root() / "eth" / "test" / "biwi_eth.txt"
    expected = reference_loader(path, obs_len)
    got = cut_windows(read_recording(path), obs_len)
    assert len(got["obs"]) == len(expected)
    for i, (frame, ped, xy) in enumerate(expected):
        assert got["frame"][i] == frame and got["agent"][i] == ped, f"[sample {i}] order differs"
        np.testing.assert_allclose(np.concatenate([got["obs"][i], got["fut"][i]]), xy, atol=1e-5,
                                   err_msg=f"[sample {i}]")


def test_cut_windows_handles_gaps_absences_and_lone_agents(tmp_path):
    rows = []
    for f in range(22):  # agent 1 present in all 22 listed frames; a frame-id gap after frame 5
        frame_id = f * 10 + (100 if f > 5 else 0)
        rows.append((frame_id, 1, f * 1.0, 0.0))
        if f != 3:
            rows.append((frame_id, 2, f * 1.0, 1.0))  # agent 2 absent at listed frame 3
        if f >= 2:
            rows.append((frame_id, 3, 0.0, f * 1.0))
    path = tmp_path / "toy.txt"
    path.write_text("".join(f"{a}\t{b}\t{c}\t{d}\n" for a, b, c, d in sorted(rows)))
    w = cut_windows(read_recording(path), obs_len=8)
    # windows start at listed frames 0..2; agent 3 is complete only from start 2, agent 2 only from start 4
    # -> window 0: only agent 1 (dropped), window 1: only agent 1 (dropped), window 2: agents 1 and 3.
    assert w["frame"].tolist() == [20, 20]
    assert w["agent"].tolist() == [1, 3]
    assert w["group"].tolist() == [0, 0]
    np.testing.assert_allclose(w["obs"][0, :, 0], np.arange(2, 10))  # gap ignored: consecutive listed frames


def test_fewshot_keeps_every_tenth_training_window():
    full = load_windows("stochastic", "zara1", "train")
    few = load_windows("fewshot", "zara1", "train")
    kept_frames = {(r, f) for r, f, g in zip(full.recording, full.frame, full.group, strict=False) if g % 10 == 0}
    assert {(r, f) for r, f in zip(few.recording, few.frame, strict=False)} == kept_frames
    assert few.num_groups == (full.num_groups + 9) // 10
    assert len(load_windows("fewshot", "zara1", "test")) == 2253


def test_domain_pair_trains_on_the_source_validates_on_the_target_and_tests_on_the_target():
    train = load_windows("domain", "A2B", "train")
    assert set(train.recording) == {"biwi_eth_train"}
    assert set(load_windows("domain", "A2B", "val").recording) == {"biwi_hotel_val"}  # the paper's T-GNN layout
    assert set(load_windows("domain", "B2E", "val").recording) == {"crowds_zara02_val", "crowds_zara03_val"}
    test = load_windows("domain", "A2B", "test")
    assert len(test) == 1053 and set(test.recording) == {"biwi_hotel"}


def test_strict_domain_pair_validates_on_the_source():
    assert set(load_windows("domain_strict", "A2B", "train").recording) == {"biwi_eth_train"}
    assert set(load_windows("domain_strict", "A2B", "val").recording) == {"biwi_eth_val"}
    assert set(load_windows("domain_strict", "E2A", "val").recording) == {"crowds_zara02_val", "crowds_zara03_val"}
    assert len(load_windows("domain_strict", "A2B", "test")) == 1053


def test_groups_are_windows_and_ordered():
    w = load_windows("stochastic", "univ", "test")
    assert np.all(np.diff(w.group) >= 0)
    same = w.group[1:] == w.group[:-1]
    assert np.all(w.frame[1:][same] == w.frame[:-1][same])
    assert np.all(w.agent[1:][same] > w.agent[:-1][same])  # by agent id within a window
    assert np.bincount(w.group).min() >= 2


def test_last_observed_keeps_samples_and_truncates_history():
    w = load_windows("stochastic", "hotel", "test")
    m = w.last_observed(2)
    assert m.obs.shape == (len(w), 2, 2)
    np.testing.assert_array_equal(m.obs, w.obs[:, -2:])
    np.testing.assert_array_equal(m.fut, w.fut)


@pytest.mark.parametrize("kwargs, message", [
    ({"task": "nope", "scene": "eth", "split": "test"}, "unknown task"),
    ({"task": "stochastic", "scene": "eth", "split": "dev"}, "unknown split"),
    ({"task": "stochastic", "scene": "mars", "split": "test"}, "unknown scene"),
    ({"task": "domain", "scene": "A2A", "split": "test"}, "differ"),
    ({"task": "domain", "scene": "eth", "split": "test"}, "pair"),
])
def test_load_windows_rejects_bad_arguments(kwargs, message):
    with pytest.raises((ValueError, KeyError), match=message):
        load_windows(**kwargs)


def test_the_cache_holds_derived_files_only(tmp_path, monkeypatch):
    """docs/data.md, "Derived files": the cache can be deleted at any time and is rebuilt on demand, a damaged entry
    is cut again, and an unwritable cache only costs speed (the windows and the data root's check are the same)."""
    from replays import windows
    from replays.data_root import modified_files

    root = data_root()
    path = root / "eth" / "test" / "biwi_eth.txt"
    expected = cut_windows(read_recording(path), 8)

    def cut_through(cache):
        monkeypatch.setenv("STCROWD_CACHE", str(cache))
        monkeypatch.setattr(windows, "_MEMORY", {})  # this process's copy: read the disk cache again
        got = windows.file_windows(path, 8)
        for name, value in expected.items():
            np.testing.assert_array_equal(got[name], value, err_msg=f"{cache}: {name}")

    cache = tmp_path / "cache"
    cut_through(cache)
    (entry,) = cache.glob("biwi_eth-8-*.npz")
    entry.write_bytes(b"not an npz")  # damaged: cut again and written anew
    cut_through(cache)
    assert entry.read_bytes()[:2] == b"PK", "the damaged entry was not replaced"
    for file in cache.iterdir():
        file.unlink()
    cache.rmdir()  # deleted: rebuilt on demand
    cut_through(cache)
    assert list(cache.glob("biwi_eth-8-*.npz"))
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    cut_through(blocker / "cache")  # cannot be written
    assert modified_files(root) == {}, "the data root's check works without a writable cache"
