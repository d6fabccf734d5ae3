"""Plain-numpy twin of :func:`foveatrack.openloop.kernels.cluster_kernel` (all pairs at once, the
components by scipy), for the tests to compare against."""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def cluster_labels_numpy(xyz, tol_m, tol_rad):
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    n = xyz.shape[0]
    if n == 0:
        return np.empty(0, np.int64), 0
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    r = np.sqrt(x * x + y * y + z * z)
    dx = x[None, :] - x[:, None]
    dy = y[None, :] - y[:, None]
    dz = z[None, :] - z[:, None]
    d2 = dx * dx + dy * dy + dz * dz
    tol = np.maximum(tol_rad * np.minimum(r[:, None], r[None, :]), tol_m)
    i, j = np.nonzero(np.triu(d2 <= tol * tol, 1))
    g = coo_matrix((np.ones(i.size), (i, j)), shape=(n, n))
    k, comp = connected_components(g, directed=False)
    # number the clusters in the order of their first point, as the kernel does
    first = np.full(k, n)
    np.minimum.at(first, comp, np.arange(n))
    rank = np.empty(k, np.int64)
    rank[np.argsort(first)] = np.arange(k)
    return rank[comp], int(k)


def objects_from_labels_numpy(xyz, labels, n, min_points=1, max_extent_m=np.inf, t_ns=None):
    """Twin of :func:`foveatrack.openloop.objects.objects_from_labels` (numpy's median per cluster):
    ``(xyz_m, n_points, extent_m, sides_m, t_median_ns)`` per kept cluster, and the kept labels."""
    out, kept = [], []
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n + 1))
    sizes = np.diff(bounds)
    for c in np.flatnonzero(sizes >= min_points).tolist():
        rows = order[bounds[c]:bounds[c + 1]]
        pts = xyz[rows]
        med = np.median(pts, axis=0)
        sides = pts.max(axis=0) - pts.min(axis=0)
        ext = float(np.max(sides))
        if ext <= max_extent_m:
            out.append((med, int(pts.shape[0]), ext, sides, None if t_ns is None else float(np.median(t_ns[rows]))))
            kept.append(c)
    return out, kept
