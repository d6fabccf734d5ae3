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
def cluster_kernel(xyz, tol_m, tol_rad, labels):
    """Single-linkage clusters of the points ``xyz`` (N, 3): points ``i`` and ``j`` are linked when

    .. math:: |p_i - p_j| \\le \\max(\\mathrm{tol\\_m},\\ \\mathrm{tol\\_rad} \\cdot \\min(|p_i|, |p_j|))

    (a gap that grows with range, as the beams spread), and a cluster is what links join.  Fills
    ``labels`` (N,) int64 with 0, 1, 2, ... numbered in the order of each cluster's first point, and
    returns the number of clusters.  Distances are compared squared, each a sum in the fixed order
    x, y, z; O(N^2) pairs: meant for the foreground left after the background is taken out.
    """
    n = xyz.shape[0]
    parent = np.arange(n)
    r = np.empty(n)
    for i in range(n):
        r[i] = math.sqrt(xyz[i, 0] * xyz[i, 0] + xyz[i, 1] * xyz[i, 1] + xyz[i, 2] * xyz[i, 2])
    for i in range(n):
        xi, yi, zi, ri = xyz[i, 0], xyz[i, 1], xyz[i, 2], r[i]
        for j in range(i + 1, n):
            dx = xyz[j, 0] - xi
            dy = xyz[j, 1] - yi
            dz = xyz[j, 2] - zi
            d2 = dx * dx + dy * dy + dz * dz
            tol = tol_rad * min(ri, r[j])
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
    k = 0
    for i in range(n):
        root = _root(parent, i)
        if root == i:
            labels[i] = k
            k += 1
        else:
            labels[i] = labels[root]
    return k
