"""Numba kernel of the open-loop tracker's hot loop: clustering a frame's foreground points into
objects (:mod:`foveatrack.openloop.objects`).

Kept apart from :mod:`foveatrack.kernels` (Algorithm 1's kernels) so the two can change apart; the
same rules hold: arrays and scalars only, no fast-math, a plain-numpy twin compared in the tests
(``tests/openloop/test_cluster_kernel.py``: :func:`foveatrack.openloop.objects.cluster_labels_numpy`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@njit(cache=True)
def _link(xyz, r, i, j, tol_m, tol_rad, parent):
    """Join the clusters of points ``i`` and ``j`` if they are within the gap (see :func:`cluster_kernel`)."""
    dx = xyz[j, 0] - xyz[i, 0]
    dy = xyz[j, 1] - xyz[i, 1]
    dz = xyz[j, 2] - xyz[i, 2]
    d2 = dx * dx + dy * dy + dz * dz
    tol = tol_rad * min(r[i], r[j])
    if tol < tol_m:
        tol = tol_m
    if d2 <= tol * tol:
        a = _root(parent, i)
        b = _root(parent, j)
        if a != b:
            if a < b:
                parent[b] = a
            else:
                parent[a] = b


@njit(cache=True)
def cluster_kernel(xyz, tol_m, tol_rad, labels):
    """Single-linkage clusters of the points ``xyz`` (N, 3): points ``i`` and ``j`` are linked when

    .. math:: |p_i - p_j| \\le \\max(\\mathrm{tol\\_m},\\ \\mathrm{tol\\_rad} \\cdot \\min(|p_i|, |p_j|))

    (a gap that grows with range, as the beams spread), and a cluster is what links join.  Fills
    ``labels`` (N,) int64 with 0, 1, 2, ... numbered in the order of each cluster's first point, and
    returns the number of clusters.  Distances are compared squared, each a sum in the fixed order
    x, y, z.

    Only pairs in neighbouring cubes of side ``max(tol_m, tol_rad * max|p|)`` (no link is longer) are
    tested: points sorted by cube, the 27 cubes around each point found by binary search (nine: a
    column's three cubes are consecutive keys, scanned after one search -- 15 -> 9 us a frame).  Where the
    cube numbers would not fit an int64 (points ~1e18 cubes apart), every pair is tested.  The
    result does not depend on the order links are found: a cluster's root is its smallest index.
    """
    n = xyz.shape[0]
    parent = np.arange(n)
    r = np.empty(n)
    rmax = 0.0
    for i in range(n):
        r[i] = math.sqrt(xyz[i, 0] * xyz[i, 0] + xyz[i, 1] * xyz[i, 1] + xyz[i, 2] * xyz[i, 2])
        if r[i] > rmax:
            rmax = r[i]
    cell = tol_rad * rmax
    if cell < tol_m:
        cell = tol_m
    ok = n > 0 and math.isfinite(rmax)
    if ok:
        lo = np.empty(3)
        hi = np.empty(3)
        for c in range(3):
            lo[c] = xyz[0, c]
            hi[c] = xyz[0, c]
            for i in range(n):
                lo[c] = min(lo[c], xyz[i, c])
                hi[c] = max(hi[c], xyz[i, c])
        span = 1.0
        for c in range(3):
            span *= math.floor((hi[c] - lo[c]) / cell) + 3.0
        ok = span < 2.0 ** 62
    if ok:
        sy = np.int64(math.floor((hi[1] - lo[1]) / cell)) + 3
        sz = np.int64(math.floor((hi[2] - lo[2]) / cell)) + 3
        cx = np.empty(n, np.int64)
        cy = np.empty(n, np.int64)
        cz = np.empty(n, np.int64)
        key = np.empty(n, np.int64)
        for i in range(n):   # +1: a neighbour cube index of -1 stays >= 0
            cx[i] = np.int64(math.floor((xyz[i, 0] - lo[0]) / cell)) + 1
            cy[i] = np.int64(math.floor((xyz[i, 1] - lo[1]) / cell)) + 1
            cz[i] = np.int64(math.floor((xyz[i, 2] - lo[2]) / cell)) + 1
            key[i] = (cx[i] * sy + cy[i]) * sz + cz[i]
        order = np.argsort(key, kind="mergesort")
        skey = key[order]
        for i in range(n):
            for ax in range(-1, 2):
                for ay in range(-1, 2):
                    # cubes cz - 1 .. cz + 1 are consecutive keys (cz is 1 .. sz - 2): one search, the
                    # same pairs in the same order as one a cube (docstring)
                    k = ((cx[i] + ax) * sy + (cy[i] + ay)) * sz + (cz[i] - 1)
                    a = np.searchsorted(skey, k)
                    while a < n and skey[a] <= k + 2:
                        j = order[a]
                        if j > i:
                            _link(xyz, r, i, j, tol_m, tol_rad, parent)
                        a += 1
    else:
        for i in range(n):
            for j in range(i + 1, n):
                _link(xyz, r, i, j, tol_m, tol_rad, parent)
    k = 0
    for i in range(n):
        root = _root(parent, i)
        if root == i:
            labels[i] = k
            k += 1
        else:
            labels[i] = labels[root]
    return k


@njit(cache=True)
def _median_sorted(s, k):
    """numpy's median of the ``k`` sorted values ``s``: the middle one, or the mean of the middle two
    (``(a + b) / 2``, the float sum numpy's mean takes)."""
    h = k // 2
    if k % 2 == 1:
        return s[h]
    return (s[h - 1] + s[h]) / 2.0


@njit(cache=True)
def cluster_summary_kernel(xyz, t_ns, labels, n, min_points, med, sides, count, t_med):
    """Per cluster ``c < n`` of ``labels``: its point count ``count[c]`` and, if at least
    ``min_points``, the per-axis median of its points ``med[c]`` (numpy's ``np.median(pts, axis=0)``),
    the sides of their bounding box ``sides[c]`` (``pts.max(axis=0) - pts.min(axis=0)``) and, where
    ``t_ns`` gives every point's time (else it is empty), the median of their times ``t_med[c]`` [ns,
    as numpy's median of the int64 times gives it, a float].  A frame's clusters one after another
    where ``np.median`` took ~15 us a call (numpy twin: ``tests/openloop/cluster_twin.py``)."""
    sizes = np.zeros(n, np.int64)
    for i in range(labels.size):
        sizes[labels[i]] += 1
    start = np.zeros(n + 1, np.int64)
    for c in range(n):
        start[c + 1] = start[c] + sizes[c]
    fill = start[:n].copy()
    idx = np.empty(labels.size, np.int64)
    for i in range(labels.size):         # the points of each cluster in their order
        idx[fill[labels[i]]] = i
        fill[labels[i]] += 1
    big = 0
    for c in range(n):
        big = max(big, sizes[c])
    buf = np.empty(big)
    tbuf = np.empty(big)
    for c in range(n):
        k = sizes[c]
        count[c] = k
        if k < min_points or k == 0:
            continue
        for a in range(3):
            for j in range(k):
                buf[j] = xyz[idx[start[c] + j], a]
            s = np.sort(buf[:k])
            med[c, a] = _median_sorted(s, k)
            sides[c, a] = s[k - 1] - s[0]
        if t_ns.size == labels.size:
            for j in range(k):
                tbuf[j] = float(t_ns[idx[start[c] + j]])
            t_med[c] = _median_sorted(np.sort(tbuf[:k]), k)


@njit(cache=True)
def frame_objects_kernel(xyz, t_ns, tol_m, tol_rad, min_points, max_extent_m, flag, want_lone, med, sides, count,
                         t_med, point_obj, flagged, lone):
    """A frame's objects in one call (the sky tracker's, :meth:`foveatrack.sky.tracks.SkyTracker._objects`):
    :func:`cluster_kernel` on ``xyz`` (N, 3), :func:`cluster_summary_kernel`, and the clusters kept (at
    least ``min_points`` points, no side of the box over ``max_extent_m``) numbered in label order,
    their summaries moved to the first rows of ``med``, ``sides`` (N, 3), ``count``, ``t_med`` (N,).
    Per point ``point_obj[i]`` (N,) its object (-1: none); per object ``flagged`` (N,) how many of its
    points have ``flag`` (N,) set; with ``want_lone``, into ``lone`` (N,) the points alone in their
    cluster, without ``flag`` and in no object.  Returns (objects, lone points).  Numpy twin:
    :func:`foveatrack.openloop.objects.frame_objects_numpy` (one call where a dozen numpy calls and
    three kernels took ~35 us for a frame's few dozen points)."""
    n_pts = xyz.shape[0]
    labels = np.empty(n_pts, np.int64)
    n = cluster_kernel(xyz, tol_m, tol_rad, labels)
    cluster_summary_kernel(xyz, t_ns, labels, n, min_points, med, sides, count, t_med)
    index = np.empty(n, np.int64)
    size = count[:n].copy()         # each cluster's points, before the kept ones move up
    k = 0
    for c in range(n):
        index[c] = -1
        # (no side over: numpy's max of the three is NaN with a NaN, and NaN <= x is false, as here)
        if size[c] >= min_points and sides[c, 0] <= max_extent_m and sides[c, 1] <= max_extent_m \
                and sides[c, 2] <= max_extent_m:
            index[c] = k
            if k < c:               # rows move up only: row k is a dropped cluster's, or its own
                for a in range(3):
                    med[k, a] = med[c, a]
                    sides[k, a] = sides[c, a]
                count[k] = count[c]
                t_med[k] = t_med[c]
            k += 1
    for j in range(k):
        flagged[j] = 0
    m = 0
    for i in range(n_pts):
        o = index[labels[i]]
        point_obj[i] = o
        if o >= 0:
            if flag[i]:
                flagged[o] += 1
        elif want_lone and size[labels[i]] == 1 and not flag[i]:
            lone[m] = i
            m += 1
    return k, m
