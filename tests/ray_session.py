"""Ray as the tests start it: a small object store, and workers that see the data root and given modules."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

OBJECT_STORE_BYTES = 100 * 1024**2
"""each Ray node's object store [bytes]: Ray's default maps 30 % of the machine's memory, which a limit on a process's
address space (``ulimit -v``) refuses, and the driver then aborts the whole pytest process"""


def connect_kwargs(modules: Path) -> dict[str, Any]:
    """``ray.init``'s arguments besides where to start or connect: no dashboard, no worker logs, and workers that see
    ``STCROWD_DATA`` and import from ``modules`` first."""
    paths = os.pathsep.join([str(modules), os.environ.get("PYTHONPATH", "")])
    return {"include_dashboard": False, "log_to_driver": False, "runtime_env": {"env_vars": {
        "STCROWD_DATA": str(Path(os.environ["STCROWD_DATA"]).resolve()), "PYTHONPATH": paths}}}
