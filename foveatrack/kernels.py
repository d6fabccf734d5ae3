"""Numba kernels of the tracker's hot loops (the per-frame work of Algorithm 1 on every point).

Plain-numpy twins: the generic route of :mod:`foveatrack.detection` (``valid_points`` and
``Box.contains`` on points turned by :meth:`foveatrack.reconstruction.Reconstructor.lidar_to_world`);
``tests/tracker/test_detection_kernels.py`` compares the two.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def box_members_kernel(xyz, rot, offset, lo, hi, out_idx):
    """Indices of the points inside an axis-aligned box D after a rigid turn; returns how many.

    Point ``p`` (lidar frame) is tested as ``w = rot @ (p + offset)`` against ``lo <= w < hi``
    (:class:`foveatrack.space_of_interest.Box`); ``rot = I, offset = 0`` tests it in the lidar frame.
    Points that are not finite or are exactly (0, 0, 0) (Livox "no return") never count.
    ``out_idx`` (N,) int64 receives the indices in point order.
    """
    k = 0
    for j in range(xyz.shape[0]):
        x = xyz[j, 0]
        y = xyz[j, 1]
        z = xyz[j, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        if x == 0.0 and y == 0.0 and z == 0.0:
            continue
        px = x + offset[0]
        py = y + offset[1]
        pz = z + offset[2]
        wx = rot[0, 0] * px + rot[0, 1] * py + rot[0, 2] * pz
        wy = rot[1, 0] * px + rot[1, 1] * py + rot[1, 2] * pz
        wz = rot[2, 0] * px + rot[2, 1] * py + rot[2, 2] * pz
        if lo[0] <= wx < hi[0] and lo[1] <= wy < hi[1] and lo[2] <= wz < hi[2]:
            out_idx[k] = j
            k += 1
    return k


def compile_all() -> None:
    """Compile (or load from numba's cache) every kernel here, on tiny inputs.

    A real-time driver calls this before data flows: a first call compiles, which takes up to a
    second on a fresh install and would stall the first frame.
    """
    box_members_kernel(np.zeros((1, 3)), np.eye(3), np.zeros(3), np.zeros(3), np.ones(3), np.empty(1, np.int64))
