"""A frame's foreground points clustered into objects (single linkage with a gap that grows with
range: :func:`foveatrack.cluster_kernels.cluster_kernel`), each summarised for acquisition."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foveatrack.fixed_order import norm3


@dataclass(frozen=True)
class FrameObject:
    """One cluster: ``xyz_m`` the per-axis median of its points (Algorithm 1's estimator), its
    point count, the largest side of its bounding box and its range."""
    xyz_m: np.ndarray
    n_points: int
    extent_m: float
    range_m: float


def cluster_labels(xyz: np.ndarray, tol_m: float, tol_rad: float) -> tuple[np.ndarray, int]:
    """Cluster labels (0.. in order of first point) and the number of clusters."""
    from foveatrack.cluster_kernels import cluster_kernel

    xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
    labels = np.empty(xyz.shape[0], dtype=np.int64)
    k = cluster_kernel(xyz, float(tol_m), float(tol_rad), labels)
    return labels, int(k)


def objects_from_labels(xyz: np.ndarray, labels: np.ndarray, n: int) -> list[FrameObject]:
    out = []
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n + 1))
    for c in range(n):
        pts = xyz[order[bounds[c]:bounds[c + 1]]]
        med = np.median(pts, axis=0)
        ext = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
        out.append(FrameObject(med, int(pts.shape[0]), ext, norm3(med)))
    return out
