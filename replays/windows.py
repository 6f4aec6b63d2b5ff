"""Benchmark windows, cut exactly as the Social-GAN loader behind every published ETH/UCY table.

Per file: the sorted unique frame ids are the time axis (gaps ignored); a window is ``obs_len + 12``
consecutive listed frames, stride 1; a sample is an agent present in every frame of the window; a
window is kept when it holds at least two samples. Samples are ordered by window, then agent id.
Positions are rounded to 4 decimals first, as that loader does.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from replays.atomic import atomic_path
from replays.constants import COORD_DECIMALS, DOMAIN_TASKS, FEWSHOT_EVERY, MIN_AGENTS_PER_WINDOW, SPLITS, T_PRED, TASKS
from replays.data_root import cache_dir, data_root
from replays.errors import DataRootError
from replays.files import require_budget
from replays.recording import DENSE_BYTES_PER_CELL, Recording, read_recording
from replays.scenes import SCENES, scene_info

ALL_SCENES = "all"  # pseudo-scene: all five scenes at once (universal model)
CACHE_VERSION = 1  # bump when the windowing changes, to invalidate disk caches
GRID_BYTES_PER_CELL = DENSE_BYTES_PER_CELL + 5  # + int32 presence counts + bool "full", per (frame, agent)
SAMPLE_BYTES_PER_STEP = 32  # int64 frame index + float64 (x, y) + float32 (x, y), per sample step


@dataclass(frozen=True, eq=False)
class Windows:
    """Samples of one (task, scene, split); N samples, T_obs observed and 12 future steps of 0.4 s.

    Attributes:
        obs: (N, T_obs, 2) float32 metres, world frame.
        fut: (N, 12, 2) float32 metres, world frame.
        group: (N,) int64, equal for samples of the same window (agents sharing a scene moment).
        recording: (N,) str file stem each sample comes from.
        frame: (N,) int64 first frame id of the window.
        agent: (N,) int64 agent id in its recording.
    """

    obs: np.ndarray
    fut: np.ndarray
    group: np.ndarray
    recording: np.ndarray
    frame: np.ndarray
    agent: np.ndarray
    task: str = ""
    scene: str = ""
    split: str = ""

    def __len__(self) -> int:
        return len(self.obs)

    def __repr__(self) -> str:
        return f"Windows({self.task}/{self.scene}/{self.split}: {len(self)} samples, {self.num_groups} windows)"

    @property
    def num_groups(self) -> int:
        return int(self.group.max()) + 1 if len(self.group) else 0

    def subset(self, mask: np.ndarray) -> Windows:
        """Samples where ``mask`` (N,) is true; groups renumbered 0..G-1 in order."""
        arrays = {f.name: getattr(self, f.name)[mask] for f in fields(self) if f.name in _ARRAYS}
        arrays["group"] = np.unique(arrays["group"], return_inverse=True)[1].astype(np.int64)
        return Windows(**arrays, task=self.task, scene=self.scene, split=self.split)

    def last_observed(self, steps: int) -> Windows:
        """Same samples with only the last ``steps`` observed frames (e.g. 2 for momentary scoring)."""
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        arrays["obs"] = self.obs[:, -steps:]
        return Windows(**arrays, task=self.task, scene=self.scene, split=self.split)


_ARRAYS = ("obs", "fut", "group", "recording", "frame", "agent")
_CACHED = ("obs", "fut", "group", "frame", "agent")  # per-file arrays; the recording name is the file stem


def cut_windows(recording: Recording, obs_len: int) -> dict[str, np.ndarray]:
    """Cut one recording into windows (see module docstring); groups numbered from 0 in this file.

    Returns:
        obs (S, obs_len, 2), fut (S, 12, 2) float32 metres; group, frame, agent (S,) int64.

    Raises:
        MemoryBudgetError: the (frame x agent) grid or the samples would pass ``MEMORY_BUDGET_BYTES``.
    """
    seq_len = obs_len + T_PRED
    recording.grid_budget(GRID_BYTES_PER_CELL, "windowing grid")
    xy, present = recording.dense(COORD_DECIMALS)
    n_frames = len(recording.frames)
    n_windows = n_frames - seq_len + 1
    if n_windows <= 0:
        return _empty(obs_len)
    counts = np.cumsum(np.vstack([np.zeros((1, present.shape[1]), np.int32), present]), axis=0, dtype=np.int32)
    full = (counts[seq_len:] - counts[:n_windows]) == seq_len  # (n_windows, A)
    full &= (full.sum(axis=1) >= MIN_AGENTS_PER_WINDOW)[:, None]
    w_idx, a_idx = np.nonzero(full)  # row-major: by window, then agent id
    require_budget(len(w_idx) * seq_len * SAMPLE_BYTES_PER_STEP,
                   f"{recording.path or recording.name}: {len(w_idx)} samples of {seq_len} steps")
    paths = xy[w_idx[:, None] + np.arange(seq_len), a_idx[:, None]].astype(np.float32)
    return {
        "obs": paths[:, :obs_len],
        "fut": paths[:, obs_len:],
        "group": np.unique(w_idx, return_inverse=True)[1].astype(np.int64),
        "frame": recording.frames[w_idx].astype(np.int64),
        "agent": recording.agents[a_idx].astype(np.int64),
    }


def _empty(obs_len: int) -> dict[str, np.ndarray]:
    return {
        "obs": np.zeros((0, obs_len, 2), np.float32), "fut": np.zeros((0, T_PRED, 2), np.float32),
        "group": np.zeros(0, np.int64),
        "frame": np.zeros(0, np.int64), "agent": np.zeros(0, np.int64),
    }


_MEMORY: dict[tuple, dict[str, np.ndarray]] = {}


def file_windows(path: Path, obs_len: int) -> dict[str, np.ndarray]:
    """``cut_windows`` of one file, cached in memory and on disk (keyed by path, size, mtime, ctime, obs_len)."""
    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns, obs_len, CACHE_VERSION)
    if key in _MEMORY:
        return _MEMORY[key]
    digest = hashlib.sha1(repr(key).encode()).hexdigest()[:20]
    cached = cache_dir() / f"{path.stem}-{obs_len}-{digest}.npz"
    try:
        with np.load(cached) as data:
            result = {name: data[name] for name in _CACHED}
    except (OSError, ValueError, KeyError):
        result = cut_windows(read_recording(path), obs_len)
        _save_npz(cached, result)
    _MEMORY[key] = result
    return result


def _save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    try:
        with atomic_path(path) as tmp:
            np.savez(tmp, **arrays)
    except OSError:
        pass  # a read-only cache only costs speed


def split_files(task: str, scene: str, split: str, root: Path) -> list[Path]:
    """Recording files making up one split, in loading order (sorted by name).

    ``scene="all"`` (training a universal model): every recording's train/val portion, or every test set.
    Domain pair X2Y: train = X's ``raw/train`` portions; val = Y's ``raw/val`` portions (the paper's T-GNN
    layout) or, for ``domain_strict``, X's own; test = Y's test set.
    """
    if scene == ALL_SCENES:
        if split == "test":
            return sorted(f for name in SCENES for f in (root / name / "test").glob("*.txt"))
        return sorted((root / "raw" / split).glob(f"*_{split}.txt"))
    if task in DOMAIN_TASKS:
        source, target = _domain_pair(scene)
        if split == "test":
            folder = root / target.name / "test"
            return sorted(folder.glob("*.txt"))
        # paper (T-GNN) layout: validation on the target's val portion; "domain_strict": on the source's
        portion_of = target if split == "val" and task == "domain" else source
        return [root / "raw" / split / f"{rec}_{split}.txt" for rec in sorted(portion_of.train_recordings)]
    return sorted((root / scene_info(scene).name / split).glob("*.txt"))


def _domain_pair(pair: str):
    try:
        src, tgt = pair.upper().split("2")
        source, target = scene_info(src), scene_info(tgt)
    except (ValueError, KeyError) as err:
        raise ValueError(f"domain scene must be a pair like 'A2B' (letters A-E), got {pair!r}") from err
    if source.name == target.name:
        raise ValueError(f"domain pair {pair!r}: source and target must differ")
    return source, target


def load_windows(task: str, scene: str, split: str, root: str | os.PathLike | None = None) -> Windows:
    """Benchmark samples of one task, scene and split.

    Args:
        task: stochastic | deterministic | momentary | fewshot | domain | domain_strict.
        scene: eth | hotel | univ | zara1 | zara2 (or letter); for ``domain`` and ``domain_strict`` a pair
            like ``"A2B"``;
            ``"all"`` for every scene at once.
        split: train | val | test.
        root: data root (default: ``$STCROWD_DATA`` or the user cache).

    Returns:
        ``Windows`` with obs (N, T_obs, 2) and fut (N, 12, 2) float32 metres, T_obs = 2 for momentary.
    """
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}")
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; expected one of {', '.join(SPLITS)}")
    if task not in DOMAIN_TASKS and scene != ALL_SCENES:
        scene_info(scene)  # raises on an unknown scene
    root_path = data_root(root)
    obs_len = TASKS[task]["obs_len"]
    files = split_files(task, scene, split, root_path)
    if not files:
        raise DataRootError(f"{root_path}: no recordings for {task}/{scene}/{split}")
    parts = [file_windows(path, obs_len) for path in files]
    offsets = np.cumsum([0] + [p["group"].max() + 1 if len(p["group"]) else 0 for p in parts])
    merged = {name: np.concatenate([p[name] for p in parts]) for name in _CACHED}
    merged["recording"] = np.concatenate([np.full(len(p["group"]), path.stem, dtype=object)
                                          for p, path in zip(parts, files, strict=True)])
    merged["group"] = np.concatenate([p["group"] + off for p, off in zip(parts, offsets, strict=False)])
    name = scene.upper() if task in DOMAIN_TASKS else scene if scene == ALL_SCENES else scene_info(scene).name
    windows = Windows(**merged, task=task, scene=name, split=split)
    if task == "fewshot" and split == "train":
        windows = windows.subset(windows.group % FEWSHOT_EVERY == 0)
    return windows
