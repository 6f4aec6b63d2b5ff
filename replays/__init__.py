"""ETH/UCY (and simulated) recordings: data root and fetch, strict parsing, scenes, benchmark windows.

Quick start::

    from replays import load_windows
    w = load_windows(task="stochastic", scene="eth", split="test")
    w.obs.shape, w.fut.shape        # (181, 8, 2), (181, 12, 2) metres
"""

from replays.constants import STEP_S, T_OBS, T_OBS_MOMENTARY, T_PRED, TASKS
from replays.data_root import data_root, verify_data_root
from replays.errors import (
    DataFormatError,
    DataRootError,
    MemoryBudgetError,
    NotRegularFileError,
    RecordingError,
    UnknownNameError,
)
from replays.fetch import FetchError
from replays.recording import Recording, read_recording, write_recording
from replays.scenes import SCENE_NAMES, SCENES, Scene, load_scene, scene_info, scene_of_recording
from replays.windows import Windows, load_windows

__all__ = [
    "SCENES", "SCENE_NAMES", "STEP_S", "TASKS", "T_OBS", "T_OBS_MOMENTARY", "T_PRED",
    "DataFormatError", "DataRootError", "FetchError", "MemoryBudgetError", "NotRegularFileError", "Recording",
    "RecordingError", "Scene", "UnknownNameError", "Windows",
    "data_root", "load_scene", "load_windows", "read_recording", "scene_info", "scene_of_recording",
    "verify_data_root", "write_recording",
]
