"""How well the pose pairs determine the extrinsic ``X``: a 1-sigma never smaller than they allow.

Two estimates, and the larger is reported, per axis:

* the joint fit's linearised covariance (:func:`foveatrack.imu_calib.handeye.solve_handeye`): its
  weights are noise variances estimated from its own residuals, so the covariance is already scaled
  by the evidence; it is widened to the 90 % upper confidence bound of those variances
  (``dof / chi2_0.10(dof)``: with few residuals the scatter of the residuals can understate the
  noise by chance, and an uncertainty must not);
* Efron's bootstrap over the pairs (resampled with replacement, each resample solved the same way):
  it sees what the linearisation misses (uneven pairs, one pair pulling the fit) but understates the
  spread with few pairs.

With fewer than :data:`MIN_PAIRS_FOR_SIGMA` pairs there is no 1-sigma (NaN) and a warning says why:
with 2 pairs every bootstrap resample is either the full set (the same X) or one pair twice (one
axis, refused), so the bootstrap's spread was exactly 0 while the answer was 0.28 deg off (issue 27);
and 2 pairs leave the rotation's residuals nearly without redundancy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from foveatrack.imu_calib.handeye import DegenerateMotion, HandEyeResult, solve_handeye
from foveatrack.imu_calib.se3 import so3_log

#: Fewest pose pairs for which a 1-sigma is given (below: NaN and a warning).
MIN_PAIRS_FOR_SIGMA = 4
#: The covariance is widened to this one-sided upper confidence bound of the residuals' variance.
VARIANCE_CONFIDENCE = 0.90


@dataclass(frozen=True)
class Uncertainty:
    rotation_sigma_deg: np.ndarray    # (3,) 1-sigma of the rotation error vector, lidar frame (NaN: none)
    translation_sigma_m: np.ndarray   # (3,)
    samples: int                      # bootstrap resamples solved
    method: str = ""                  # what the figures are, in words (for the extrinsic file)

    @property
    def rotation_rss_deg(self) -> float:
        """1-sigma of the total rotation angle's error (root of the summed per-axis variances: the
        rms of the angle, the figure to set beside a total-angle error)."""
        return float(np.sqrt(np.sum(self.rotation_sigma_deg ** 2)))

    @property
    def translation_rss_m(self) -> float:
        return float(np.sqrt(np.sum(self.translation_sigma_m ** 2)))

    @property
    def given(self) -> bool:
        return bool(np.all(np.isfinite(self.rotation_sigma_deg)) and np.all(np.isfinite(self.translation_sigma_m)))


def _none(samples: int, why: str) -> Uncertainty:
    nan = np.full(3, np.nan)
    return Uncertainty(nan, nan, samples, why)


def bootstrap_sigma(A, B, X: np.ndarray, samples: int = 200, seed: int = 0, free=None, **solve_kw):
    """Per-axis 1-sigma of ``X`` by resampling the pose pairs with replacement (Efron's bootstrap);
    resamples whose motion is degenerate are skipped.  Returns (rotation [deg], translation [m],
    resamples solved); NaN with fewer than two."""
    rng = np.random.default_rng(seed)
    n = len(A)
    rot, tr = [], []
    for _ in range(samples):
        idx = rng.integers(0, n, n)
        try:
            r = solve_handeye([A[i] for i in idx], [B[i] for i in idx],
                              free=None if free is None else [free[i] for i in idx], **solve_kw)
        except DegenerateMotion:
            continue
        rot.append(np.degrees(so3_log(r.X[:3, :3] @ X[:3, :3].T)))
        tr.append(r.X[:3, 3] - X[:3, 3])
    if len(rot) < 2:
        return np.full(3, np.nan), np.full(3, np.nan), len(rot)
    return np.std(rot, axis=0, ddof=1), np.std(tr, axis=0, ddof=1), len(rot)


def linearised_sigma(he: HandEyeResult) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis 1-sigma of the joint fit (rotation [deg], translation [m]), widened to the upper
    confidence bound of the residual variance (module docstring)."""
    if he.covariance is None or he.dof < 1:
        return np.full(3, np.nan), np.full(3, np.nan)
    widen = he.dof / chi2.ppf(1.0 - VARIANCE_CONFIDENCE, he.dof)
    var = np.diag(he.covariance) * widen
    return np.degrees(np.sqrt(var[:3])), np.sqrt(var[3:])


def extrinsic_uncertainty(A, B, he: HandEyeResult, samples: int = 200, seed: int = 0, free=None,
                          **solve_kw) -> tuple[Uncertainty, list[str]]:
    """The reported 1-sigma of ``he.X`` from the pairs ``A, B`` it was solved from, and warnings.

    ``A, B`` (and ``free``, their unmeasured translation directions): the pairs the solver used
    (``he.used`` already applied).
    """
    n = he.pairs_used
    if n < MIN_PAIRS_FOR_SIGMA:
        why = (f"only {n} pose pair{'s' if n != 1 else ''} ({n + 1} poses): too few to tell how good the extrinsic is, "
               f"so no 1-sigma is given; it needs at least {MIN_PAIRS_FOR_SIGMA} pairs: use more poses")
        return _none(0, why), [why]
    lin_rot, lin_tr = linearised_sigma(he)
    if samples > 0:
        b_rot, b_tr, solved = bootstrap_sigma(A, B, he.X, samples, seed, free, **solve_kw)
    else:
        b_rot, b_tr, solved = np.full(3, np.nan), np.full(3, np.nan), 0
    rot = np.fmax(lin_rot, b_rot)
    tr = np.fmax(lin_tr, b_tr)
    method = (f"1-sigma per axis over {n} pose pairs: the larger of the joint fit's covariance (at the "
              f"{VARIANCE_CONFIDENCE:.0%} upper bound of its residuals' variance) and a bootstrap "
              f"({solved} resamples)")
    return Uncertainty(rot, tr, solved, method), []
