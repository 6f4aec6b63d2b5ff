"""Job functions for the grid tests (imported by the spawned workers; tests/ is on their sys.path)."""

from __future__ import annotations

import os
import signal
from pathlib import Path


def write(output: str, text: str) -> None:
    Path(output).write_text(text)


def fail(output: str) -> None:
    raise ValueError(f"cannot make {output}")


def die_once(output: str) -> None:
    """Kill this worker process the first time (as the kernel's OOM killer would); succeed the second time."""
    marker = Path(output + ".died")
    if not marker.exists():
        marker.write_text("x")
        os.kill(os.getpid(), signal.SIGKILL)
    Path(output).write_text("survived")


def die(output: str) -> None:
    """Kill this worker process every time (a job that always runs out of memory)."""
    os.kill(os.getpid(), signal.SIGKILL)
