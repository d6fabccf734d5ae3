"""``exp`` in plain IEEE arithmetic, the same bits on every x86-64 CPU.

The C library's ``exp`` (which numba's ``math.exp`` calls) and numpy's ``np.exp`` pick CPU-specific
variants (FMA, AVX2, AVX-512) that differ in the last bit: measured here, glibc's and numpy's ``exp`` of
200 000 arguments in [-20, 0] gave other bits on this AVX-512 machine than with those units switched
off.  A per-point ``exp`` that scales a return's power (effect ``weather``'s two-way transmission) or
decides a return (``return_probability``'s logistic) would then break "same seed, same bits" across
machines (``tests/determinism``).  This one uses only ``+``, ``*``, ``floor`` and ``ldexp``, which
IEEE 754 defines exactly, in a fixed order (numba contracts nothing into FMAs without fast-math), like
the scan kernels' own ``sin``/``cos`` (:func:`sim.scan.kernels._sincos_rev`).

Method: ``x = k ln2 + r`` with ``k`` the nearest integer to ``x / ln2`` and ``r`` in [-ln2/2, ln2/2]
by Cody and Waite's two-part ``ln2`` (fdlibm's constants: ``k * LN2_HI`` is exact for ``|k| < 2^11``);
``exp(r)`` by its Taylor series to ``r^13`` (remainder below 4e-18 relative); the result scaled by
``2^k`` (``ldexp``, exact unless it underflows).  Relative error a few ulp (``tests/sensor``); an
argument above 709.78 gives inf, below -745.2 gives 0, NaN stays NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

LN2_HI = 6.93147180369123816490e-01
LN2_LO = 1.90821492927058770002e-10
INV_LN2 = 1.44269504088896338700e+00
X_MAX = 709.782712893383973096     # exp(X_MAX) is the largest finite double
X_MIN = -745.13321910194110842     # below it exp rounds to 0
# 1/n! for n = 2..13, Horner from the top
_P = tuple(1.0 / math.factorial(n) for n in range(2, 14))
(_P2, _P3, _P4, _P5, _P6, _P7, _P8, _P9, _P10, _P11, _P12, _P13) = _P


@njit(cache=True, inline="always", error_model="numpy")
def exp_portable(x):
    """``exp(x)`` with the same bits on every CPU (module docstring)."""
    if not x < X_MAX:
        return x if x != x else math.inf
    if not x > X_MIN:
        return 0.0
    k = np.floor(x * INV_LN2 + 0.5)
    r = (x - k * LN2_HI) - k * LN2_LO
    p = 1.0 + r * (1.0 + r * (_P2 + r * (_P3 + r * (_P4 + r * (_P5 + r * (_P6 + r * (_P7 + r * (
        _P8 + r * (_P9 + r * (_P10 + r * (_P11 + r * (_P12 + r * _P13))))))))))))
    return math.ldexp(p, int(k))


def exp_portable_np(x) -> np.ndarray:
    """The numpy twin of :func:`exp_portable`, elementwise the same operations, so the same bits."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        xc = np.clip(x, X_MIN, X_MAX)
        k = np.floor(xc * INV_LN2 + 0.5)
        r = (xc - k * LN2_HI) - k * LN2_LO
        p = 1.0 + r * (1.0 + r * (_P2 + r * (_P3 + r * (_P4 + r * (_P5 + r * (_P6 + r * (_P7 + r * (
            _P8 + r * (_P9 + r * (_P10 + r * (_P11 + r * (_P12 + r * _P13))))))))))))
        out = np.ldexp(p, k.astype(np.int64))
    out = np.where(x >= X_MAX, np.inf, out)
    out = np.where(x <= X_MIN, 0.0, out)
    return np.where(np.isnan(x), x, out)
