"""The reactive step compiled (numba): the same walks as the plain numpy path, to the last bit, in a fraction of the
time.

``st_sim.reactive.reactive`` steps N crowds as arrays (N, A): cheap where the arrays are large, but each pedestrian off
its log scores hundreds of candidate places, one chooser after another, on arrays of a few dozen rows, so the plain
path spends its time calling numpy, not computing. Here the same arithmetic runs in loops compiled by numba:

- ``exact``: numpy's rounding in loops (its pairwise sums, ``maximum``/``minimum``/``clip`` on ties and NaN,
  ``arange``'s values) and ``st_sim.sim.exact``'s arctangent, so that every number equals the plain path's;
- ``geometry``: the robot's body gaps and the scene's depth at a point (``footprint``, ``MapDepth.at``);
- ``tables``: a replay's route tables as one tuple, and the places along the routes (``routes.Routes``);
- ``way_round``: the way round the robot, a shortest walk on a grid (``candidates._way_round_m``, ``detour``);
- ``choose``: every chooser of every crowd, one after another, the nearest to the robot first (``choosing``,
  ``candidates``);
- ``in_the_way``: who leaves its log for the robot or for the others (``reactive._robot_in_the_way``,
  ``reactive._others_in_the_way``);
- ``step``: the rest of ``reactive.advance`` round the choice (noticing, leaving, rejoining, the counts carried on),
  which ``reactive.advance_compiled`` calls round the room each keeps and the newcomers (numpy's, in both paths).

The plain path stays the reference (``Routes(..., compiled=False)``): ``tests/test_reactive_compiled.py`` walks both
on drawn crowds and on the replays and asserts every state equal, bit for bit, and ``benchmarks/bench_reactive.py
--digest`` compares whole episodes. Both paths map points to pixels with the homography written out in one order
(``replays.scenes.apply_homography``; no BLAS product, whose rounding depended on the batch and the CPU), so they look
up the same pixel even for a point within a rounding error of a pixel's edge. Kernels compile on first use (a few
minutes of one core) and are cached on disk (``cache=True``, in this package's ``__pycache__``); a process pays a
second or two to load them.
numba re-compiles a kernel when its own file changes, not when a constant or function it took from another file does,
so ``drop_stale_caches`` deletes the cached kernels whenever any file they depend on (``SOURCES``) has changed.

The kernels pass arrays and scalars to the functions they call, never a tuple of arrays (``RouteTables``,
``choose.StepArrays`` are read once per crowd or pedestrian): numba counts references to every array of a tuple at
every call, which costs more than the arithmetic of the small functions called per candidate or grid cell.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

from replays.atomic import write_text_atomic

PACKAGE = Path(__file__).parent
ROOT = PACKAGE.parents[2]
SOURCES = (*sorted(path.relative_to(ROOT).as_posix() for path in PACKAGE.glob("*.py")),
           "st_sim/reactive/candidates.py", "st_sim/reactive/choosing.py", "st_sim/reactive/detour.py",
           "st_sim/reactive/footprint.py", "st_sim/reactive/reaction.py", "st_sim/reactive/routes.py",
           "st_sim/sim/exact.py", "st_sim/sim/map_depth.py", "replays/constants.py")
"""the files whose code or constants the kernels compile in (``tests/test_reactive_compiled.py`` checks that every
module the kernels import from is here)"""


def drop_stale_caches(package: Path = PACKAGE, root: Path = ROOT, sources: tuple[str, ...] = SOURCES) -> None:
    """Delete the kernels' cached machine code (``package``'s ``__pycache__/*.nbi``, ``*.nbc``) when any of
    ``sources`` (paths under ``root``) changed since it was compiled: numba checks only the file a kernel is defined
    in, not the constants and functions it took from others. Nothing happens where the package cannot be written
    (an installed copy, whose sources do not change)."""
    cache = package / "__pycache__"
    stamp = cache / "kernels.sha256"
    try:
        fingerprint = hashlib.sha256(b"".join((root / name).read_bytes() for name in sources)).hexdigest()
        if stamp.is_file() and stamp.read_text() == fingerprint:
            return
        for stale in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:
            stale.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        write_text_atomic(stamp, fingerprint)
    except OSError:
        return


def announce_compiling(package: Path = PACKAGE) -> bool:
    """Say on stderr, once per process, that the kernels compile now when none is cached yet in ``package`` (the
    first reactive step on a fresh install takes a few minutes of one core); whether it said so."""
    global _announced
    if _announced or any((package / "__pycache__").glob("*.nbi")):
        return False
    _announced = True
    print("STCrowd: compiling the reactive pedestrians' kernels (numba; once per install, a few minutes of one core, "
          "then cached)", file=sys.stderr, flush=True)
    return True


_announced = False
drop_stale_caches()
