"""Products of 3-vectors and 3 x 3 matrices in a fixed order of IEEE operations: the same bits on
every x86-64 CPU.

Why not ``np.dot`` / ``ndarray.dot`` / ``@`` / ``np.matmul`` / ``np.linalg.norm(v)``: numpy hands a
float64 product (and the norm of a vector, ``sqrt(dot(v, v))``) to its BLAS, OpenBLAS, which is built
for every x86-64 core and picks its kernels by the CPU it loads on.  The Haswell/Zen, Skylake-X,
Sandy Bridge and older kernels sum in different orders and some fuse multiply and add, so one product
differs in its last bit between machines, and a closed-loop run drifts apart from there
(``tests/determinism`` runs every scene under each ``OPENBLAS_CORETYPE`` to check it does not).

Here every sum is written out left to right, ``a0*b0 + a1*b1 + a2*b2 = (a0*b0 + a1*b1) + a2*b2``,
on Python floats (CPython neither reorders nor fuses) or, for many rows at once, with numpy's
elementwise multiply and add on columns (separate ufunc calls: nothing to contract; a vector lane
computes what the scalar loop does).  For three elements these are also cheaper than a BLAS call
through numpy's dispatch.  :func:`rows_times_mat3T` turns points exactly as the box kernel does
(:func:`foveatrack.kernels.box_members_kernel`: ``r0 * px + r1 * py + r2 * pz``).
"""

from __future__ import annotations

import math

import numpy as np

_F64 = np.dtype(np.float64)


def floats3(v) -> list[float]:
    """The three components of ``v`` as Python floats (an array's ``tolist`` is the quick way: the
    recording's records are built with it on the loop's thread every frame)."""
    if type(v) is np.ndarray and v.dtype is _F64 and v.ndim == 1:   # a wrong length fails to unpack
        return v.tolist()
    return np.asarray(v, dtype=np.float64).reshape(3).tolist()


def dot3(a, b) -> float:
    """``a . b`` of two 3-vectors (sequences or arrays of 3 floats)."""
    a0, a1, a2 = floats3(a)
    b0, b1, b2 = floats3(b)
    return a0 * b0 + a1 * b1 + a2 * b2


def norm3(v) -> float:
    """``|v|`` of a 3-vector: ``sqrt(v . v)``, as ``np.linalg.norm`` defines it (without its BLAS)."""
    x, y, z = floats3(v)
    return math.sqrt(x * x + y * y + z * z)


def dist3(a, b) -> float:
    """``norm3(a - b)`` of two 3-vectors without the array of their difference: the same subtractions,
    products and sums, on floats (a track's few distances a frame, where the array cost the most)."""
    ax, ay, az = floats3(a)
    bx, by, bz = floats3(b)
    x, y, z = ax - bx, ay - by, az - bz
    return math.sqrt(x * x + y * y + z * z)


def mat3_vec(R, v) -> np.ndarray:
    """``R @ v`` (3,) of a 3 x 3 matrix (an array, or its rows as floats) and a 3-vector."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist() if type(R) is np.ndarray else R
    x, y, z = floats3(v)
    return np.array([r00 * x + r01 * y + r02 * z,
                     r10 * x + r11 * y + r12 * z,
                     r20 * x + r21 * y + r22 * z])


def mat3T_vec(R: np.ndarray, v) -> np.ndarray:
    """``R.T @ v`` (3,): a vector turned back by the rotation ``R`` (world -> body for body -> world)."""
    return np.array(rows_T_times(R.tolist(), *floats3(v)))


def rows_T_times(rows, x: float, y: float, z: float) -> tuple[float, float, float]:
    """``R.T @ (x, y, z)`` on ``R``'s rows as floats (three tuples of 3), in floats: the products and
    sums of :func:`mat3T_vec`, without its arrays (callers once a frame or a track)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
    return (r00 * x + r10 * y + r20 * z,
            r01 * x + r11 * y + r21 * z,
            r02 * x + r12 * y + r22 * z)


def rows_times_mat3T(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``X @ R.T`` (N, 3): each row of ``X`` (N, 3) turned by ``R`` (3 x 3), column by column."""
    X = np.asarray(X, dtype=np.float64)
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    out = np.empty((X.shape[0], 3))
    for i, (r0, r1, r2) in enumerate(np.asarray(R, dtype=np.float64).tolist()):
        out[:, i] = r0 * x + r1 * y + r2 * z
    return out


def mats3_times_mat3(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` for a stack of 3 x 3 matrices ``A`` (..., 3, 3) and one 3 x 3 ``B``."""
    A = np.asarray(A, dtype=np.float64)
    out = np.empty(A.shape)
    a0, a1, a2 = A[..., 0], A[..., 1], A[..., 2]     # A's columns, each (..., 3)
    for k, (b0, b1, b2) in enumerate(np.asarray(B, dtype=np.float64).T.tolist()):
        out[..., k] = a0 * b0 + a1 * b1 + a2 * b2
    return out


def mats3_times_vec3(A: np.ndarray, v) -> np.ndarray:
    """``A @ v`` (..., 3) for a stack of 3 x 3 matrices ``A`` (..., 3, 3) and one 3-vector ``v``."""
    A = np.asarray(A, dtype=np.float64)
    x, y, z = floats3(v)
    return A[..., 0] * x + A[..., 1] * y + A[..., 2] * z
