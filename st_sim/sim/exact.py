"""Arithmetic that gives the same bits on every CPU: the crowd's transcendental functions and sums, built from
IEEE-exact operations only.

numpy picks its kernels at run time (SSE, AVX2, AVX-512) and glibc's libm its own (with or without fused multiply-adds):
``exp``, ``sin``, ``cos`` and Python's ``x ** 2`` (libm's ``pow``) differ between them in the last bit, and so do
OpenBLAS's products (``@``, ``np.dot``, ``linalg.norm`` of one vector). A crowd is chaotic, so one such bit grows into
another crowd. Here every result comes from ``+``, ``-``, ``*``, ``/``, ``sqrt``, ``rint`` and ``ldexp`` (each correctly
rounded everywhere), one numpy operation after another (nothing to fuse), in a fixed order: ``exp``, ``sin`` and ``cos``
are FreeBSD's (fdlibm's) algorithms, within 1 ulp of the true value; sums of the two coordinates of a vector, and along
an axis, are written out.
"""

from __future__ import annotations

import numpy as np

LN2_HI, LN2_LO = 6.93147180369123816490e-01, 1.90821492927058770002e-10  # ln 2 in two parts, LN2_HI with 32 bits
INV_LN2 = 1.44269504088896338700e00
EXP_P = (1.66666666666666019037e-01, -2.77777777770155933842e-03, 6.61375632143793436117e-05,
         -1.65339022054652515390e-06, 4.13813679705723846039e-08)  # fdlibm's e_exp.c: exp(r) on |r| <= ln2 / 2
EXP_RANGE = (-746.0, 710.0)  # exp is 0 below, inf above
INV_PIO2 = 6.36619772367581382433e-01
PIO2 = (1.57079632673412561417e00, 6.07710050650619224932e-11,  # pi / 2 in three parts of 33 bits and their tails
        6.07710050630396597660e-11, 2.02226624879595063154e-21,  # (FreeBSD's __rem_pio2: part, tail, part, ...)
        2.02226624871116645580e-21, 8.47842766036889956997e-32)
MAX_ANGLE_RAD = 2.0 ** 19  # sin and cos reduce angles up to this (quadrant counts stay exact) [rad]
SIN_S = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
         2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)  # __sin on |x| <= pi/4
COS_C = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
         -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)  # __cos on |x| <= pi/4


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(...) dot products of 2-vectors (..., 2): x x + y y."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def length(v: np.ndarray) -> np.ndarray:
    """(...) Euclidean lengths of 2-vectors (..., 2), as ``np.linalg.norm(v, axis=-1)`` (not guarded against
    overflow: lengths in metres)."""
    return np.sqrt(dot(v, v))


def total(a: np.ndarray, axis: int) -> np.ndarray:
    """``a.sum(axis)`` added in index order along ``axis`` (one slice after another)."""
    parts = np.moveaxis(np.asarray(a), axis, 0)
    out = np.zeros(parts.shape[1:], np.result_type(parts, np.float64))
    for part in parts:
        out = out + part
    return out


def exp(x: np.ndarray | float) -> np.ndarray:
    """e ** x elementwise (float64, any shape): x = k ln 2 + r, |r| <= ln 2 / 2, a rational approximation of e ** r
    (fdlibm), scaled by 2 ** k; exactly 0 for -inf, inf for inf, NaN for NaN."""
    x = np.clip(np.asarray(x, np.float64), *EXP_RANGE)
    k = np.rint(x * INV_LN2)
    hi = x - k * LN2_HI  # exact: k has at most 11 bits, LN2_HI 32
    lo = k * LN2_LO
    r = hi - lo
    t = r * r
    p1, p2, p3, p4, p5 = EXP_P
    c = r - t * (p1 + t * (p2 + t * (p3 + t * (p4 + t * p5))))
    y = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    with np.errstate(over="ignore"):
        return np.ldexp(y, np.where(np.isnan(k), 0.0, k).astype(np.int64))


def cos_sin(angle_rad: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Cosine and sine of angles (any shape, |angle| < MAX_ANGLE_RAD) [rad]: the angle less the nearest multiple n
    of pi / 2 (three parts of pi / 2, with the rounding error carried), FreeBSD's __cos and __sin on the rest, and
    the quadrant n mod 4 choosing and signing them.

    Raises:
        ValueError: an angle is not finite or not below MAX_ANGLE_RAD in magnitude.
    """
    x = np.asarray(angle_rad, np.float64)
    if not (np.abs(x) < MAX_ANGLE_RAD).all():
        raise ValueError(f"cos_sin: angles must be finite and below {MAX_ANGLE_RAD:g} rad in magnitude")
    n = np.rint(x * INV_PIO2)
    head, rest = x, 0.0
    for part, tail in zip(PIO2[0::2], PIO2[1::2], strict=True):  # each round: 33 more bits of pi / 2
        taken = n * part  # exact: n has at most 20 bits
        head, before = head - taken, head
        rest = n * tail - ((before - head) - taken)
    y0 = head - rest
    y1 = (head - y0) - rest  # angle - n pi / 2 = y0 + y1
    z = y0 * y0
    w = z * z
    s1, s2, s3, s4, s5, s6 = SIN_S
    r = s2 + z * (s3 + z * s4) + z * w * (s5 + z * s6)
    v = z * y0
    sin = y0 - ((z * (0.5 * y1 - v * r) - y1) - v * s1)
    c1, c2, c3, c4, c5, c6 = COS_C
    r = z * (c1 + z * (c2 + z * c3)) + w * w * (c4 + z * (c5 + z * c6))
    hz = 0.5 * z
    w = 1.0 - hz
    cos = w + (((1.0 - w) - hz) + (z * r - y0 * y1))
    quadrant = n.astype(np.int64) % 4
    return (np.choose(quadrant, [cos, -sin, -cos, sin]), np.choose(quadrant, [sin, cos, -sin, -cos]))
