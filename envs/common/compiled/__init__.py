"""The reactive step compiled (numba): the same walks as the plain numpy path, to the last bit, in a fraction of the
time.

``envs.common.reactive`` steps N crowds as arrays (N, A): cheap where the arrays are large, but each pedestrian off
its log scores hundreds of candidate places, one chooser after another, on arrays of a few dozen rows, so the plain
path spends its time calling numpy, not computing. Here the same arithmetic runs in loops compiled by numba:

- ``exact``: numpy's rounding in loops (its pairwise sums, ``maximum``/``minimum``/``clip`` on ties and NaN,
  ``arange``'s values), so that every number equals the plain path's;
- ``geometry``: the robot's body gaps and the scene's depth at a point (``footprint``, ``MapDepth.at``);
- ``tables``: a replay's route tables as one tuple, and the places along the routes (``routes.Routes``);
- ``way_round``: the way round the robot, a shortest walk on a grid (``candidates._way_round_m``, ``detour``);
- ``choose``: every chooser of every crowd, one after another, the nearest to the robot first (``choosing``,
  ``candidates``);
- ``in_the_way``: who leaves its log for the robot or for the others (``reactive._robot_in_the_way``,
  ``reactive._others_in_the_way``).

The plain path stays the reference (``Routes(..., compiled=False)``): ``tests/test_reactive_compiled.py`` walks both
on drawn crowds and on the replays and asserts every state equal, bit for bit, and ``benchmarks/bench_reactive.py
--digest`` compares whole episodes. One difference is allowed and stated: on a scene whose image homography is
projective (ETH, HOTEL; UCY's are affine) numpy maps points to pixels with a BLAS product whose rounding depends on
the batch, so a point within a rounding error of a pixel's edge may be looked up in the neighbouring pixel (the plain
path itself does so from one batch size to another). Kernels compile on first use and are cached on disk
(``cache=True``); a process pays about a second to load them.
"""
