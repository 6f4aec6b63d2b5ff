"""Arithmetic that gives the same bits on every CPU: the crowd's transcendental functions and sums, built from
IEEE-exact operations only.

numpy picks its kernels at run time (SSE, AVX2, AVX-512) and glibc's libm its own (with or without fused multiply-adds):
``exp``, ``sin``, ``cos`` and Python's ``x ** 2`` (libm's ``pow``) differ between them in the last bit, and so do
OpenBLAS's products (``@``, ``np.dot``, ``linalg.norm`` of one vector). A crowd is chaotic, so one such bit grows into
another crowd. Here every result comes from ``+``, ``-``, ``*``, ``/``, ``sqrt``, ``rint`` and ``ldexp`` (each correctly
rounded everywhere), one numpy operation after another (nothing to fuse), in a fixed order: ``exp``, ``sin`` and ``cos``
are FreeBSD's (fdlibm's) algorithms, within 1 ulp of the true value; sums of the two coordinates of a vector, and along
an axis, are written out. Poisson draws (``poisson_draws``) multiply uniform draws down to ``exp``'s threshold, as
numpy's own sampler does down to libm's.
"""

from __future__ import annotations

import decimal

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


def cap_speed(velocity_mps: np.ndarray, max_speed_mps: np.ndarray) -> np.ndarray:
    """Scale down rows of (N, 2) velocities whose norm exceeds max_speed_mps (N,) [m/s]."""
    speed = length(velocity_mps)
    scale = np.minimum(1.0, max_speed_mps / np.maximum(speed, 1e-9))
    return velocity_mps * scale[:, None]


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


def poisson_draws(rng: np.random.Generator, mean: float, n: int) -> np.ndarray:
    """(n,) int64 Poisson counts of ``mean`` [-], one after another from ``rng``: each multiplies uniform draws until
    their product falls to e ** -mean (``exp``) or below, and counts the draws before that one. Below a mean of 10
    this is numpy's ``Generator.poisson``, uniform for uniform, with the threshold from ``exp`` instead of libm's;
    beyond it, where numpy switches to a rejection method that calls libm's ``log``, the same multiplication (as
    many draws as the count, fine for the crowd's means)."""
    counts = np.zeros(n, np.int64)
    if mean <= 0:
        return counts  # numpy draws nothing for a mean of 0
    threshold = float(exp(-mean))
    for i in range(n):
        product = rng.random()
        while product > threshold:
            counts[i] += 1
            product *= rng.random()
    return counts


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


TABLE_ANGLE_RAD = 8.0  # rounded_cos_sin takes angles up to this (its series needs no reduction) [rad]
TABLE_DIGITS = 60  # rounded_cos_sin's working precision [decimal digits]


