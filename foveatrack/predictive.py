"""Predictive controller option (beyond the paper): a constant-velocity filter on the target's
world bearing, feeding its rate forward so a crossing target is held in the fovea, not chased.

Per axis, state ``x = [theta, omega]`` (world bearing [deg], its rate [deg/s]); a measurement is
``theta_m = head_angle_est(t_d) + e_head(t_d)`` at the detection time ``t_d`` (head angle from the
reconstruction, error from :func:`foveatrack.control.head_errors_deg`).  Kalman filter with the
white-noise-acceleration model (FilterPy's ``Q_discrete_white_noise``, dim 2):

.. math:: F = \\begin{bmatrix}1 & \\Delta t\\\\ 0 & 1\\end{bmatrix},\\quad
          Q = q \\begin{bmatrix}\\Delta t^3/3 & \\Delta t^2/2\\\\ \\Delta t^2/2 & \\Delta t\\end{bmatrix},
          \\quad H = [1, 0],\\quad R = r

The commanded rate is

.. math:: v = \\hat\\omega + \\operatorname{deadband\\_p}(\\hat\\theta(t_a) - \\hat h(t_a))

with the dead band ``pred_deadband_deg`` (0.3 deg default; the paper's 2 deg would park the target
at the band's edge, since the feed-forward already keeps the head turning), and
where ``t_a`` is when the command will act (frame end + send delay + latency + dead time) and
``h`` the head angle predicted by the reconstruction.  The dead band applies to the *corrective*
term only: inside it the head still turns at the target's rate.  Pan innovations are wrapped to
(-180, 180]; the pan state is kept unwrapped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from foveatrack.detection import wrap_deg


@dataclass
class BearingFilter:
    """Constant-velocity Kalman filter on one bearing angle.

    q_deg2_s3 : float > 0  white-acceleration spectral density [deg^2/s^3]
    r_deg2 : float > 0     measurement variance [deg^2]
    wrap : bool            innovations wrapped to (-180, 180] (pan)
    """

    q_deg2_s3: float = 4.0
    r_deg2: float = 0.04
    wrap: bool = False
    x: np.ndarray | None = field(default=None, init=False)
    P: np.ndarray | None = field(default=None, init=False)
    t_s: float | None = field(default=None, init=False)
    n_updates: int = field(default=0, init=False)

    @property
    def initialised(self) -> bool:
        return self.x is not None

    def reset(self) -> None:
        self.x = self.P = self.t_s = None
        self.n_updates = 0

    def _predict_to(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """``(F x, F P F^T + Q)`` with ``F = [[1, dt], [0, 1]]`` and the white-acceleration
        ``Q = q [[|dt|^3/3, dt^2/2], [dt^2/2, |dt|]]``, written out on floats in a fixed order (a BLAS
        product's order differs per CPU: :mod:`foveatrack.fixed_order`; powers as products, not libm)."""
        dt = t_s - self.t_s
        adt = abs(dt)
        q = self.q_deg2_s3
        x0, x1 = self.x.tolist()
        (p00, p01), (p10, p11) = self.P.tolist()
        a00, a01 = p00 + dt * p10, p01 + dt * p11          # row 0 of F P (row 1 is P's)
        q01 = q * (adt * adt / 2)
        P = np.array([[a00 + a01 * dt + q * (adt * adt * adt / 3), a01 + q01],
                      [p10 + p11 * dt + q01, p11 + q * adt]])
        return np.array([x0 + dt * x1, x1]), P

    def update(self, t_s: float, theta_deg: float) -> None:
        if self.x is None:
            self.x = np.array([theta_deg, 0.0])
            self.P = np.diag([self.r_deg2, 100.0])   # rate unknown: 10 deg/s 1-sigma
            self.t_s = t_s
            self.n_updates = 1
            return
        x, P = self._predict_to(t_s)
        innov = theta_deg - x[0]
        if self.wrap:
            innov = wrap_deg(innov)
        S = P[0, 0] + self.r_deg2
        K = P[:, 0] / S
        self.x = x + K * innov
        self.P = P - np.outer(K, P[0, :])
        self.P = 0.5 * (self.P + self.P.T)
        self.t_s = t_s
        self.n_updates += 1

    def predict(self, t_s: float) -> tuple[float, float, float]:
        """(theta [deg], omega [deg/s], sigma_theta [deg]) at ``t_s`` (no state change)."""
        x, P = self._predict_to(t_s)
        return float(x[0]), float(x[1]), math.sqrt(max(P[0, 0], 0.0))
