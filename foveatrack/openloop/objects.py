"""A frame's foreground points clustered into objects (single linkage with a gap that grows with
range: :func:`foveatrack.openloop.kernels.cluster_kernel`), each summarised for acquisition."""

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
    from foveatrack.openloop.kernels import cluster_kernel

    xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
    labels = np.empty(xyz.shape[0], dtype=np.int64)
    k = cluster_kernel(xyz, float(tol_m), float(tol_rad), labels)
    return labels, int(k)


def objects_from_labels(xyz: np.ndarray, labels: np.ndarray, n: int, min_points: int = 1,
                        max_extent_m: float = np.inf) -> tuple[list[FrameObject], list[int]]:
    """The clusters of at least ``min_points`` points and at most ``max_extent_m`` across (the
    drone-like ones; a scene's scattered returns make thousands of small clusters not worth a
    summary), and their labels."""
    out, kept = [], []
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(n + 1))
    sizes = np.diff(bounds)
    for c in np.flatnonzero(sizes >= min_points).tolist():
        pts = xyz[order[bounds[c]:bounds[c + 1]]]
        med = np.median(pts, axis=0)
        ext = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
        if ext <= max_extent_m:
            out.append(FrameObject(med, int(pts.shape[0]), ext, norm3(med)))
            kept.append(c)
    return out, kept
