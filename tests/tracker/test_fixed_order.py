"""foveatrack.fixed_order: each product is the left-to-right sum of its terms (the helpers agree with
one another to the bit), within a dot product's rounding bound of the exact value, and turns points
as the box kernel does.  That the closed loop's bits no longer depend on OpenBLAS's kernels is
checked in tests/determinism (every scene under each ``OPENBLAS_CORETYPE``)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from foveatrack.fixed_order import (dot3, mat3_vec, mat3T_vec, mats3_times_mat3, mats3_times_vec3, norm3,
                                    rows_times_mat3T)
from foveatrack.kernels import box_members_kernel
from foveatrack.reconstruction import head_trig, rotation_matrix

U = 2.0 ** -53      # unit roundoff of float64


def _vectors(rng, n):
    """3-vectors over many magnitudes, with mixed signs (cancellation) and exact zeros."""
    v = rng.normal(0, 1, (n, 3)) * 10.0 ** rng.uniform(-6, 6, (n, 1))
    v[rng.random((n, 3)) < 0.05] = 0.0
    return v


def test_dot3_is_within_the_rounding_bound_of_the_exact_dot_product():
    """|fl(a.b) - a.b| <= gamma_3 sum |a_k b_k| (Higham, Accuracy and Stability, eq. 3.5), the exact
    value taken in rationals; and the sum is left to right, not another order."""
    rng = np.random.default_rng(1)
    a, b = _vectors(rng, 3000), _vectors(rng, 3000)
    gamma3 = 3 * U / (1 - 3 * U)
    for x, y in zip(a, b):
        exact = sum(Fraction(float(p)) * Fraction(float(q)) for p, q in zip(x, y))
        got = dot3(x, y)
        assert abs(Fraction(got) - exact) <= Fraction(gamma3) * sum(abs(Fraction(float(p)) * Fraction(float(q)))
                                                                    for p, q in zip(x, y))
        x0, x1, x2 = (float(c) for c in x)
        y0, y1, y2 = (float(c) for c in y)
        assert got == (x0 * y0 + x1 * y1) + x2 * y2


def test_dot3_takes_sequences_and_other_dtypes_as_float64():
    assert dot3((1, 2, 3), [4.0, 5.0, 6.0]) == 32.0
    assert dot3(np.array([1, 2, 3], dtype=np.int32), np.array([0.5, 0.25, 2.0], dtype=np.float32)) == 7.0
    assert norm3((3, 4, 12)) == 13.0
    assert norm3(np.array([0.0, 0.0, -2.5], dtype=">f8")) == 2.5


def test_norm3_is_sqrt_of_dot3_and_close_to_hypot():
    rng = np.random.default_rng(2)
    for v in _vectors(rng, 2000):
        n = norm3(v)
        assert n == math.sqrt(dot3(v, v))
        assert abs(n - math.hypot(*v)) <= 6 * U * n


def test_matrix_helpers_are_rows_of_dot3():
    """Every matrix helper's entry is dot3 of a row and a column: one order of sums everywhere."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        R = rng.normal(0, 3, (3, 3))
        v = rng.normal(0, 20, 3)
        X = rng.normal(0, 20, (7, 3))
        A = rng.normal(0, 3, (2, 4, 3, 3))
        w = mat3_vec(R, v)
        assert w.tolist() == [dot3(R[i], v) for i in range(3)]
        assert mat3T_vec(R, v).tolist() == [dot3(R[:, i], v) for i in range(3)]
        assert rows_times_mat3T(X, R).tolist() == [[dot3(R[i], x) for i in range(3)] for x in X]
        AB = mats3_times_mat3(A, R)
        assert AB.shape == A.shape
        assert AB.tolist() == [[[[dot3(m[i], R[:, k]) for k in range(3)] for i in range(3)] for m in row] for row in A]
        assert mats3_times_vec3(A, v).tolist() == [[[dot3(m[i], v) for i in range(3)] for m in row] for row in A]
        # and they are numpy's (BLAS's) products within twice a 3-term dot product's rounding bound
        assert np.all(np.abs(w - R @ v) <= 6 * U * (np.abs(R) @ np.abs(v)))
        assert np.all(np.abs(AB - A @ R) <= 6 * U * (np.abs(A) @ np.abs(R)))


def test_rows_times_mat3T_turns_points_as_the_box_kernel_does():
    """A box one ulp wide around each point as rows_times_mat3T turns it holds the point in the box
    kernel, whose turn is ``r0 * px + r1 * py + r2 * pz`` with rotation_matrix's entries."""
    rng = np.random.default_rng(9)
    idx = np.empty(1, dtype=np.int64)
    for _ in range(500):
        pan, tilt = float(rng.uniform(-400.0, 400.0)), float(rng.uniform(-90.0, 90.0))
        offset, p = rng.normal(0, 0.1, 3), rng.normal(0, 20, (1, 3))
        w = rows_times_mat3T(p + offset, rotation_matrix(pan, tilt))[0]
        assert box_members_kernel(p, *head_trig(pan, tilt), offset, w, np.nextafter(w, np.inf), idx) == 1
