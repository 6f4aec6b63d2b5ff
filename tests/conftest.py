"""Shared fixtures and the hypothesis profiles. The ETH/UCY data root comes from $STCROWD_DATA (set by .ci/run); a
missing root fails.

Hypothesis profiles, chosen by $HYPOTHESIS_PROFILE (default "ci"; see docs/contributing.md, "Property tests"):
- "ci": every run draws the same examples (``derandomize``: each test's draws are seeded by the test itself), so a
  landing never fails on a rare draw it did not cause. Hypothesis's example database is off with derandomize; the
  record of past failures is the ``@example(...)`` decorators pinned on the tests, which every profile runs first.
- "fuzz" (``make fuzz``): fresh random draws, $HYPOTHESIS_FUZZ_FACTOR (default 10) times each test's own
  ``max_examples``, only the property tests; failures are kept in the local database ``.hypothesis/`` and replayed
  first on the next fuzz run, until they are pinned as ``@example``.
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, is_hypothesis_test, settings
from hypothesis.database import DirectoryBasedExampleDatabase

from replays.scenes import Scene

# Both built on Hypothesis's defaults, not on what it loaded at import (with $CI set, a profile with no database), so
# a profile means the same on every machine; no deadline and no too-slow check: a shared CI machine's pauses are no bug
_PATIENT = {"deadline": None, "suppress_health_check": [HealthCheck.too_slow], "print_blob": True}
settings.register_profile("ci", settings.get_profile("default"), derandomize=True, database=None, **_PATIENT)
settings.register_profile("fuzz", settings.get_profile("default"), derandomize=False, **_PATIENT,
                          database=DirectoryBasedExampleDatabase(".hypothesis/examples"))
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
settings.load_profile(PROFILE)  # before the test modules are imported: their @settings inherit it
FUZZ_FACTOR = int(os.environ.get("HYPOTHESIS_FUZZ_FACTOR", "10"))  # examples per test, times its own max_examples


def pytest_report_header(config: pytest.Config) -> str:
    return f"hypothesis profile: {PROFILE} ($HYPOTHESIS_PROFILE; ci = the same draws on every run)"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Fuzz profile: keep only the property tests, each drawing ``FUZZ_FACTOR`` times its own ``max_examples``."""
    if PROFILE != "fuzz":
        return
    kept, dropped, widened = [], [], set()
    for item in items:
        test = getattr(item, "obj", None)
        if not is_hypothesis_test(test):
            dropped.append(item)
            continue
        kept.append(item)
        if id(test) not in widened:  # parametrised items share one function
            widened.add(id(test))
            own = test._hypothesis_internal_use_settings  # the settings @given reads at each call
            test._hypothesis_internal_use_settings = settings(own, max_examples=own.max_examples * FUZZ_FACTOR)
    config.hook.pytest_deselected(items=dropped)
    items[:] = kept


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


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--perturb", action="store_true",
                     help="run as on another CPU: every simulated pedestrian starts 1e-9 m off, training windows "
                          "move by one float32 ulp, torch seeds are offset by one (see _another_cpu)")


def _nudge(xy: np.ndarray, size: float) -> np.ndarray:
    """xy moved by up to ``size`` in each coordinate, a fixed function of xy (same input, same nudge), so
    runs that must agree with each other still do, while every trajectory differs from an unperturbed run."""
    phase = np.sin(np.asarray(xy, dtype=np.float64) @ np.array([12.9898, 78.233]) * 1e3)[..., None]
    return xy + size * np.concatenate([phase, np.cos(phase * 7.0)], axis=-1)


@pytest.fixture(autouse=True)
def _another_cpu(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    """With --perturb, change float rounding the way another CPU, BLAS or summation order does: a test that holds
    only for one chaotic trajectory fails here, a property that the model keeps passes. (Another torch thread count
    is not among the perturbations: a process whose OpenMP pool has two threads deadlocks in the children it forks,
    such as gymnasium's async vector envs.)"""
    if not request.config.getoption("--perturb"):
        return
    import torch

    from predictor import train
    from st_sim.sim import physics

    add_pedestrians, load_windows, manual_seed = physics.add_pedestrians, train.load_windows, torch.manual_seed

    def nudged_pedestrians(space, xy_m, vxy_mps, radius_m):
        return add_pedestrians(space, _nudge(np.asarray(xy_m, dtype=np.float64), 1e-9), vxy_mps, radius_m)

    def nudged_windows(*args, **kwargs):
        windows = load_windows(*args, **kwargs)
        up = np.float32(np.inf)
        return replace(windows, obs=np.nextafter(windows.obs, up), fut=np.nextafter(windows.fut, up))

    monkeypatch.setattr(physics, "add_pedestrians", nudged_pedestrians)
    monkeypatch.setattr(train, "load_windows", nudged_windows)
    monkeypatch.setattr(torch, "manual_seed", lambda seed: manual_seed(seed + 1))
