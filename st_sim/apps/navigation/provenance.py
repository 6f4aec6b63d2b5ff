"""Where a benchmark run ran: STCrowd's commit, the versions of what decides its arithmetic, the CPU and the SIMD
kernels NumPy, torch and numba chose on it.

    record = machine_record()     # {"commit": "cab691a...", "tree_clean": true, "python": "3.11.7", ...}

A run keeps one record per machine that ran part of it (``run.json`` and ``summary.json``, ``ran_on``): it is not
part of the run's identity (the same episodes come out on every CPU; docs, "Reproducing a result"), but it tells
another lab what to match when a figure does not reproduce.
"""

from __future__ import annotations

import importlib.metadata
import platform
import subprocess
from functools import cache
from pathlib import Path
from typing import Any

PACKAGES = ("numpy", "torch", "numba", "pymunk", "gymnasium", "stable-baselines3", "stcrowd")
"""the distributions whose versions a record holds"""
REPOSITORY = Path(__file__).resolve().parents[3]


@cache
def machine_record() -> dict[str, Any]:
    """The commit of STCrowd's repository (``unknown`` outside a git checkout) and whether its tracked files are
    unchanged, Python's and ``PACKAGES``' versions, the CPU model, and the SIMD level each library dispatches to."""
    return {**_commit(), "python": platform.python_version(), "versions": {name: _version(name) for name in PACKAGES},
            "machine": platform.machine(), "cpu": _cpu_model(), "simd": _simd_levels()}


def _commit() -> dict[str, Any]:
    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(REPOSITORY), *args], capture_output=True, text=True, timeout=30,
                              check=True).stdout.strip()

    try:
        return {"commit": git("rev-parse", "HEAD"), "tree_clean": not git("status", "--porcelain",
                                                                           "--untracked-files=no")}
    except (OSError, subprocess.SubprocessError):
        return {"commit": "unknown", "tree_clean": None}


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "absent"


def _cpu_model() -> str:
    """``model name`` of /proc/cpuinfo (Linux), else what ``platform`` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _simd_levels() -> dict[str, str]:
    """NumPy's highest dispatch target in use (a feature disabled by ``NPY_DISABLE_CPU_FEATURES`` counts as absent),
    torch's CPU capability (``ATEN_CPU_CAPABILITY`` lowers it), numba's target CPU (``NUMBA_CPU_NAME``)."""
    levels = {}
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

        found = [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]
        levels["numpy"] = found[-1] if found else "baseline"
    except ImportError:
        levels["numpy"] = "unknown"
    try:
        import torch

        levels["torch"] = torch.backends.cpu.get_cpu_capability()
    except ImportError:
        levels["torch"] = "absent"
    try:
        import numba
        from llvmlite import binding

        levels["numba"] = numba.config.CPU_NAME or binding.get_host_cpu_name()
    except ImportError:
        levels["numba"] = "absent"
    return levels
