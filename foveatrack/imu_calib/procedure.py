"""The lidar-IMU calibration of paper Section IV.A on one sequence of static poses.

1. The IMU's relative motions ``B_i`` between consecutive poses (:mod:`.imu_integration`).
2. The lidar's ``A_i``: each pose's cloud accumulated for ``accumulate_s`` from the start of its
   static window, registered to the previous pose's (:mod:`.registration`), seeded with the IMU's
   motion mapped through the nominal mount ``X0`` (the drawing's; ICP only refines within its basin).
   A translation direction the planes in view do not face (a level Horizon in a room sees walls but
   neither floor nor ceiling: the vertical) is not measured: ICP keeps the seed's value along it and
   the pair's translation equations are used only across it (``Registration.free_directions``).
3. The pairs checked against each other (:mod:`.pair_check`): a pair that disagrees with the
   others' extrinsic is registered again, seeded through that extrinsic instead of the nominal mount
   (a wrong nominal mount is the usual reason a registration slides), and removed if it still
   disagrees; every removal is named in a warning.
4. ``X`` from ``A_i X = X B_i`` over the kept pairs (:mod:`.handeye`, the joint weighted fit), with
   a 1-sigma never smaller than the pairs allow (:mod:`.uncertainty`) and warnings where the
   motions determine ``X`` poorly (too few pairs, rotation axes close together).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from foveatrack.errors import UserError
from foveatrack.imu_calib import handeye, pair_check, registration, uncertainty
from foveatrack.imu_calib.imu_integration import ImuMotion, ImuSamples, relative_motions
from foveatrack.imu_calib.se3 import inv_T, se3_log


@dataclass(frozen=True)
class PoseCloud:
    xyz_m: np.ndarray    # (N, 3) lidar frame, time order
    t_s: np.ndarray      # (N,) point times
    t0_s: float          # start of the static window the cloud was taken in


@dataclass(frozen=True)
class CalibrationResult:
    X: np.ndarray                      # T_lidar_imu
    uncertainty: uncertainty.Uncertainty
    A: list
    B: list
    handeye: handeye.HandEyeResult
    registrations: list
    imu: ImuMotion
    accumulate_s: float
    removed: list = field(default_factory=list)        # pair_check.RemovedPair, pairs left out of X
    reregistered: list = field(default_factory=list)   # pairs registered a second time (index)
    warnings: list = field(default_factory=list)       # what the user must hear, in words

    def consistency(self) -> np.ndarray:
        """Per pair ``|| Log(A_i) - Log(X B_i X^-1) ||`` with the registered ``A_i`` (eq. (8) without
        ground truth: what a real rig can report)."""
        Xi = inv_T(self.X)
        return np.array([np.linalg.norm(se3_log(a) - se3_log(self.X @ b @ Xi)) for a, b in zip(self.A, self.B)])


def accumulated(cloud: PoseCloud, accumulate_s: float) -> np.ndarray:
    return cloud.xyz_m[cloud.t_s < cloud.t0_s + accumulate_s]


def lidar_motions(clouds: list[PoseCloud], B: list, X0: np.ndarray, accumulate_s: float,
                  stages=registration.DEFAULT_STAGES, progress=None) -> list[registration.Registration]:
    """Registration of pose i+1's accumulated cloud onto pose i's, for every consecutive pair."""
    pts = [accumulated(c, accumulate_s) for c in clouds]
    for i, p in enumerate(pts):
        if len(p) < 100:
            raise UserError(f"pose {i}: {len(p)} lidar points in {accumulate_s:g} s; the scene gives the "
                            "lidar too little to register against (need at least 100)")
    X0i = inv_T(X0)
    models = [registration.CloudModel(p) for p in pts]
    out = []
    for i in range(len(pts) - 1):
        guess = X0 @ B[i] @ X0i
        out.append(registration.register(models[i + 1], models[i], guess, stages))
        models[i] = None   # its cells are no longer needed
        if progress is not None:
            progress.update(1)
    return out


def solve_pairs(A: list, B: list, bootstrap_samples: int = 200, seed: int = 0, free=None, **handeye_kw):
    """Screened pairs -> ``(HandEyeResult, Uncertainty, removed, warnings)``; ``HandEyeResult.used``
    indexes ``A``.  ``free``: per pair the translation directions its lidar motion did not measure
    (:attr:`.registration.Registration.free_directions`; None: all measured)."""
    def sub(idx):
        return None if free is None else [free[i] for i in idx]

    kept, removed = pair_check.screen_pairs(A, B, free, **handeye_kw)
    he = handeye.solve_handeye([A[i] for i in kept], [B[i] for i in kept], free=sub(kept), **handeye_kw)
    he = replace(he, used=np.asarray(kept, dtype=np.int64)[he.used])
    unc, warnings = uncertainty.extrinsic_uncertainty([A[i] for i in he.used], [B[i] for i in he.used], he,
                                                      samples=bootstrap_samples, seed=seed, free=sub(he.used),
                                                      **handeye_kw)
    warnings = [r.describe() for r in removed] + warnings
    if len(A) < pair_check.MIN_PAIRS_TO_CHECK:
        warnings.append(f"{len(A)} pose pairs cannot be checked against each other (a slid registration would go "
                        f"into the extrinsic unseen): use at least {pair_check.MIN_PAIRS_TO_CHECK + 1} poses")
    if he.axis_spread_deg < handeye.WEAK_AXIS_SPREAD_DEG:
        warnings.append(
            f"the pairs' rotation axes spread only {he.axis_spread_deg:.1f} deg (< {handeye.WEAK_AXIS_SPREAD_DEG:g}): the "
            "rotation about their common direction and the translation along it are weakly determined (see the "
            "1-sigma); turn the rig about axes further apart (pan, tilt and roll, or both head axes)")
    return he, unc, removed, warnings


def calibrate(clouds: list[PoseCloud], imu: ImuSamples, windows: list[tuple[float, float]],
              accumulate_s: float, X0: np.ndarray | None = None, bootstrap_samples: int = 200, seed: int = 0,
              imu_motion: ImuMotion | None = None, progress=None, **handeye_kw) -> CalibrationResult:
    """The extrinsic ``X = T_lidar_imu`` from static poses (see the module docstring)."""
    if len(clouds) != len(windows):
        raise ValueError(f"{len(clouds)} clouds for {len(windows)} static windows")
    X0 = np.eye(4) if X0 is None else X0
    motion = imu_motion or relative_motions(imu, windows)
    regs = lidar_motions(clouds, motion.B, X0, accumulate_s, progress=progress)
    A = [r.T for r in regs]
    free = [r.free_directions for r in regs]
    kept, removed = pair_check.screen_pairs(A, motion.B, free, **handeye_kw)
    again = []
    if removed:
        # Seed the disagreeing pairs through the others' extrinsic and register them again.
        X_kept = handeye.solve_handeye([A[i] for i in kept], [motion.B[i] for i in kept],
                                       free=[free[i] for i in kept], **handeye_kw).X
        Xi = inv_T(X_kept)
        for r in removed:
            i = r.index
            pts = [accumulated(clouds[k], accumulate_s) for k in (i, i + 1)]
            regs[i] = registration.register(pts[1], pts[0], X_kept @ motion.B[i] @ Xi)
            A[i], free[i] = regs[i].T, regs[i].free_directions
            again.append(i)
    he, unc, removed, warnings = solve_pairs(A, motion.B, bootstrap_samples, seed, free, **handeye_kw)
    gone = {r.index for r in removed}
    kept_again = [i for i in again if i not in gone]
    if kept_again:
        warnings.insert(0, f"pose pair{'s' if len(kept_again) > 1 else ''} {', '.join(str(i + 1) for i in kept_again)} "
                        "disagreed with the others until registered again from the fitted extrinsic (the nominal "
                        "mount seeded the registration too far off: give the drawing's mount)")
    return CalibrationResult(he.X, unc, A, motion.B, he, regs, motion, accumulate_s, removed, again, warnings)
