"""``sim.portable_exp``: the per-point ``exp`` of the weather and return-probability effects, the same
bits on every CPU (its numba kernel equals its numpy twin bit for bit) and within an ulp of libm's."""

import math

import numpy as np
from numba import njit

from sim.portable_exp import X_MAX, X_MIN, exp_portable, exp_portable_np


@njit(cache=True)
def _many(x):
    out = np.empty_like(x)
    for i in range(x.size):
        out[i] = exp_portable(x[i])
    return out


def _arguments():
    rng = np.random.default_rng(7)
    edges = [0.0, -0.0, 1e-300, -1e-300, X_MAX, np.nextafter(X_MAX, 0), X_MIN, np.nextafter(X_MIN, 0),
             -708.4, -740.0, 709.0, np.nan, np.inf, -np.inf]
    return np.concatenate([rng.uniform(-760, 720, 100_000), rng.uniform(-60, 0, 100_000),
                           rng.uniform(-1e-6, 1e-6, 1000), edges])


def test_the_kernel_and_its_numpy_twin_give_the_same_bits():
    x = _arguments()
    a, b = _many(x), exp_portable_np(x)
    assert np.array_equal(a.view(np.int64), b.view(np.int64))


def test_within_one_ulp_of_the_c_library_and_its_limits():
    x = _arguments()
    got = _many(x)
    ref = np.array([math.exp(v) if v < 709.78 else (v if v != v else math.inf) for v in x])
    normal = np.isfinite(ref) & (ref > np.finfo(float).tiny)
    ulp = np.abs(got[normal] - ref[normal]) / np.spacing(ref[normal])
    assert ulp.max() <= 1.0
    assert np.isnan(got[np.isnan(x)]).all()
    assert (got[x >= X_MAX] == np.inf).all() and (got[x <= X_MIN] == 0.0).all()
    assert _many(np.array([0.0]))[0] == 1.0
