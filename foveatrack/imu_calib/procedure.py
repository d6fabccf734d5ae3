"""The lidar-IMU calibration of paper Section IV.A on one sequence of static poses.

1. The IMU's relative motions ``B_i`` between consecutive poses (:mod:`.imu_integration`).
2. The lidar's ``A_i``: each pose's cloud accumulated for ``accumulate_s`` from the start of its
   static window, registered to the previous pose's (:mod:`.registration`), seeded with the IMU's
   motion mapped through the nominal mount ``X0`` (the drawing's; ICP only refines within its basin).
3. ``X`` from ``A_i X = X B_i`` (:mod:`.handeye`), with a bootstrap 1-sigma over the pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from foveatrack.errors import UserError
from foveatrack.imu_calib import handeye, registration
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
    uncertainty: handeye.Uncertainty
    A: list
    B: list
    handeye: handeye.HandEyeResult
    registrations: list
    imu: ImuMotion
    accumulate_s: float

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
    he = handeye.solve_handeye(A, motion.B, **handeye_kw)
    unc = handeye.bootstrap_uncertainty(A, motion.B, he.X, samples=bootstrap_samples, seed=seed, **handeye_kw)
    return CalibrationResult(he.X, unc, A, motion.B, he, regs, motion, accumulate_s)
