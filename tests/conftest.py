"""Shared fixtures. The ETH/UCY data root comes from $STCROWD_DATA (set by .ci/run); a missing root fails."""

from __future__ import annotations

import numpy as np
import pytest

from replays.scenes import Scene


@pytest.fixture(autouse=True)
def _private_window_cache(tmp_path_factory, monkeypatch):
    """Keep the windows disk cache out of the user's home during tests (one cache per session)."""
    monkeypatch.setenv("STCROWD_CACHE", str(tmp_path_factory.getbasetemp() / "windows-cache"))


@pytest.fixture
def toy_scene() -> Scene:
    """A 10 m x 10 m map at 0.1 m per pixel; the right half (x >= 5 m) is a wall."""
    walkable = np.ones((100, 100), bool)
    walkable[:, 50:] = False
    H = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 1.0]])  # world = 0.1 * pixel
    return Scene("toy", H, walkable)
