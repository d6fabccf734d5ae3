"""A frame's foreground points clustered into objects (single linkage with a gap that grows with
range: :func:`foveatrack.openloop.kernels.cluster_kernel`), each summarised for acquisition."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foveatrack.detection import frozen_maker


@dataclass(frozen=True)
class FrameObject:
    """One cluster: ``xyz_m`` the per-axis median of its points (Algorithm 1's estimator), its
    point count, the largest side of its bounding box and its range; ``sides_m`` the box's sides;
    ``t_median_ns`` the median of its points' times where they were given."""
    xyz_m: np.ndarray
    n_points: int
    extent_m: float
    range_m: float
    sides_m: np.ndarray | None = None
    t_median_ns: float | None = None


_make_frame_object = frozen_maker(FrameObject)   # FrameObject(...) without the frozen init's cost per field, per object


def cluster_labels(xyz: np.ndarray, tol_m: float, tol_rad: float) -> tuple[np.ndarray, int]:
    """Cluster labels (0.. in order of first point) and the number of clusters."""
    from foveatrack.openloop.kernels import cluster_kernel

    xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
    labels = np.empty(xyz.shape[0], dtype=np.int64)
    k = cluster_kernel(xyz, float(tol_m), float(tol_rad), labels)
    return labels, int(k)


def object_summaries(xyz: np.ndarray, labels: np.ndarray, n: int, min_points: int = 1,
                     max_extent_m: float = np.inf, t_ns: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The summaries :func:`objects_from_labels` makes its objects of, as arrays: the kept clusters'
    labels (k,), medians (k, 3), box sides (k, 3), point counts (k,) and median times [ns] (k,; with
    ``t_ns``, else unset).  The sky tracker builds its own objects of them, without a
    :class:`FrameObject` each."""
    from foveatrack.openloop.kernels import cluster_summary_kernel

    xyz = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 3)
    med = np.empty((n, 3))
    sides = np.empty((n, 3))
    count = np.empty(n, np.int64)
    t_med = np.empty(n)
    times = np.empty(0, np.int64) if t_ns is None else np.ascontiguousarray(t_ns, np.int64)
    cluster_summary_kernel(xyz, times, np.ascontiguousarray(labels, np.int64), int(n), int(min_points), med, sides,
                           count, t_med)
    # the kept clusters' summaries taken out at once (a frame's few objects each cost a handful of
    # numpy calls one by one): each median and box its own row of a fresh array
    big = np.flatnonzero(count >= min_points)
    kept = big[sides[big].max(axis=1) <= max_extent_m]
    return kept, med[kept], sides[kept], count[kept], t_med[kept]


def frame_objects(xyz: np.ndarray, t_ns: np.ndarray, tol_m: float, tol_rad: float, min_points: int,
                  max_extent_m: float, flag: np.ndarray, want_lone: bool
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """A frame's points clustered and summarised at once (the sky tracker's objects): the kept
    objects' medians (k, 3), box sides (k, 3), point counts (k,) and median times [ns] (k,) as
    :func:`object_summaries` gives them, per point its object (-1: none), per object how many of its
    points have ``flag`` (N,) set, and with ``want_lone`` the indices of the points alone in their
    cluster, without ``flag`` and in no object (else None).  One kernel
    (:func:`foveatrack.openloop.kernels.frame_objects_kernel`); twin :func:`frame_objects_numpy`."""
    from foveatrack.openloop.kernels import frame_objects_kernel

    n = xyz.shape[0]
    med, sides = np.empty((n, 3)), np.empty((n, 3))
    count, t_med = np.empty(n, np.int64), np.empty(n)
    point_obj, flagged, lone = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    k, m = frame_objects_kernel(np.ascontiguousarray(xyz, np.float64), np.ascontiguousarray(t_ns, np.int64),
                                float(tol_m), float(tol_rad), int(min_points), float(max_extent_m),
                                np.ascontiguousarray(flag, np.bool_), bool(want_lone), med, sides, count, t_med,
                                point_obj, flagged, lone)
    return med[:k], sides[:k], count[:k], t_med[:k], point_obj, flagged[:k], (lone[:m] if want_lone else None)


def frame_objects_numpy(xyz: np.ndarray, t_ns: np.ndarray, tol_m: float, tol_rad: float, min_points: int,
                        max_extent_m: float, flag: np.ndarray, want_lone: bool):
    """Twin of :func:`frame_objects`: :func:`cluster_labels`, :func:`object_summaries` and numpy."""
    labels, n = cluster_labels(xyz, tol_m, tol_rad)
    kept, meds, boxes, counts, t_med = object_summaries(xyz, labels, n, min_points, max_extent_m, t_ns)
    index = np.full(n, -1, np.int64)
    index[kept] = np.arange(kept.size)
    point_obj = index[labels]
    flagged = np.bincount(point_obj[flag & (point_obj >= 0)], minlength=kept.size)
    lone = None
    if want_lone:
        alone = np.bincount(labels, minlength=n)[labels] == 1
        lone = np.flatnonzero(alone & ~flag & (point_obj < 0))
    return meds, boxes, counts, t_med, point_obj, flagged, lone


def objects_from_labels(xyz: np.ndarray, labels: np.ndarray, n: int, min_points: int = 1,
                        max_extent_m: float = np.inf, t_ns: np.ndarray | None = None
                        ) -> tuple[list[FrameObject], list[int]]:
    """The clusters of at least ``min_points`` points and at most ``max_extent_m`` across (the
    drone-like ones; a scene's scattered returns make thousands of small clusters not worth a
    summary), and their labels; with ``t_ns`` (N,) each one's median time too.  The medians and
    extents come from :func:`foveatrack.openloop.kernels.cluster_summary_kernel`
    (:func:`object_summaries`)."""
    kept, meds, boxes, counts, t_med = object_summaries(xyz, labels, n, min_points, max_extent_m, t_ns)
    x, y, z = meds[:, 0], meds[:, 1], meds[:, 2]
    ranges = np.sqrt(x * x + y * y + z * z)          # norm3's sum, row by row
    times = [None] * kept.size if t_ns is None else t_med.tolist()
    out = [_make_frame_object(m, n_pts, e, r, s, t) for m, n_pts, e, r, s, t in
           zip(meds, counts.tolist(), boxes.max(axis=1).tolist(), ranges.tolist(), boxes, times)]
    return out, kept.tolist()
