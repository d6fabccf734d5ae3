"""The packed points of a recording frame in one pass (numba): what :func:`foveatrack.recording.format.
pack_points_numpy` computes in ~12 numpy passes and 5 unaligned field copies (~0.3 ms for a 3 000-point
frame against ~0.01 ms here).  tests/recording/test_points_format3.py compares the bytes of both.

Format 3 (docs/recordings.md): a frame on the Livox mm grid -- every coordinate ``v`` equal to the
client's ``k * 1e-3`` for an integer ``k`` [mm] with ``|k| < MAX_GRID_MM`` -- is stored as float32
``rint(2048 v) / 2048`` [m]; point times as ``dt / unit`` where ``unit`` is the gcd of the offsets
``dt`` [ns] from the frame time (1 when all are 0).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from foveatrack.mm_grid import MM_PER_M
from foveatrack.recording.format import GRID_PER_M, MAX_GRID_MM, packed_point_dtype


@njit(cache=True)
def grid_scan_kernel(xyz, dt_ns, max_mm):
    """(on the mm grid and within ``max_mm``, gcd of |dt_ns| (0 if all 0), min dt_ns, max dt_ns).

    xyz (n, 3) float64 [m]; dt_ns (n,) int64.  On the grid: ``rint(1000 v) * 1e-3 == v`` (the
    client's ``mm_to_m``, to the bit) and ``|rint(1000 v)| < max_mm``; NaN is off the grid."""
    on = True
    g = 0
    lo = hi = 0
    for i in range(xyz.shape[0]):
        for j in range(3):
            v = xyz[i, j]
            k = np.rint(v * MM_PER_M)
            if not (abs(k) < max_mm) or k * 1e-3 != v:
                on = False
        d = dt_ns[i]
        if i == 0 or d < lo:
            lo = d
        if i == 0 or d > hi:
            hi = d
        a = abs(d)
        if g and a % g == 0:        # the common case: one division, not Euclid's two
            continue
        while a:                    # Euclid: g = gcd(g, a)
            g, a = a, g % a
    return on, g, lo, hi


@njit(cache=True)
def pack_grid_kernel(xyz, dt_ns, unit, reflectivity, out):
    """Fill ``out`` (records x, y, z float32, dt int16 or int32, reflectivity uint8) from a frame on
    the mm grid (checked by :func:`grid_scan_kernel`): x = rint(2048 v) / 2048, dt = dt_ns / unit."""
    for i in range(xyz.shape[0]):
        r = out[i]
        r.x = np.rint(xyz[i, 0] * 2048.0) / 2048.0
        r.y = np.rint(xyz[i, 1] * 2048.0) / 2048.0
        r.z = np.rint(xyz[i, 2] * 2048.0) / 2048.0
        r.dt = dt_ns[i] // unit
        r.reflectivity = reflectivity[i]


assert GRID_PER_M == 2048.0     # the kernel's constant


def pack_points(xyz: np.ndarray, dt_ns: np.ndarray, reflectivity: np.ndarray) -> tuple[np.ndarray, int]:
    """The packed points of one frame and the unit of their ``dt`` [ns]: float32 on the mm grid when
    the frame is on it, float64 otherwise.  xyz (n, 3) float64 [m]; dt_ns (n,) int64 (within int32:
    the caller checks); reflectivity (n,) uint8.  Same bytes as ``pack_points_numpy``."""
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    dt_ns = np.ascontiguousarray(dt_ns, dtype=np.int64)
    reflectivity = np.ascontiguousarray(reflectivity, dtype=np.uint8)
    on, g, lo, hi = grid_scan_kernel(xyz, dt_ns, float(MAX_GRID_MM))
    unit = int(g) or 1
    dt_type = "<i2" if -(2**15) <= lo // unit and hi // unit < 2**15 else "<i4"
    if on:
        out = np.empty(xyz.shape[0], packed_point_dtype("float32", dt_type))
        pack_grid_kernel(xyz, dt_ns, unit, reflectivity, out)
        return out, unit
    out = np.empty(xyz.shape[0], packed_point_dtype("float64", dt_type))
    out["x"], out["y"], out["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    out["dt"] = dt_ns // unit
    out["reflectivity"] = reflectivity
    return out, unit
