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