def rounded_cos_sin(angle_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine and sine of angles (any shape, |angle| <= TABLE_ANGLE_RAD) [rad], each the float64 nearest the true
    value: the Taylor series of the angle's exact binary value in TABLE_DIGITS-digit decimals, rounded once. Slow
    (about a millisecond an angle): for tables built once, such as a planner's headings, whose every entry is then the
    same on every CPU and equal to a correctly rounding libm's.

    Raises:
        ValueError: an angle is not finite or beyond TABLE_ANGLE_RAD in magnitude.
    """
    x = np.asarray(angle_rad, np.float64)
    if not (np.abs(x) <= TABLE_ANGLE_RAD).all():
        raise ValueError(f"rounded_cos_sin: angles must be finite and at most {TABLE_ANGLE_RAD:g} rad in magnitude")
    cos, sin = np.empty_like(x), np.empty_like(x)
    with decimal.localcontext(prec=TABLE_DIGITS):
        for index, angle in np.ndenumerate(x):
            value = decimal.Decimal(float(angle))
            sums, term, k = [decimal.Decimal(0)] * 4, decimal.Decimal(1), 0
            while k < 8 or abs(term) > decimal.Decimal(10) ** -(TABLE_DIGITS - 4):
                sums[k % 4] += term  # the terms x^k / k!, by k mod 4: cos = s0 - s2, sin = s1 - s3
                k += 1
                term = term * value / k
            cos[index], sin[index] = float(sums[0] - sums[2]), float(sums[1] - sums[3])
    return cos, sin


ATAN_HI = (4.63647609000806093515e-01, 7.85398163397448278999e-01, 9.82793723247329054082e-01,
           1.57079632679489655800e00)  # atan(0.5), atan(1), atan(1.5), atan(inf), high parts (fdlibm's s_atan.c)
ATAN_LO = (2.26987774529616870924e-17, 3.06161699786838301793e-17, 1.39033110312309984516e-17,
           6.12323399573676603587e-17)  # their low parts
ATAN_T = (3.33333333333329318027e-01, -1.99999999998764832476e-01, 1.42857142725034663711e-01,
          -1.11111104054623557880e-01, 9.09088713343650656196e-02, -7.69187620504482999495e-02,
          6.66107313738753120669e-02, -5.83357013379057348645e-02, 4.97687799461593236017e-02,
          -3.65315727442169155270e-02, 1.62858201153657823623e-02)  # atan(x) = x - x^3 (T0 + x^2 T1 + ...) near 0
PI_HI, PI_LO = 3.1415926535897931160e00, 1.2246467991473531772e-16


def atan(x: np.ndarray | float) -> np.ndarray:
    """Arctangent elementwise [rad] (float64, any shape): |x| reduced to one of five ranges round 0, 0.5, 1, 1.5 and
    infinity, where atan is a known constant plus the atan of a small argument (fdlibm's polynomial)."""
    x = np.asarray(x, np.float64)
    a = np.abs(x)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        reduced = np.select([a < 0.4375, a < 0.6875, a < 1.1875, a < 2.4375],
                            [a, (2.0 * a - 1.0) / (2.0 + a), (a - 1.0) / (a + 1.0), (a - 1.5) / (1.0 + 1.5 * a)],
                            -1.0 / a)
    part = np.select([a < 0.4375, a < 0.6875, a < 1.1875, a < 2.4375], [-1, 0, 1, 2], 3)
    z = reduced * reduced
    w = z * z
    t = ATAN_T
    s1 = z * (t[0] + w * (t[2] + w * (t[4] + w * (t[6] + w * (t[8] + w * t[10])))))
    s2 = w * (t[1] + w * (t[3] + w * (t[5] + w * (t[7] + w * t[9]))))
    hi, lo = np.asarray(ATAN_HI)[np.maximum(part, 0)], np.asarray(ATAN_LO)[np.maximum(part, 0)]
    near = reduced - reduced * (s1 + s2)
    far = hi - ((reduced * (s1 + s2) - lo) - reduced)
    return np.copysign(np.where(part < 0, near, far), x)


def atan2(y: np.ndarray | float, x: np.ndarray | float) -> np.ndarray:
    """The angle of the points (x, y) elementwise [rad], in [-pi, pi], as ``np.arctan2`` for finite arguments (0 at
    the origin, pi or -pi at a negative zero x): ``atan`` of the smaller over the larger magnitude, then placed in its
    octant."""
    y, x = np.broadcast_arrays(np.asarray(y, np.float64), np.asarray(x, np.float64))
    ay, ax = np.abs(y), np.abs(x)
    steep = ay > ax
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ratio = np.where(steep, ax / np.where(steep, ay, 1.0), ay / np.where(ax > 0, ax, 1.0))
    base = atan(ratio)  # in [0, pi / 4]
    half_pi = ATAN_HI[3]
    angle = np.where(steep, (half_pi - base) + ATAN_LO[3], base)  # angle of (|x|, |y|), in [0, pi / 2]
    angle = np.where(np.signbit(x), (PI_HI - angle) + PI_LO, angle)  # -0.0 too, as arctan2
    return np.copysign(angle, y)
