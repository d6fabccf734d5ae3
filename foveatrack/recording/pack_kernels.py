"""The packed points of a recording frame in one pass (numba): what :func:`foveatrack.recording.format.
pack_points_numpy` computes in ~10 numpy passes and 5 unaligned field copies (~0.3 ms for a 3 000-point
frame against ~0.01 ms here).  tests/recording/test_points_mm_grid.py compares the bytes of both.

Formats 3 and 4 (docs/recordings.md): a frame on the Livox mm grid -- every coordinate ``v`` equal to
the client's ``k * 1e-3`` for an integer ``k`` [mm] with ``|k| < MAX_GRID_MM`` -- is stored as float32
``rint(2048 v) / 2048`` [m]; format 4 stores each point's time as ``age_ns`` = frame time - point
time [ns], int32.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from foveatrack.mm_grid import MM_PER_M
from foveatrack.recording.format import GRID_PER_M, MAX_GRID_MM, packed_point_dtype


@njit(cache=True)
def grid_scan_kernel(xyz, max_mm):
    """Whether every point is on the mm grid and within ``max_mm``.  xyz (n, 3) float64 [m].  On the
    grid: ``rint(1000 v) * 1e-3 == v`` (the client's ``mm_to_m``, to the bit) and ``|rint(1000 v)| <
    max_mm``; NaN is off the grid."""
    for i in range(xyz.shape[0]):
        for j in range(3):
            v = xyz[i, j]
            k = np.rint(v * MM_PER_M)
            if not (abs(k) < max_mm) or k * 1e-3 != v:
                return False
    return True


@njit(cache=True)
def pack_grid_kernel(xyz, t_ns, t_ns_points, reflectivity, out):
    """Fill ``out`` (records x, y, z float32, age_ns int32, reflectivity uint8) from a frame on the mm
    grid (checked by :func:`grid_scan_kernel`): x = rint(2048 v) / 2048, age_ns = t_ns - point time."""
    for i in range(xyz.shape[0]):
        r = out[i]
        r.x = np.rint(xyz[i, 0] * 2048.0) / 2048.0
        r.y = np.rint(xyz[i, 1] * 2048.0) / 2048.0
        r.z = np.rint(xyz[i, 2] * 2048.0) / 2048.0
        r.age_ns = t_ns - t_ns_points[i]
        r.reflectivity = reflectivity[i]


assert GRID_PER_M == 2048.0     # the kernel's constant


def pack_points(xyz: np.ndarray, t_ns: int, t_ns_points: np.ndarray, reflectivity: np.ndarray) -> np.ndarray:
    """The packed points of one frame of time ``t_ns``: float32 on the mm grid when the frame is on
    it, float64 otherwise.  xyz (n, 3) float64 [m]; t_ns_points (n,) int64 (t_ns - t_ns_points within
    int32: the caller checks); reflectivity (n,) uint8.  Same bytes as ``pack_points_numpy`` of
    ``t_ns - t_ns_points``."""
    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    t_ns_points = np.ascontiguousarray(t_ns_points, dtype=np.int64)
    reflectivity = np.ascontiguousarray(reflectivity, dtype=np.uint8)
    if grid_scan_kernel(xyz, float(MAX_GRID_MM)):
        out = np.empty(xyz.shape[0], packed_point_dtype("float32"))
        pack_grid_kernel(xyz, np.int64(t_ns), t_ns_points, reflectivity, out)
        return out
    out = np.empty(xyz.shape[0], packed_point_dtype("float64"))
    out["x"], out["y"], out["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    out["age_ns"] = t_ns - t_ns_points
    out["reflectivity"] = reflectivity
    return out
