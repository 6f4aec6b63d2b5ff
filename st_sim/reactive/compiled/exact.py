"""numpy's rounding in compiled loops: the kernels compute every number as the plain numpy path does, so that the
walks are the same to the last bit.

numpy's ``maximum``/``minimum`` return the second operand on a tie (``maximum(-0.0, 0.0)`` is ``0.0``) and propagate
NaN; ``clip`` keeps the value on a tie with a bound; a sum along an axis starts from 0 and adds pairwise (eight
accumulators over blocks of up to 128 values, halves beyond); ``arange`` fills ``start + i * delta`` with ``delta``
the rounded difference of its first two values. The bearing's arctangent is ``st_sim.sim.exact.atan2``'s, one point
at a time (numba's ``np.arctan2`` calls libm, which rounds by the CPU).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from st_sim.sim.exact import ATAN_HI, ATAN_LO, ATAN_T, PI_HI, PI_LO

PAIRWISE_BLOCK = 128  # numpy sums blocks of up to this many values with eight accumulators [-]


@njit(cache=True, inline="always")
def maximum(a: float, b: float) -> float:
    """``np.maximum(a, b)``: NaN if either is, ``b`` on a tie."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a > b else b


@njit(cache=True, inline="always")
def minimum(a: float, b: float) -> float:
    """``np.minimum(a, b)``: NaN if either is, ``b`` on a tie."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a < b else b


@njit(cache=True, inline="always")
def clip(x: float, low: float, high: float) -> float:
    """``np.clip(x, low, high)``: NaN for a NaN ``x``, ``x`` on a tie with a bound."""
    if x != x:
        return x
    if x < low:
        x = low
    if x > high:
        x = high
    return x


@njit(cache=True, inline="always")
def first_of_least(value: float, best: float, have: bool) -> bool:
    """Whether ``value`` takes the place of ``best`` (the value chosen so far, if ``have``) as ``np.argmin`` chooses
    in a scan: the first NaN, else the first of the least values."""
    if not have:
        return True
    if best != best:
        return False
    return value != value or value < best


@njit(cache=True, inline="always")
def length(x: float, y: float) -> float:
    """``footprint.length_m`` of the vector (x, y) [m]."""
    return np.sqrt(x * x + y * y)


@njit(cache=True, inline="always")
def atan(x: float) -> float:
    """``st_sim.sim.exact.atan(x)`` [rad]: the same operations on the one range ``|x|`` falls in."""
    a = abs(x)
    if a < 0.4375:
        reduced, part = a, -1
    elif a < 0.6875:
        reduced, part = (2.0 * a - 1.0) / (2.0 + a), 0
    elif a < 1.1875:
        reduced, part = (a - 1.0) / (a + 1.0), 1
    elif a < 2.4375:
        reduced, part = (a - 1.5) / (1.0 + 1.5 * a), 2
    else:  # and NaN
        reduced, part = -1.0 / a, 3
    z = reduced * reduced
    w = z * z
    t = ATAN_T
    s1 = z * (t[0] + w * (t[2] + w * (t[4] + w * (t[6] + w * (t[8] + w * t[10])))))
    s2 = w * (t[1] + w * (t[3] + w * (t[5] + w * (t[7] + w * t[9]))))
    if part < 0:
        return math.copysign(reduced - reduced * (s1 + s2), x)
    return math.copysign(ATAN_HI[part] - ((reduced * (s1 + s2) - ATAN_LO[part]) - reduced), x)


@njit(cache=True, inline="always")
def atan2(y: float, x: float) -> float:
    """``st_sim.sim.exact.atan2(y, x)``: the angle of the point (x, y) [rad], the same bits."""
    ay, ax = abs(y), abs(x)
    steep = ay > ax
    ratio = ax / ay if steep else ay / (ax if ax > 0 else 1.0)
    angle = atan(ratio)
    if steep:
        angle = (ATAN_HI[3] - angle) + ATAN_LO[3]
    if math.copysign(1.0, x) < 0.0:  # -0.0 too
        angle = (PI_HI - angle) + PI_LO
    return math.copysign(angle, y)


@njit(cache=True)
def _block(values: np.ndarray, start: int, n: int) -> float:
    """numpy's sum of ``n`` <= ``PAIRWISE_BLOCK`` values from ``start``: in order below 8, else eight accumulators."""
    if n < 8:
        total = 0.0
        for i in range(start, start + n):
            total += values[i]
        return total
    r0, r1, r2, r3 = values[start], values[start + 1], values[start + 2], values[start + 3]
    r4, r5, r6, r7 = values[start + 4], values[start + 5], values[start + 6], values[start + 7]
    whole = n - n % 8
    for i in range(start + 8, start + whole, 8):
        r0 += values[i]
        r1 += values[i + 1]
        r2 += values[i + 2]
        r3 += values[i + 3]
        r4 += values[i + 4]
        r5 += values[i + 5]
        r6 += values[i + 6]
        r7 += values[i + 7]
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(start + whole, start + n):
        total += values[i]
    return total


@njit(cache=True, inline="always")
def _half(n: int) -> int:
    """Where numpy splits ``n`` > ``PAIRWISE_BLOCK`` values: half of them, less the rest of a division by 8."""
    return n // 2 - (n // 2) % 8


@njit(cache=True)
def _pairwise(values: np.ndarray, start: int, n: int) -> float:
    """numpy's pairwise sum of ``n`` values from ``start``: blocks of up to ``PAIRWISE_BLOCK``, else the sum of the
    two halves' sums (numpy recurses; here an explicit stack, as numba caches no recursive function)."""
    if n <= PAIRWISE_BLOCK:
        return _block(values, start, n)
    starts, sizes = np.empty(64, np.int64), np.empty(64, np.int64)
    lefts, phases = np.empty(64), np.zeros(64, np.int64)  # phase 0: to split, 1: left half summing, 2: right half
    starts[0], sizes[0], depth = start, n, 1
    result, returning = 0.0, False
    while depth:
        top = depth - 1
        if returning:  # a half's sum is ``result``
            if phases[top] == 1:
                lefts[top], phases[top] = result, 2
                starts[depth], sizes[depth], phases[depth] = starts[top] + _half(sizes[top]), \
                    sizes[top] - _half(sizes[top]), 0
                depth += 1
                returning = False
            else:
                result = lefts[top] + result
                depth -= 1
            continue
        if sizes[top] <= PAIRWISE_BLOCK:
            result = _block(values, starts[top], sizes[top])
            depth -= 1
            returning = True
            continue
        phases[top] = 1
        starts[depth], sizes[depth], phases[depth] = starts[top], _half(sizes[top]), 0
        depth += 1
    return result


@njit(cache=True)
def total(values: np.ndarray, n: int) -> float:
    """The sum of ``values[:n]`` (a contiguous float64 row) as ``values[:n].sum()`` rounds it."""
    return 0.0 + _pairwise(values, 0, n)


@njit(cache=True)
def arange(start: float, stop: float, step: float) -> np.ndarray:
    """``np.arange(start, stop, step)`` for floats, the same values."""
    count = int(np.ceil((stop - start) / step))
    out = np.empty(max(count, 0))
    if count > 0:
        out[0] = start
    if count > 1:
        out[1] = start + step
        delta = out[1] - start
        for i in range(2, count):
            out[i] = start + i * delta
    return out
