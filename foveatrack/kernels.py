"""Numba kernels of the tracker's hot loops (the per-frame work of Algorithm 1 on every point).

Plain-numpy twins: the generic route of :mod:`foveatrack.detection` (``valid_points`` and
``Box.contains`` on points turned by :meth:`foveatrack.reconstruction.Reconstructor.lidar_to_world`);
``tests/tracker/test_detection_kernels.py`` compares the two.  The sky tracker
(:mod:`foveatrack.sky.tracks`) tests every point of a frame with the first two kernels: its frame of
a few thousand points took a dozen numpy passes for each test (~30 us each, where one pass takes a
few).  :func:`axis_angles_kernel` is the dead reckoning's (:mod:`foveatrack.reconstruction`) at a
frame's node instants, its twin ``_AxisIntegrator.angle`` (``tests/tracker/test_reconstruction.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def valid_point(x, y, z):
    """A point is finite and not exactly (0, 0, 0), Livox "no return" (the test of every kernel that
    drops invalid points; twin :func:`foveatrack.detection.valid_points`)."""
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z) and (x != 0.0 or y != 0.0 or z != 0.0)


@njit(cache=True)
def valid_mask_kernel(xyz, ok):
    """``ok[j]``: point ``j`` of ``xyz`` (N, 3) is valid (:func:`valid_point`; twin
    :func:`foveatrack.detection.valid_points`); returns how many are."""
    n = 0
    for j in range(xyz.shape[0]):
        v = valid_point(xyz[j, 0], xyz[j, 1], xyz[j, 2])
        ok[j] = v
        n += v
    return n


@njit(cache=True)
def box_inside_kernel(xyz, lo, hi, out_idx):
    """Indices of the points of ``xyz`` (N, 3) with ``lo <= p < hi`` on every axis, in point order
    (:meth:`foveatrack.space_of_interest.Box.contains`, its twin, and ``np.flatnonzero``); returns
    how many.  No validity test: a point that is not finite fails a comparison, as in the twin."""
    k = 0
    lo0, lo1, lo2 = lo[0], lo[1], lo[2]
    hi0, hi1, hi2 = hi[0], hi[1], hi[2]
    for j in range(xyz.shape[0]):
        x = xyz[j, 0]
        y = xyz[j, 1]
        z = xyz[j, 2]
        if (x >= lo0) & (x < hi0) & (y >= lo1) & (y < hi1) & (z >= lo2) & (z < hi2):
            out_idx[k] = j
            k += 1
    return k



@njit(cache=True)
def close_pairs_kernel(P, limit, out):
    """The pairs ``a < b`` of rows of ``P`` (N, 3) at most ``limit`` apart, in row-major order, into
    ``out`` (N (N - 1) / 2, 2); returns how many.  The distance as numpy's elementwise form sums it,
    ``sqrt((dx dx + dy dy) + dz dz)`` of ``P[a] - P[b]`` (twin: the distance matrix and
    ``np.argwhere``, ``tests/sky/test_sky_tracks.py``): the sky tracker's merge rule, ~20 confirmed
    tracks of a flock a frame, where the matrix took a dozen numpy calls."""
    k = 0
    n = P.shape[0]
    for a in range(n):
        for b in range(a + 1, n):
            dx = P[a, 0] - P[b, 0]
            dy = P[a, 1] - P[b, 1]
            dz = P[a, 2] - P[b, 2]
            if math.sqrt(dx * dx + dy * dy + dz * dz) <= limit:
                out[k, 0] = a
                out[k, 1] = b
                k += 1
    return k


@njit(cache=True)
def association_kernel(P, V, O, r_m2, gate_chi2, gate_max2, candidate, on_scenery, big, cost, allowed):
    """The sky tracker's gated costs (:meth:`foveatrack.sky.tracks.SkyTracker._associate`): for track
    ``i`` (predicted position ``P[i]``, its per-axis variances ``V[i]``) and object ``j`` (``O[j]``),
    ``cost[i, j]`` the squared Mahalanobis distance ``sum_a d_a^2 / (V[i, a] + r_m2)`` (``d = O[j] -
    P[i]``), ``allowed[i, j]`` whether it is at most ``gate_chi2``, the squared distance at most
    ``gate_max2`` and not a candidate seen off the scenery (``candidate[i]``) against an object on it
    (``on_scenery[j]``); a pair not allowed costs ``big``.  Returns how many pairs are allowed.  numpy's
    broadcast forms element for element, sums x, y, z in order (twin: ``tests/sky/test_sky_tracks.py``)."""
    n_allowed = 0
    for i in range(P.shape[0]):
        for j in range(O.shape[0]):
            dx = O[j, 0] - P[i, 0]
            dy = O[j, 1] - P[i, 1]
            dz = O[j, 2] - P[i, 2]
            dx2 = dx * dx
            dy2 = dy * dy
            dz2 = dz * dz
            c = dx2 / (V[i, 0] + r_m2) + dy2 / (V[i, 1] + r_m2) + dz2 / (V[i, 2] + r_m2)
            ok = (c <= gate_chi2) and (dx2 + dy2 + dz2 <= gate_max2) and not (candidate[i] and on_scenery[j])
            allowed[i, j] = ok
            cost[i, j] = c if ok else big
            n_allowed += ok
    return n_allowed


@njit(cache=True)
def in_field_kernel(P, rows, offset, cos_field, out):
    """``out[i]``: world point ``P[i]`` lies in the lidar's field, the cone of cosine ``cos_field``
    about its axis, at the pose of rotation ``rows`` (9, row by row) and ``offset`` (3,): ``q = R.T p
    - offset`` summed as :func:`foveatrack.fixed_order.mat3T_vec` sums it, ``|q| > 0`` and ``q_x >=
    cos_field |q|`` (the sky tracker's field test of its tracks, twice a track a frame; twin: the
    scalar form in ``tests/sky/test_sky_tracks.py``)."""
    for i in range(P.shape[0]):
        px = P[i, 0]
        py = P[i, 1]
        pz = P[i, 2]
        x = (rows[0] * px + rows[3] * py + rows[6] * pz) - offset[0]
        y = (rows[1] * px + rows[4] * py + rows[7] * pz) - offset[1]
        z = (rows[2] * px + rows[5] * py + rows[8] * pz) - offset[2]
        r = math.sqrt(x * x + y * y + z * z)
        out[i] = (r > 0) and (x >= cos_field * r)

@njit(cache=True)
def box_members_kernel(xyz, cos_pan, sin_pan, cos_tilt, sin_tilt, offset, lo, hi, out_idx):
    """Indices of the points inside an axis-aligned box D after the head's turn; returns how many.

    Point ``p`` (lidar frame) is tested as ``w = R (p + offset)`` against ``lo <= w < hi``
    (:class:`foveatrack.space_of_interest.Box`), with ``R = R_z(pan) R_y(-tilt)`` made from the
    pose's cosines and sines (:func:`foveatrack.reconstruction.head_trig`) entry by entry as
    :func:`foveatrack.reconstruction.rotation_matrix` makes it; ``(1, 0, 1, 0)`` and ``offset = 0``
    test it in the lidar frame.
    Points that are not finite or are exactly (0, 0, 0) (Livox "no return") never count.
    ``xyz`` (N, 3) C-contiguous; ``out_idx`` (N,) int64 receives the indices in point order.

    Two passes: the box test of every point without a branch (:func:`_box_mask`, which LLVM turns
    into vector code: ~4x faster than a test that stops at the first failing axis), then the
    validity test for the members only.  The same members as testing validity first: arithmetic
    on a non-finite point cannot raise here, its comparisons are False or its validity test
    rejects it.  Each point's test is its own, so the result does not depend on the vector width.
    """
    flat = xyz.reshape(-1)
    inside = np.empty(xyz.shape[0], dtype=np.uint8)
    _box_mask(flat, cos_pan, sin_pan, cos_tilt, sin_tilt, offset, lo, hi, inside)
    k = 0
    for j in range(inside.shape[0]):
        if inside[j]:
            x = flat[3 * j]
            y = flat[3 * j + 1]
            z = flat[3 * j + 2]
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                continue
            if x == 0.0 and y == 0.0 and z == 0.0:
                continue
            out_idx[k] = j
            k += 1
    return k


@njit(cache=True)
def _box_mask(flat, cos_pan, sin_pan, cos_tilt, sin_tilt, offset, lo, hi, inside):
    """``inside[j] = lo <= R (p_j + offset) < hi`` on every axis, for the points ``p_j`` stored
    row after row in ``flat`` (3N,).  Each coordinate is ``r0 * px + r1 * py + r2 * pz`` in that
    order (no fused multiply-add: numba does not contract without fastmath)."""
    cp, sp, ct, st = cos_pan, sin_pan, cos_tilt, sin_tilt
    r00, r01, r02 = cp * ct, -sp, -cp * st     # rotation_matrix's entries, the same products
    r10, r11, r12 = sp * ct, cp, -sp * st
    r20, r21, r22 = st, 0.0, ct
    o0, o1, o2 = offset[0], offset[1], offset[2]
    lo0, lo1, lo2 = lo[0], lo[1], lo[2]
    hi0, hi1, hi2 = hi[0], hi[1], hi[2]
    for j in range(inside.shape[0]):
        px = flat[3 * j] + o0
        py = flat[3 * j + 1] + o1
        pz = flat[3 * j + 2] + o2
        wx = r00 * px + r01 * py + r02 * pz
        wy = r10 * px + r11 * py + r12 * pz
        wz = r20 * px + r21 * py + r22 * pz
        inside[j] = (lo0 <= wx) & (wx < hi0) & (lo1 <= wy) & (wy < hi1) & (lo2 <= wz) & (wz < hi2)


@njit(cache=True)
def _median_select(a, n):
    """Median of ``a[:n]`` as numpy's (the middle value, or the mean of the middle two), by selection,
    reordering ``a``: Wirth's algorithm (N. Wirth, *Algorithms + Data Structures = Programs*, 1976, the
    procedure ``find``) puts the k-th smallest at ``a[k]`` with nothing larger before it, so the other
    middle value of an even count is the largest of ``a[:k]``.  O(n), and one pass where the values
    come in order (the time stamps).  The value equals a sort's (it is one of the inputs, or the mean
    of two) except for the sign of a zero, which :func:`box_median_kernel` flags.  numba compiles
    this in a fraction of the time its generic sort takes (the first run's compile, issue 30)."""
    k = n // 2
    lo, hi = 0, n - 1
    while lo < hi:
        x = a[k]
        i, j = lo, hi
        while True:
            while a[i] < x:
                i += 1
            while x < a[j]:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
            if i > j:
                break
        if j < k:
            lo = i
        if k < i:
            hi = j
    v = a[k]
    if n % 2:
        return v
    below = a[0]
    for q in range(1, k):
        if a[q] > below:
            below = a[q]
    return (below + v) / 2


@njit(cache=True)
def box_median_kernel(xyz, t_ns, cos_pan, sin_pan, cos_tilt, sin_tilt, offset, lo, hi, out_xyz):
    """Algorithm 1 with a box D in one call: the members of :func:`box_members_kernel` and their
    per-axis median position (into ``out_xyz`` (3,)) and median time.

    Returns ``(n, t_med_ns, hypot_xy)``: the number of members, the median of their ``t_ns`` as
    float64 and ``hypot(x, y)`` of the median (libm's ``hypot``, which ``np.hypot`` calls too: the
    bearing's elevation needs it; 0 members: ``(0, 0.0, 0.0)``).  ``n`` is returned negated when a
    median coordinate is zero: the sign of a zero median depends on how the sort orders -0.0 and
    +0.0 (:func:`_median_select`), which may differ from numpy's, so the caller then takes numpy's
    route for that frame.
    Plain-numpy twin: :func:`foveatrack.detection.detect_points` (``np.median`` per axis).
    """
    idx = np.empty(xyz.shape[0], dtype=np.int64)
    n = box_members_kernel(xyz, cos_pan, sin_pan, cos_tilt, sin_tilt, offset, lo, hi, idx)
    if n == 0:
        return 0, 0.0, 0.0
    col = np.empty(n, dtype=np.float64)
    zero = False
    for c in range(3):
        for j in range(n):
            col[j] = xyz[idx[j], c]
        v = _median_select(col, n)
        out_xyz[c] = v
        if v == 0.0:
            zero = True
    for j in range(n):
        col[j] = float(t_ns[idx[j]])
    t_med = _median_select(col, n)
    return (-n if zero else n), t_med, math.hypot(out_xyz[0], out_xyz[1])


@njit(cache=True)
def axis_angles_kernel(K, accel, has_accel, lo, hi, has_limits, wrap, ts, out, col, py):
    """One axis of the head's dead reckoning at each instant of ``ts``: ``out[i, col]`` the angle
    :meth:`foveatrack.reconstruction._AxisIntegrator.angle` gives (its twin; ``_advance``'s arithmetic
    in its order, pan wrapped as ``wrap_deg`` wraps a float).  ``K`` (m, 4): the knots' ``(t, angle,
    v, v_tgt)`` in time order, the first in force at the earliest of ``ts``; ``accel`` the speed's
    ramp if ``has_accel``; ``lo``, ``hi`` the stops if ``has_limits``.  A knot that reverses toward a
    stop is the kernel's where its deceleration clearly stops short of the stop (``_reversal_at_stop``'s
    test, ``reach <= g``, with ``m * m`` for its ``m ** 2`` and a margin of 1e-12 of the terms, far
    above the few ulps between libm's ``pow``, as CPython's ``**``, and the product); one that may
    reach the stop is left to the twin (``py[i]`` set).  Returns how many were."""
    m = K.shape[0]
    n_py = 0
    for i in range(ts.shape[0]):
        t = ts[i]
        j = m - 1                   # the knot in force: the last at or before t (bisect_right - 1)
        while j > 0 and K[j, 0] > t:
            j -= 1
        kt = K[j, 0]
        kang = K[j, 1]
        kv = K[j, 2]
        kvt = K[j, 3]
        tau = t - kt
        dv = kvt - kv
        if not has_accel or dv == 0.0:
            ang = kang + kvt * tau
        else:
            a = math.copysign(accel, dv)
            T = abs(dv) / accel
            if tau <= T:
                ang = kang + kv * tau + 0.5 * a * tau * tau
            else:
                ang = kang + kv * T + 0.5 * a * T * T + kvt * (tau - T)
        if has_limits:
            if has_accel and kv * kvt < 0.0:
                # _reversal_at_stop's "reach <= g" (its min and max as Python's: the first unless the
                # second is strictly less / greater); then its None: the motion above, clamped below
                stop = hi if kv > 0.0 else lo
                g = (1.0 if kv > 0.0 else -1.0) * (stop - kang)
                g = 0.0 if 0.0 > g else g
                u = abs(kv)
                t_turn = u / accel
                mt = t_turn if t_turn < tau else tau
                near = u * mt
                far = 0.5 * accel * (mt * mt)
                if not near - far + 1e-12 * (near + far) + 1e-300 <= g:
                    py[i] = True
                    n_py += 1
                    continue
            if ang > hi or ang < lo:
                ang = min(max(ang, lo), hi)
        if wrap and not (-180.0 < ang <= 180.0):
            w = np.fmod(ang + 180.0, 360.0)      # C fmod, as math.fmod
            w = (w + 360.0 if w < 0.0 else w) - 180.0
            ang = 180.0 if w == -180.0 else w
        out[i, col] = ang
    return n_py
