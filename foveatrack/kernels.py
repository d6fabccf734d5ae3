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

    The box test comes first (most points of a frame are outside D) and the validity test only
    for the points inside: the same members as testing validity first, since arithmetic on a
    non-finite point cannot raise here and its validity test still rejects it.
    """
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    o0, o1, o2 = offset[0], offset[1], offset[2]
    lo0, lo1, lo2 = lo[0], lo[1], lo[2]
    hi0, hi1, hi2 = hi[0], hi[1], hi[2]
    k = 0
    for j in range(xyz.shape[0]):
        x = xyz[j, 0]
        y = xyz[j, 1]
        z = xyz[j, 2]
        px = x + o0
        py = y + o1
        pz = z + o2
        wx = r00 * px + r01 * py + r02 * pz
        if not lo0 <= wx < hi0:
            continue
        wy = r10 * px + r11 * py + r12 * pz
        if not lo1 <= wy < hi1:
            continue
        wz = r20 * px + r21 * py + r22 * pz
        if not lo2 <= wz < hi2:
            continue
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        if x == 0.0 and y == 0.0 and z == 0.0:
            continue
        out_idx[k] = j
        k += 1
    return k


@njit(cache=True)
def _median_sorted(s):
    """Median of a sorted 1-D array as numpy's: the middle value, or the mean of the middle two."""
    m = s.shape[0] // 2
    if s.shape[0] % 2:
        return s[m]
    return (s[m - 1] + s[m]) / 2


@njit(cache=True)
def box_median_kernel(xyz, t_ns, rot, offset, lo, hi, out_xyz):
    """Algorithm 1 with a box D in one call: the members of :func:`box_members_kernel` and their
    per-axis median position (into ``out_xyz`` (3,)) and median time.

    Returns ``(n, t_med_ns)``: the number of members and the median of their ``t_ns`` as float64
    (0 members: ``(0, 0.0)``).  ``n`` is returned negated when a median coordinate is zero: the
    sign of a zero median depends on how the sort orders -0.0 and +0.0, which may differ from
    numpy's, so the caller then takes numpy's route for that frame.
    Plain-numpy twin: :func:`foveatrack.detection.detect_points` (``np.median`` per axis).
    """
    idx = np.empty(xyz.shape[0], dtype=np.int64)
    n = box_members_kernel(xyz, rot, offset, lo, hi, idx)
    if n == 0:
        return 0, 0.0
    col = np.empty(n, dtype=np.float64)
    zero = False
    for c in range(3):
        for j in range(n):
            col[j] = xyz[idx[j], c]
        col.sort()
        v = _median_sorted(col)
        out_xyz[c] = v
        if v == 0.0:
            zero = True
    for j in range(n):
        col[j] = float(t_ns[idx[j]])
    col.sort()
    t_med = _median_sorted(col)
    return (-n if zero else n), t_med
