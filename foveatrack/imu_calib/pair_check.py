"""Pose pairs checked against each other before the extrinsic is trusted (paper Section IV.A).

One registration that slides (issue 27: a 90 deg yaw mount with the identity as nominal mount, one
pair's registration 87 cm off) goes into a least-squares ``X`` in full: the translation came out
38 cm off and nothing said so.  Each pair is therefore predicted from all the others: ``X`` solved
without pair ``k`` (:func:`~foveatrack.imu_calib.handeye.solve_handeye`), and pair ``k``'s residuals
of ``A X = X B`` under it, rotation [rad] and translation [m], each divided by the typical
(median) residual of all pairs so predicted -- a leave-one-out residual, which a bad pair cannot hide
by pulling the fit towards itself.  The worst pair beyond :data:`MAX_SCORE` is removed, and the check
runs again on the rest, at most :data:`MAX_REMOVED_FRACTION` of the pairs in all.

Scale: for 3-vector residuals with per-axis noise ``s`` the median norm is 1.538 ``s``; the scale is
not taken below :data:`ROTATION_FLOOR_RAD` / :data:`TRANSLATION_FLOOR_M` (far below what a lidar
registers and an IMU integrates, 0.03-0.05 deg and 2-3 mm per pair; the floors only keep exact
synthetic data from flagging rounding).  The score combines both as ``sqrt((r_rot/s_rot)^2 +
(r_tr/s_tr)^2)``, a 6-degree-of-freedom chi: 6 is exceeded by chance once in 300 000 pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foveatrack.imu_calib.handeye import DegenerateMotion, pair_residuals, solve_handeye

MIN_PAIRS_TO_CHECK = 4          # with 3 pairs a bad one cannot be told from the two it spoils
MAX_SCORE = 6.0
MAX_REMOVED_FRACTION = 1 / 3
ROTATION_FLOOR_RAD = np.radians(0.005)
TRANSLATION_FLOOR_M = 0.0005
_MEDIAN_CHI3 = 1.538


@dataclass(frozen=True)
class RemovedPair:
    index: int                  # the pair (poses index and index + 1, counted from 0)
    score: float
    rotation_residual_deg: float
    translation_residual_m: float
    typical_rotation_deg: float     # the scale it was judged against (per-axis noise)
    typical_translation_m: float

    def describe(self) -> str:
        i = self.index
        return (f"pose pair {i + 1} (poses {i + 1}-{i + 2}) removed: its lidar and IMU motions disagree by "
                f"{self.rotation_residual_deg:.3f} deg and {self.translation_residual_m * 100:.1f} cm under the extrinsic "
                f"of the other pairs ({self.score:.0f} x their typical {self.typical_rotation_deg:.3f} deg / "
                f"{self.typical_translation_m * 100:.2f} cm): a registration that slid, or a pose that moved")


def leave_one_out_scores(A, B, idx: list[int], free=None,
                         **solve_kw) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Per pair of ``idx``: score, rotation residual [rad], translation residual [m] of the pair
    under the X of the others; and the scales (rotation [rad], translation [m]).  ``free``: per pair
    the translation directions its lidar motion did not measure (:func:`~.handeye.solve_handeye`)."""
    def sub(js):
        return None if free is None else [free[j] for j in js]

    r_rot = np.full(len(idx), np.inf)
    r_tr = np.full(len(idx), np.inf)
    for k, i in enumerate(idx):
        others = [j for j in idx if j != i]
        try:
            X = solve_handeye([A[j] for j in others], [B[j] for j in others], free=sub(others), **solve_kw).X
        except DegenerateMotion:
            continue     # the others alone cannot solve: this pair is needed, not judged
        rr, rt = pair_residuals(A[i], B[i], X, None if free is None else free[i])
        r_rot[k], r_tr[k] = np.linalg.norm(rr), np.linalg.norm(rt)
    finite = np.isfinite(r_rot)
    s_rot = max(float(np.median(r_rot[finite])) / _MEDIAN_CHI3, ROTATION_FLOOR_RAD) if finite.any() else np.inf
    s_tr = max(float(np.median(r_tr[finite])) / _MEDIAN_CHI3, TRANSLATION_FLOOR_M) if finite.any() else np.inf
    score = np.where(finite, np.hypot(r_rot / s_rot, r_tr / s_tr), 0.0)
    return score, r_rot, r_tr, s_rot, s_tr


def screen_pairs(A, B, free=None, **solve_kw) -> tuple[list[int], list[RemovedPair]]:
    """The indices of the pairs kept and the pairs removed (module docstring)."""
    idx = list(range(len(A)))
    removed: list[RemovedPair] = []
    max_removed = int(len(A) * MAX_REMOVED_FRACTION)
    while len(idx) >= MIN_PAIRS_TO_CHECK and len(removed) < max_removed:
        score, r_rot, r_tr, s_rot, s_tr = leave_one_out_scores(A, B, idx, free, **solve_kw)
        k = int(np.argmax(score))
        if not score[k] > MAX_SCORE:
            break
        removed.append(RemovedPair(idx[k], float(score[k]), float(np.degrees(r_rot[k])), float(r_tr[k]),
                                   float(np.degrees(s_rot)), float(s_tr)))
        del idx[k]
    return idx, removed
