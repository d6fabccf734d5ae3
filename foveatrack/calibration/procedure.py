"""The calibration procedure: the state machine and the estimators (paper Appendix D.4).

"We calibrate the gimbal's rotation speed by tracking a pre-known feature point (e.g. a room corner)
in the lidar point cloud.  The calibration builds a lookup table mapping the command to actual
rotation speed."

Driver-agnostic state machine: the driver feeds every lidar frame to :meth:`Calibrator.step`, sends
the returned :class:`HeadCommand` (``None`` = keep the current, latched, command) and stops when
:attr:`Calibrator.done`; :meth:`Calibrator.result` returns the :class:`SpeedTable` and
:attr:`Calibrator.report` says what could not be measured and why.

Procedure
---------
1. Reference: head stopped, ``reference_s`` of frames locate the corner near ``FeatureSpec.approx_xyz``.
2. For each axis, for each byte of the plan, two legs: OUT (direction +1) until ``dwell_s`` has passed,
   the feature has turned ``max_excursion_deg`` from the reference or it is lost (three frames in a
   row without it, once ``settle_s`` has passed), stop, rest ``rest_s`` (longer, up to
   ``max_rest_s``, while the corner still turns); BACK (direction -1, same byte) until the feature
   is back at the reference (or, out of sight, as long as OUT lasted), stop, rest.  Both directions
   are measured and the head stays near its start.  An OUT leg stopped by the excursion with fewer
   than ``min_steady_samples`` frames after its ramp (a fast byte: ramp and stop fill the
   excursion) is run again after its BACK leg, from where that leg coasted to behind the start, and
   back (stopping a coast early to come home).
3. Return: the slowest usable byte brings each axis back to the reference, then stop; done.

Feature (per frame): points within ``radius_m`` of the predicted corner; three planes by sequential
RANSAC (seeded generator) refined by least squares (SVD); the corner is their intersection (solve
``N c = d``), accepted only if the normals are well separated.  Points are first de-rotated to the
frame's mean time with the leg's current rate estimate, so fast legs do not smear the planes.  Now
and then a corner comes out 0.05-0.3 m off (a plane taken from the wrong points); the online rate and
angle (de-rotation, excursion and return checks) are medians over the last samples
(:meth:`Calibrator._recent_motion`), and the estimate leaves such corners out (:func:`on_smooth_track`).

Estimate (batch, in :meth:`result`): the rotation axis of each head axis *in the lidar frame* is the
direction in which the corner positions do not move (smallest eigenvector of the pooled, per-leg
centred scatter of corner positions; falls back to the prior -- lidar Y for tilt, ``R_y(t0) z`` for pan
-- if the legs are too short to tell; :class:`PriorAxisCalibrator` combines the two, and warns and
uses the data alone when they contradict the prior).  This makes pan calibration independent of the
unknown start tilt (an error of cos(tilt) otherwise).  The angle of the corner about that axis is fitted against the
corner's time by least squares over the steady part of each leg (after ``settle_s``, and never
before the leg's ramp has ended, :func:`fit_ramp`; the corners off the leg's smooth track left out,
here and in the axis scatter):

.. math:: \\theta(t) = a + b\\,t,\\quad \\hat v = \\mp b,\\quad
          \\sigma_{\\hat v} = \\sqrt{\\frac{\\sum r_i^2/(n-2)}{\\sum (t_i-\\bar t)^2}}

(pan: the corner turns the opposite way about world-up in lidar coordinates).  The legs of each
direction, then the two directions are combined by inverse-variance weighting; half the directions'
difference (asymmetry) is added in quadrature to the uncertainty.  The line's crossing of the reference angle, minus the command time,
is the entry's effective delay ``dead_time + v / (2 a)``; a line through those delays gives the dead
time and acceleration written into the table.  Lidar origin is assumed on (or near, relative to the
corner distance) the rotation axes only for the *online* excursion check; the estimate itself does
not depend on it.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np

from foveatrack.calibration.corner import _SIGN, _angle_about, _angle_about_unwrapped, _rotate_about, find_corner
from foveatrack.calibration.plan import CalibrationPlan, CalibrationReport, FeatureSpec, LegRecord
from foveatrack.control import STOP, HeadCommand
from foveatrack.detection import valid_points
from foveatrack.errors import UserError
from foveatrack.frames import Frame
from foveatrack.speed_table import TURBO, AxisTable, SpeedEntry, SpeedTable, axis_bytes


#: The corner's angle noise about an axis, 1 sigma [deg] (about 5 mm at 6 m), and how long the tilt
#: may be driven with the corner out of sight before its estimate is void [s] (a leg ends after three
#: missed frames once settled; before, up to ``settle_s`` of its ramp may pass unseen).
TILT_CORNER_SIGMA_DEG = 0.1
TILT_UNSEEN_MAX_S = 1.0

#: Above this chi-square (2 degrees of freedom) a head axis's prior and the corner data disagree
#: (:meth:`PriorAxisCalibrator._axis_fit`): were both right, it is exceeded with probability
#: ``exp(-13.8 / 2) = 0.001``.  In simulation the statistic runs far below its nominal law (the
#: first-order data sigma is conservative): 0.01-0.94 for the pan axis over 11 runs with the right
#: start tilt, while a start tilt 10 deg off gave 16, 13.5 deg off 22-28 and 28.5 deg off 21-39 (a
#: wrong prior also spoils the procedure's online de-rotation, which widens the data's sigma).
PRIOR_CONFLICT_CHI2 = 13.8
#: The same p = 0.001 for one angle alone (chi-square, 1 degree of freedom): which of the pan prior's
#: two angles, the start tilt and the lean toward lidar Y, the data contradict
#: (:meth:`AxisFit.start_tilt_and_lean_chi2`).
PRIOR_CONFLICT_CHI2_1DOF = 10.8


def on_smooth_track(t_s: np.ndarray, q_m: np.ndarray, n_sigma: float = 5.0, floor_m: float = 1e-3,
                    min_n: int = 10, max_rounds: int = 5) -> np.ndarray:
    """Which corner positions of a steady leg lie on its smooth track (bool mask); the others are
    wrong corners (a plane RANSAC took from the wrong points), 0.05-0.3 m off where the noise is ~5 mm.

    t_s : (n,) [s] increasing; q_m : (n, 3) [m] corner positions (lidar frame)
    n_sigma : > 0, the cut in robust standard deviations; floor_m : > 0 [m], the least scale (exact
    synthetic corners); min_n >= 6: fewer positions are all kept (a median of fewer residuals of a
    3-parameter fit is no scale).

    The track is a quadratic in time per coordinate (a constant-rate arc of <= 15 deg at any radius
    departs from it by < 1 mm; the head's speed ripple adds < 1 cm at 35 deg/s), fitted by least
    squares to the positions kept so far; the scale per coordinate is 1.4826 x the median absolute
    deviation of their residuals (consistent with the standard deviation for Gaussian noise, and
    unmoved by a minority of outliers: Rousseeuw & Croux, JASA 88 (1993) 1273).  Positions whose
    residual exceeds ``n_sigma`` scales in any coordinate are dropped and the fit repeated until the
    set stops changing (at most ``max_rounds`` times).  Why it matters: one such corner among the ~90
    of two tilt legs made their scatter look like a curved arc and turned the estimated tilt axis
    (9-23 deg in 6 of 40 simulated runs of a one-byte plan, 22 deg with every tilt speed 2.5-4 % high
    in 3 of them; the same on the live rig).
    """
    t = np.asarray(t_s, float)
    q = np.asarray(q_m, float)
    keep = np.ones(len(t), bool)
    if len(t) < min_n:
        return keep
    tc = t - t.mean()
    V = np.column_stack([np.ones_like(tc), tc, tc * tc])
    for _ in range(max_rounds):
        coef, *_ = np.linalg.lstsq(V[keep], q[keep], rcond=None)
        res = q - V @ coef
        med = np.median(res[keep], axis=0)
        scale = np.maximum(1.4826 * np.median(np.abs(res[keep] - med), axis=0), floor_m)
        new = np.all(np.abs(res - med) <= n_sigma * scale, axis=1)
        if new.sum() < min_n or np.array_equal(new, keep):
            break
        keep = new
    return keep


def fit_ramp(t_s: np.ndarray, ang_deg: np.ndarray, t_from_s: float, min_n: int = 6,
             min_speed_deg_s: float = 0.2) -> tuple[float, float, float, float] | None:
    """The ramp of one leg: ``(t_end_s, v_deg_s, a_deg_s2, t0_s)``, where the head reaches its speed
    (``t_end_s = t0 + |v| / a``), or None (fewer than ``min_n`` samples, slower than
    ``min_speed_deg_s``, or no fit).

    t_s : (n,) [s] increasing, the leg's sample times from its command on; ang_deg : (n,) [deg] the
    corner's angle about the (prior) axis; t_from_s [s]: the command's arrival (command time +
    link latency): the head cannot move before it.

    The head's model of App. D.4 timing (as in :class:`PriorAxisCalibrator`'s timing fit and
    :mod:`foveatrack.reconstruction`): still until ``t0`` (arrival + dead time), then constant
    acceleration ``a`` up to the speed ``v``:

    .. math:: \\theta(t) = \\theta_0 + \\mathrm{sgn}(v)\\,g(t - t_0),\\quad
              g(\\tau) = \\begin{cases} 0 & \\tau < 0 \\\\ a\\tau^2/2 & \\tau < |v|/a \\\\
              |v|(\\tau - |v|/(2a)) & \\text{else} \\end{cases}

    fitted by scipy ``least_squares`` (soft-L1 loss, scale 0.05 deg: the corner's noise, so a wrong
    corner 0.5-3 deg off does not move it) from four starting accelerations (5-300 deg/s^2), the best
    kept.  A leg whose ramp had not ended when it stopped fits any ``|v| / a`` reaching past its last
    sample: ``t_end_s`` then lies at or after it, and the leg has no steady part (which is the
    truth: the seed-2 PTS-303 turbo legs of a 15 deg excursion read 9 % low from their ramp's tail).
    """
    from scipy.optimize import least_squares

    t = np.asarray(t_s, float)
    y = np.asarray(ang_deg, float)
    if len(t) < min_n:
        return None
    k = max(3, len(t) // 3)
    v0 = float(np.polyfit(t[-k:], y[-k:], 1)[0])
    if not abs(v0) >= min_speed_deg_s:
        return None
    tc = t - t_from_s

    def resid(p):
        th0, t0, v, la = p
        a = math.exp(la)
        tau = tc - t0
        tr = abs(v) / a
        g = np.where(tau < 0, 0.0, np.where(tau < tr, 0.5 * a * tau ** 2, abs(v) * (tau - 0.5 * tr)))
        return y - (th0 + math.copysign(1.0, v) * g)

    best = None
    lo = [-np.inf, 0.0, -np.inf, math.log(0.5)]
    hi = [np.inf, max(float(tc[-1]), 1e-3), np.inf, math.log(5000.0)]
    for a0 in (5.0, 20.0, 80.0, 300.0):
        x0 = [float(y[0]), min(0.05, 0.5 * hi[1]), v0, math.log(a0)]
        try:
            fit = least_squares(resid, x0, loss="soft_l1", f_scale=0.05, bounds=(lo, hi))
        except ValueError:
            continue
        if fit.success and (best is None or fit.cost < best.cost):
            best = fit
    if best is None:
        return None
    _, t0, v, la = best.x
    a = math.exp(la)
    return float(t_from_s + t0 + abs(v) / a), float(v), float(a), float(t_from_s + t0)


def _axis_command(axis: str, direction: int, byte: int) -> HeadCommand:
    """Turn one axis (``"pan"`` or ``"tilt"``) at ``byte`` in ``direction``, the other still."""
    return HeadCommand(direction, byte, 0, 0) if axis == "pan" else HeadCommand(0, 0, direction, byte)


def _coast_deg(rate_deg_s: float, frame_s: float) -> float:
    """The turn [deg] a leg allows for after a stop sent now at ``rate_deg_s``: a frame and 0.15 s at
    the rate (the frame, dead time), then ``rate^2 / (2 * 100 deg/s^2)`` of deceleration."""
    return abs(rate_deg_s) * (frame_s + 0.15) + rate_deg_s * rate_deg_s / (2 * 100.0)


def _leg_samples(leg: LegRecord) -> tuple[list[int], np.ndarray, np.ndarray]:
    """A leg's samples from its command to its stop (to now while it runs): their indices in
    ``leg.samples``, times (n,) [s] and corner positions (n, 3) [m]."""
    stop = math.inf if leg.t_stop_s is None else leg.t_stop_s
    idx = [i for i, (t, _) in enumerate(leg.samples) if leg.t_cmd_s < t <= stop]
    return (idx, np.array([leg.samples[i][0] for i in idx], dtype=float),
            np.array([leg.samples[i][1] for i in idx], dtype=float).reshape(-1, 3))


@dataclass(frozen=True)
class AxisFit:
    """One head axis in the lidar frame, as :meth:`PriorAxisCalibrator._axis_fit` found it.

    name : ``"pan"`` or ``"tilt"``
    axis : (3,) unit   the estimate the table is measured about
    prior : (3,) unit  the assumed axis (pan: ``R_y(start_tilt) z``; tilt: lidar Y)
    data_axis : (3,) unit or None   the corner data's own axis (sign toward the prior); None: too few
        samples to tell
    data_cov : (3, 3) or None [rad^2]  its covariance, first order (in the plane normal to it)
    chi2 : float >= 0 or None   the prior against the data (see :class:`PriorAxisCalibrator`)
    degenerate : bool  the data do not determine the axis (``w0 / w1 > 0.25``, or too few samples)
    """

    name: str
    axis: np.ndarray
    prior: np.ndarray
    data_axis: np.ndarray | None
    data_cov: np.ndarray | None
    chi2: float | None
    degenerate: bool

    @property
    def conflict(self) -> bool:
        """The prior and the data cannot both be right (``chi2 > PRIOR_CONFLICT_CHI2``)."""
        return self.chi2 is not None and self.chi2 > PRIOR_CONFLICT_CHI2

    def implied_start_tilt_deg(self) -> tuple[float, float, float, float]:
        """The pan axis of the data as a start tilt: ``(tilt, sigma, lean, sigma)`` [deg], where the
        axis is ``(cos(lean) sin(tilt), sin(lean), cos(lean) cos(tilt))`` (the lean toward lidar Y is
        what no start tilt explains) and the sigmas are the covariance's along those two angles."""
        a = self.data_axis
        t = math.atan2(a[0], a[2])
        lean = math.asin(max(-1.0, min(1.0, float(a[1]))))
        e_t = np.array([math.cos(t), 0.0, -math.sin(t)])
        e_l = np.cross(e_t, a)
        e_l /= max(np.linalg.norm(e_l), 1e-12)
        sig = [math.degrees(math.sqrt(max(float(e @ self.data_cov @ e), 0.0))) for e in (e_t, e_l)]
        return math.degrees(t), sig[0], math.degrees(lean), sig[1]

    def start_tilt_and_lean_chi2(self, start_tilt_deg: float, prior_sigma_deg: float) -> tuple[float, float]:
        """The pan prior's two angles tested one at a time: ``(start tilt, lean)``, the chi-square (1
        degree of freedom) of the configured ``start_tilt_deg`` with whatever lean fits best, and of no
        lean toward lidar Y with whatever start tilt fits best.  The 2-degree test (``chi2``) says the
        prior is wrong; these say which part of it: a start tilt off turns the pan axis in the lidar's
        XZ plane, a lidar rolled on the head leans it toward lidar Y, which no start tilt explains.

        Both are the 2-degree statistic ``p^T W p`` (``W``: the inverse of the data's covariance plus
        the prior's ``prior_sigma_deg`` [deg], in the plane normal to the data's axis) minimised over
        the free angle: with ``p = cos(f) e1 + sin(f) e2`` that is the smaller eigenvalue of the
        2 x 2 form ``[e1 e2]^T W [e1 e2]``, exact for any size of angle (the implied tilt and lean
        are first-order: with degenerate scatter they came out 40-90 deg off and their one-angle
        tests contradicted the 2-degree one, 33 and 194 against 13.7)."""
        a = self.data_axis
        S = self.data_cov + math.radians(prior_sigma_deg) ** 2 * (np.eye(3) - np.outer(a, a))
        lam, vec = np.linalg.eigh(S)        # the smallest: the data's axis, no variance
        W = sum(np.outer(vec[:, k], vec[:, k]) / lam[k] for k in (1, 2))
        t = math.radians(start_tilt_deg)
        at_start_tilt = np.column_stack([[math.sin(t), 0.0, math.cos(t)], [0.0, 1.0, 0.0]])   # any lean
        no_lean = np.column_stack([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])                          # any tilt
        return tuple(float(np.linalg.eigvalsh(B.T @ W @ B)[0]) for B in (at_start_tilt, no_lean))


class Calibrator:
    """State machine for Appendix D.4 (see module docstring).

    ``step(frame) -> HeadCommand | None``; ``done``; ``result() -> SpeedTable``; ``report``.
    """

    def __init__(self, plan: CalibrationPlan, feature: FeatureSpec, *, seed: int = 0, head: str = "",
                 date: str | None = None):
        self.plan = plan
        self.feature = feature
        self.rng = np.random.default_rng(seed)
        self.head = head
        self.date = date
        self.frames = 0
        self.frames_with_feature = 0
        self.legs: list[LegRecord] = []
        # (axis, byte, direction, repeat)
        self._queue = [(a, b, d, False) for a, bs in (("pan", plan.pan_bytes), ("tilt", plan.tilt_bytes))
                       for b in bs for d in (+1, -1)]
        self._phase = "reference"
        self._phase_t0: float | None = None
        self._ref_samples: list = []
        self._ref_q: np.ndarray | None = None      # corner at the very start
        self._last_q: np.ndarray | None = None
        self._last_t: float | None = None           # when the corner was last seen (sensor time) [s]
        self.start_tilt_sigma_deg = 0.5              # how well plan.start_tilt_deg is known [deg]
        self._rest_samples: list = []
        self._rest_t: list = []
        self._leg: LegRecord | None = None
        self._out_duration = 0.0
        self._missed = 0
        self._return_axis = None
        self._ramp_cache: dict = {}
        self._derot_deg_s = 0.0     # the rate the last frame's points were de-rotated with
        self._recentre = False      # the return phase brings one axis home before the other's legs
        self._recentre_side = 1.0
        self._recentred = False
        self.report: CalibrationReport | None = None
        self.failure: str | None = None
        self._pan_prior = np.array([math.sin(math.radians(plan.start_tilt_deg)), 0.0,
                                    math.cos(math.radians(plan.start_tilt_deg))])

    @property
    def done(self) -> bool:
        return self._phase == "done"

    # ---- online helpers --------------------------------------------------------------------
    def _prior_axis(self, axis: str) -> np.ndarray:
        return self._pan_prior if axis == "pan" else np.array([0.0, 1.0, 0.0])

    def _online_angle(self, axis: str, q: np.ndarray) -> float:
        """Head rotation since the start reference, approximately (for the excursion check)."""
        return _SIGN[axis] * float(_angle_about(q[None, :], self._prior_axis(axis), self._ref_q)[0])

    def _recent_motion(self, leg: LegRecord, n_rates: int = 3,
                       max_jump_deg_s: float = 5.0) -> tuple[float, float, float]:
        """``(t_s, angle_deg, rate_deg_s)``: the corner's angle about the leg's prior axis (from the
        start reference, not signed as a head angle) at its latest sample and its rate, from the last
        ``n_rates + 1`` samples (at least 2).

        The rate is the newest sample-to-sample rate (it follows a ramp without lag) unless it
        differs from the median of the last ``n_rates`` by more than ``max_jump_deg_s`` [deg/s] (a
        ramp changes it by 2 deg/s a 50 ms frame at 40 deg/s^2), then that median; the angle is the
        median of the samples carried to the latest time at that rate.  So one wrong corner among
        them moves neither: a corner found 0.1-0.3 m off (RANSAC on ~700 points now and then takes
        a wrong plane) read as 30-50 deg/s from the last two samples alone, which ended the leg at
        once (the excursion's coasting distance) or de-rotated the next frames so far that the
        corner was lost three times running (the leg ended with too few samples: a byte unmeasured).
        """
        recent = leg.samples[-(n_rates + 1):]
        t = np.array([x for x, _ in recent])
        ang = _angle_about_unwrapped(np.array([q for _, q in recent]), self._prior_axis(leg.axis), self._ref_q)
        rates = np.diff(ang) / np.maximum(np.diff(t), 1e-6)
        rate = float(np.median(rates))
        if abs(rates[-1] - rate) <= max_jump_deg_s:
            rate = float(rates[-1])   # the newest, which does not lag a ramp (40 deg/s^2: 2 deg/s a frame)
        return float(t[-1]), float(np.median(ang + rate * (t[-1] - t))), rate

    def _measure(self, frame: Frame) -> tuple[float, np.ndarray] | None:
        if self._last_q is None:
            center = np.asarray(self.feature.approx_xyz, float)
        else:
            center = self._last_q
        ok = valid_points(frame.xyz)
        xyz, t_s = frame.xyz[ok], frame.t_ns[ok] * 1e-9
        if xyz.shape[0] == 0:
            return None
        t_mid = float(t_s.mean())
        leg = self._leg
        self._derot_deg_s = 0.0
        if leg is not None and self._phase == "move" and len(leg.samples) >= 2:
            # de-rotate points to t_mid with the leg's current rate about the prior axis
            tb, _, w = self._recent_motion(leg)                         # deg/s of the corner
            self._derot_deg_s = w
            ax = self._prior_axis(leg.axis)
            xyz = _rotate_about(xyz, ax, np.radians(-w * (t_s - t_mid)))
            center = _rotate_about(center[None], ax, np.radians([w * (t_mid - tb)]))[0]
        found = find_corner(xyz, center, self.feature, self.rng)
        if found is None and self._phase == "rest" and leg is not None and len(leg.samples) >= 2:
            # the head coasts after a fast leg's stop (dead time, then the deceleration: 8 deg after
            # 23 deg/s); look along the arc up to a coast at 10 deg/s^2
            _, _, w = self._recent_motion(leg)
            reach = abs(w) * 0.1 + w * w / (2 * 10.0)
            if reach > 0.5 * self.feature.radius_m / max(float(np.linalg.norm(center)), 1e-3) * 57.3:
                ax = self._prior_axis(leg.axis)
                for frac in (0.25, 0.5, 0.75, 1.0):
                    c = _rotate_about(center[None], ax, np.radians([math.copysign(frac * reach, w)]))[0]
                    found = find_corner(xyz, c, self.feature, self.rng)
                    if found is not None:
                        break
        if found is None and self._missed >= 1 and self._ref_q is not None:
            found = find_corner(xyz, self._ref_q, self.feature, self.rng)   # lost: look near home
        if found is None:
            return None
        corner, _ = found
        return t_mid, corner

    def start_tilt_deg(self) -> tuple[float, float, bool]:
        """The head's tilt at the start [deg], its 1 sigma [deg], and whether the corner data gave it
        (False: the plan's ``start_tilt_deg``): what the command gate's tilt estimate counts from
        (:class:`foveatrack.calibration.drive.CalibrationDriver`).  Here always the plan's."""
        return self.plan.start_tilt_deg, self.start_tilt_sigma_deg, False

    def tilt_since_start_deg(self, t_s: float) -> tuple[float, float, float | None]:
        """The head's tilt at ``t_s`` relative to the start reference as the corner shows it, its 1-sigma
        uncertainty [deg] (for the command gate's tilt stops), and when the corner was seen [s] (None:
        no need, the head has not moved); NaN without any sighting.

        Before the reference is taken the head has been sent nothing but STOP: 0.  On a tilt leg the
        leg's robust recent angle and rate (:meth:`_recent_motion`) carried to ``t_s``; otherwise the
        corner's angle about the tilt axis at its last sighting.  The uncertainty: the corner's noise
        plus the extrapolation (its rate times the time since the sighting).  How long the tilt was
        driven since the sighting is the driver's to judge (:class:`foveatrack.calibration.drive.CalibrationDriver`):
        pan legs leave the tilt where it was, however long the corner is out of sight."""
        if self._ref_q is None:
            return 0.0, 0.0, None
        leg = self._leg
        if self._phase == "move" and leg is not None and leg.axis == "tilt" and len(leg.samples) >= 2:
            t, a, w = self._recent_motion(leg)
            ang, rate = _SIGN["tilt"] * a, _SIGN["tilt"] * w
        elif self._last_q is not None and self._last_t is not None:
            t, ang, rate = self._last_t, self._online_angle("tilt", self._last_q), 0.0
        else:
            return math.nan, math.nan, None
        dt = max(t_s - t, 0.0)
        return ang + rate * dt, TILT_CORNER_SIGMA_DEG + abs(rate) * dt, t

    # ---- the state machine -------------------------------------------------------------------
    def step(self, frame: Frame) -> HeadCommand | None:
        if self.done:
            return None
        self.frames += 1
        now = frame.t_end_s
        m = self._measure(frame)
        if m is not None:
            self.frames_with_feature += 1
            self._last_q = m[1]
            self._last_t = m[0]
            self._missed = 0
        else:
            self._missed += 1
        if self._phase_t0 is None:
            self._phase_t0 = now
        elapsed = now - self._phase_t0
        p = self.plan

        if self._phase == "reference":
            if m is not None:
                self._ref_samples.append(m[1])
            if elapsed >= p.reference_s and len(self._ref_samples) >= 3:
                self._ref_q = np.median(np.array(self._ref_samples), axis=0)
                self._rest_samples = list(self._ref_samples)
                return self._start_next_leg(now)
            if elapsed >= 5 * p.reference_s + 1.0:
                self.failure = (f"the corner was not found near {tuple(self.feature.approx_xyz)} "
                                f"(within {self.feature.radius_m} m) in {self.frames} frames: check --corner, and "
                                f"that the head is at the start pose the config gives ([head] pan0_deg, tilt0_deg; "
                                f"a calibration cut short leaves it elsewhere: home it first)")
                self._phase = "done"
                return STOP
            return None

        if self._phase == "rest":
            if m is not None:
                self._rest_samples.append(m[1])
                self._rest_t.append(m[0])
            # a fast leg's deceleration outlasts rest_s (23 deg/s at 40 deg/s^2: 0.6 s): the next leg
            # would start on a moving head and its ramp would not be the model's (from rest)
            if elapsed >= p.rest_s and (self._rest_still() or elapsed >= p.max_rest_s):
                if elapsed - p.rest_s >= 0.5 * frame.duration_s and len(self._rest_samples) >= 5:
                    self._rest_samples = self._rest_samples[-5:]     # the reference: the head at rest
                return self._start_next_leg(now)
            return None

        if self._phase == "move":
            leg = self._leg
            if m is not None:
                leg.samples.append(m)
                leg.derot_deg_s.append(self._derot_deg_s)
            ang = self._online_angle(leg.axis, self._last_q) if self._last_q is not None else 0.0
            rate = 0.0
            if len(leg.samples) >= 2:
                _, a, w = self._recent_motion(leg)
                ang, rate = _SIGN[leg.axis] * a, _SIGN[leg.axis] * w
            why = ""
            if leg.direction > 0:
                # stop early enough that dead time + deceleration + one frame stay inside the excursion
                coast = _coast_deg(rate, frame.duration_s)
                # lost: three frames in a row without the corner, counted once the leg has settled.
                # Before, the head is still in its dead time and ramp, and a frame whose scan left one
                # of the corner's planes thin (< min_plane_points: the lidar's pattern, not the head)
                # ended the leg after 0.2 s three times running in 3 of 200 simulated runs (the byte
                # then unmeasured).  The price: up to settle_s of the ramp turned with the corner unseen.
                lost = self._missed >= 3 and elapsed >= p.settle_s
                if lost:
                    why = "lost"
                elif elapsed >= p.dwell_s:
                    why = "dwell"
                elif abs(ang) + coast >= p.max_excursion_deg:
                    why = "excursion"
            else:
                # back at the start reference, predicted one frame ahead: a fast byte coasts past it,
                # and the next byte and a repeated OUT leg (below) start from there, their ramp behind
                # the start.  A repeated byte's BACK leg, and the last before the other axis's legs,
                # stop a coast early, as OUT does, to come home (the other axis's legs lost the corner
                # 5-8 deg behind the start; after the plan's last leg the return phase brings it home).
                # Out of sight: as long as OUT took (time-symmetric return).  In sight it may take a
                # little longer (it starts where OUT coasted to; its ramp takes dead time + v / (2 a)):
                # 0.1 s + v / (40 deg/s^2), at most settle_s, so a slow leg that misses the reference
                # by the corner's noise still ends on time.
                ahead = rate * frame.duration_s
                if leg.repeat or (self._queue and self._queue[0][0] != leg.axis):
                    ahead = -_coast_deg(rate, frame.duration_s)
                if self._missed == 0 and ang + ahead <= 0.0:
                    why = "reference"
                elif ((self._missed > 0 and elapsed >= self._out_duration)
                      or elapsed >= self._out_duration + min(p.settle_s, 0.1 + abs(rate) / 40.0)):
                    why = "time"
            if why:
                leg.t_stop_s, leg.end = now, why
                if leg.direction > 0:
                    self._out_duration = elapsed
                    if (why == "excursion" and not leg.repeat
                            and len(self._steady(leg)[0]) < p.min_steady_samples):
                        # ramp and stop took the excursion: after the BACK leg (which ends past the
                        # start by the byte's coast) run the byte again from there, so its ramp lies
                        # behind the start and the steady part spans the excursion; that leg's BACK
                        # stops early so that it coasts home
                        self._queue[1:1] = [(leg.axis, leg.byte, +1, True), (leg.axis, leg.byte, -1, True)]
                self._phase, self._phase_t0 = "rest", now
                self._rest_samples, self._rest_t = [], []
                return STOP
            return None

        if self._phase == "return":
            axis = self._return_axis
            ang = self._online_angle(axis, self._last_q) if self._last_q is not None else 0.0
            if self._recentre:
                # near enough (the next legs' excursion counts from the start reference): within
                # 1 deg, or past it
                if (abs(ang) <= max(p.return_tol_deg, 1.0) or ang * self._recentre_side <= 0
                        or elapsed > 30.0 or self._missed >= 5):
                    self._recentre = False
                    self._phase, self._phase_t0 = "rest", now
                    self._rest_samples, self._rest_t = [], []
                    return STOP
                d = -1 if self._recentre_side > 0 else 1
                byte = self._return_byte(axis)
                return _axis_command(axis, d, byte)
            if abs(ang) <= p.return_tol_deg or elapsed > 30.0 or self._missed >= 5:
                if axis == "pan":
                    self._return_axis, self._phase_t0 = "tilt", now
                    return STOP
                self._phase = "done"
                self._finish()
                return STOP
            byte = self._return_byte(axis)
            d = -1 if ang > 0 else 1
            return _axis_command(axis, d, byte)
        return None

    def _rest_still(self, n: int = 6, max_rate_deg_s: float = 1.0) -> bool:
        """Whether the corner has stopped turning about the last leg's axis: the median of the pairwise
        rates of the last ``n`` rest samples (Theil-Sen: a wrong corner does not move it) below
        ``max_rate_deg_s`` (about 3 sigma of ~0.05 deg corner noise over 0.25 s of 20 Hz frames)."""
        n = min(n, len(self._rest_t))
        if self._leg is None:
            return True
        if n < 3:
            return False     # not seen yet: a corner turning fast is smeared past finding (max_rest_s caps it)
        t = np.array(self._rest_t[-n:])
        Q = np.array(self._rest_samples[-n:])
        ang = _angle_about(Q, self._prior_axis(self._leg.axis), Q[-1])
        i, j = np.triu_indices(n, 1)
        dt = t[j] - t[i]
        ok = dt > 1e-6
        return bool(abs(np.median((ang[j] - ang[i])[ok] / dt[ok])) < max_rate_deg_s)

    def _return_byte(self, axis: str) -> int:
        bs = [b for b in (self.plan.pan_bytes if axis == "pan" else self.plan.tilt_bytes) if b != TURBO]
        return sorted(bs)[len(bs) // 3] if bs else 8

    def _start_next_leg(self, now: float) -> HeadCommand | None:
        ref = np.median(np.array(self._rest_samples), axis=0) if self._rest_samples else self._last_q
        if not self._queue:
            self._phase, self._phase_t0, self._return_axis = "return", now, "pan"
            return None
        last = self._leg
        if last is not None and not self._recentred and self._queue[0][0] != last.axis:
            # the other axis's legs next: bring this one home first (a fast byte's last BACK leg
            # coasts home only within 2-3 deg, and from 2.5 deg behind the start the tilt legs lost
            # the corner after 1-2 s in 4 of 30 simulated units)
            ang = self._online_angle(last.axis, self._last_q) if self._last_q is not None else 0.0
            if abs(ang) > 1.0:
                self._recentred = True
                self._phase, self._phase_t0, self._return_axis = "return", now, last.axis
                self._recentre, self._recentre_side = True, (1.0 if ang > 0 else -1.0)
                d, b = (-1 if ang > 0 else 1), self._return_byte(last.axis)
                return _axis_command(last.axis, d, b)
        self._recentred = False
        axis, byte, d, repeat = self._queue.pop(0)
        self._leg = LegRecord(axis, byte, d, now, ref_q=ref, repeat=repeat)
        self.legs.append(self._leg)
        self._phase, self._phase_t0 = "move", now
        return _axis_command(axis, d, byte)

    # ---- batch estimate ---------------------------------------------------------------------
    def _steady(self, leg: LegRecord) -> tuple[np.ndarray, np.ndarray]:
        if leg.t_stop_s is None:
            return np.empty(0), np.empty((0, 3))
        idx, t, Q = _leg_samples(leg)
        if not idx:
            return t, Q
        start = leg.t_cmd_s + self.plan.settle_s
        if len(t) >= 4:
            # adaptive: a fast leg is steady once its frame-to-frame rate matches its final rate
            ang = _angle_about(Q, self._prior_axis(leg.axis), Q[-1])
            r = np.diff(ang) / np.diff(t)
            r_f = float(np.median(r[-2:]))
            noise = 2 * 0.05 / float(np.median(np.diff(t)))   # ~0.05 deg corner noise per frame
            if abs(r_f) > 10 * noise:
                bad = np.flatnonzero(np.abs(r - r_f) > max(0.05 * abs(r_f), noise))
                t_steady = t[bad[-1] + 1] if bad.size else t[0]
                start = min(start, t_steady)
        t_ramp = self._ramp_end_s(leg)
        if t_ramp is not None:
            # never inside the ramp: its tail read as the speed (the rule above takes the rate of the
            # last frames as final, which a leg that stopped while still accelerating never reached)
            start = max(start, t_ramp + float(np.median(np.diff(t))))
        keep = t >= start
        if len(leg.derot_deg_s) == len(leg.samples) and keep.sum() >= 3:
            # a frame de-rotated at a stale rate (the corner missed in the frames before, in the
            # ramp) puts the corner up to 0.2 deg off the line where the Mid-40 scanned it off the
            # frame's middle time: seed 20's first turbo sample after two misses, 6 deg/s stale,
            # read the leg 2.7 % low.  3 deg/s: about 0.07 deg (25 ms); the online rate's own noise
            # is ~1.4 deg/s (0.05 deg corner noise over a 50 ms frame), which this rarely cuts.
            w = np.array([leg.derot_deg_s[i] for i in idx])
            ax = self._prior_axis(leg.axis)
            ang = _angle_about_unwrapped(Q[keep], ax, Q[keep][-1])
            r_line = float(np.polyfit(t[keep], ang, 1)[0])
            keep &= (np.abs(w - r_line) <= 3.0) | (abs(r_line) < 3.0)
        t, Q = t[keep], Q[keep]
        on_track = on_smooth_track(t, Q)
        return t[on_track], Q[on_track]

    def _ramp_end_s(self, leg: LegRecord) -> float | None:
        """When the head reached the leg's speed [s] (:func:`fit_ramp` on the corner's angle about the
        prior axis over the whole leg), or None (a slow or short leg: no ramp to tell)."""
        key = (len(leg.samples), leg.t_stop_s)
        hit = self._ramp_cache.get(id(leg))
        if hit is not None and hit[0] is leg and hit[1] == key:
            return hit[2]
        _, t, Q = _leg_samples(leg)
        out = None
        if len(t) >= 6:
            ang = _angle_about_unwrapped(Q, self._prior_axis(leg.axis), Q[-1])
            r = fit_ramp(t, ang, leg.t_cmd_s + self.plan.latency_s)
            out = None if r is None else r[0]
        self._ramp_cache[id(leg)] = (leg, key, out)
        return out

    def _unmeasured_reason(self, axis: str, byte: int) -> str:
        """Why a planned byte has no usable leg, and what to change in the plan."""
        p = self.plan
        short = [g for g in self.legs if g.axis == axis and g.byte == byte and g.end == "excursion"]
        if short:
            g = max(short, key=lambda g: g.t_stop_s - g.t_cmd_s)
            te = self._ramp_end_s(g)
            ramp = "" if te is None else f" (its ramp ended {te - g.t_cmd_s:.2f} s after the command)"
            return (f"too few steady frames (< {p.min_samples}) after the ramp: the longest leg stopped at "
                    f"the {p.max_excursion_deg:g} deg excursion {g.t_stop_s - g.t_cmd_s:.2f} s after its "
                    f"command{ramp}; give the corner a larger max_excursion_deg if the FoV allows")
        steady = p.dwell_s - p.settle_s
        return (f"feature lost or too few steady frames (< {p.min_samples}) in a leg's {steady:g} s after its "
                f"{p.settle_s:g} s settle (dwell {p.dwell_s:g} s); try a longer dwell or excursion")

    def _leg_scatter(self, axis: str, min_arc_rms_m: float = 0.0) -> tuple[np.ndarray, int]:
        """Scatter matrix of the ``axis`` legs' steady corner positions about each leg's mean, and the
        number of positions; legs shorter than ``plan.min_samples`` are left out, and with
        ``min_arc_rms_m`` > 0 legs whose arc is shorter (rms along it): a leg that hardly moves
        carries no information on the axis, only the corner's (anisotropic) noise."""
        C = np.zeros((3, 3))
        n = 0
        for leg in self.legs:
            if leg.axis != axis:
                continue
            _, Q = self._steady(leg)
            if len(Q) < self.plan.min_samples:
                continue
            Qc = Q - Q.mean(axis=0)
            S = Qc.T @ Qc
            if min_arc_rms_m > 0 and math.sqrt(np.linalg.eigvalsh(S)[-1] / len(Q)) < min_arc_rms_m:
                continue
            C += S
            n += len(Q)
        return C, n

    def _axis_estimate(self, axis: str) -> np.ndarray:
        prior = self._prior_axis(axis)
        C, n = self._leg_scatter(axis)
        if n < 10:
            return prior
        w, v = np.linalg.eigh(C)
        a = v[:, 0]
        if w[1] <= 0 or w[0] / w[1] > 0.25 or abs(a @ prior) < math.cos(math.radians(30)):
            return prior            # legs too short / noisy to tell the axis
        return a if a @ prior > 0 else -a

    def _finish(self) -> None:
        self._table, self.report = self._estimate()

    def _estimate(self) -> tuple[SpeedTable, CalibrationReport]:
        axes = {a: self._axis_estimate(a) for a in ("pan", "tilt")}
        per = {"pan": {}, "tilt": {}}
        fitted = []
        for leg in self.legs:
            t, Q = self._steady(leg)
            if len(t) < self.plan.min_samples:
                per[leg.axis].setdefault(leg.byte, []).append(None)
                continue
            ang = _angle_about_unwrapped(Q, axes[leg.axis], leg.ref_q)
            tm = t.mean()
            stt = float(np.sum((t - tm) ** 2))
            b = float(np.sum((t - tm) * (ang - ang.mean())) / stt)
            a0 = ang.mean() - b * tm
            res = ang - (a0 + b * t)
            s2 = float(np.sum(res ** 2)) / max(len(t) - 2, 1)
            v = _SIGN[leg.axis] * leg.direction * b
            delay = None
            if abs(b) > 1e-6:
                delay = (0.0 - a0) / b - leg.t_cmd_s - self.plan.latency_s   # reference angle is 0
            fitted.append((leg, v, s2, stt, len(t), delay))
        # A short leg's residual variance (n - 2 = 2-7 degrees of freedom) can come out far below the
        # corner's noise by chance and its leg then outweighs the others: seed 22's 5-frame turbo leg,
        # 2.0 % high, took most of the weight from a 7-frame one (0.6 %).  Below 10 frames (where
        # on_smooth_track does not run either) it is floored at the axis's median over longer legs.
        floor = {}
        for axis in ("pan", "tilt"):
            long_s2 = [f[2] for f in fitted if f[0].axis == axis and f[4] >= 10]
            floor[axis] = float(np.median(long_s2)) if long_s2 else 0.0
        for leg, v, s2, stt, n, delay in fitted:
            if n < 10:
                s2 = max(s2, floor[leg.axis])
            per[leg.axis].setdefault(leg.byte, []).append((v, math.sqrt(s2 / stt), delay, leg.direction))
        tables, unmeasured, asym = {}, {"pan": {}, "tilt": {}}, {"pan": {}, "tilt": {}}
        delays = []
        for axis in ("pan", "tilt"):
            entries = []
            plan_bytes = self.plan.pan_bytes if axis == "pan" else self.plan.tilt_bytes
            plain = [b for b in plan_bytes if b != TURBO]
            for byte in axis_bytes(axis):
                fits = [f for f in per[axis].get(byte, []) if f is not None]
                if byte not in plan_bytes:
                    # between two measured bytes a speed is interpolated; outside them it is unknown and
                    # the tracker never sends the byte (they were all said to be interpolated)
                    inside = byte != TURBO and plain and min(plain) < byte < max(plain)
                    unmeasured[axis][byte] = ("not in the plan (interpolated)" if inside else
                                              "not in the plan, outside the measured bytes (no speed: never sent)")
                    continue
                if not fits:
                    unmeasured[axis][byte] = self._unmeasured_reason(axis, byte)
                    entries.append(SpeedEntry(byte, float("nan"), float("nan"), False, note="not measured"))
                    continue
                # per direction (a swept byte has two legs each way) by inverse variance, then the
                # two directions alike, half their difference added in quadrature
                per_dir = []
                for dr in (+1, -1):
                    fd = [f for f in fits if f[3] == dr]
                    if fd:
                        wd = 1 / np.array([max(f[1], 1e-9) for f in fd]) ** 2
                        per_dir.append((float(np.sum(wd * [f[0] for f in fd]) / np.sum(wd)),
                                        math.sqrt(1 / float(np.sum(wd)))))
                vs = np.array([x[0] for x in per_dir])
                w = 1 / np.array([x[1] for x in per_dir]) ** 2
                v = float(np.sum(w * vs) / np.sum(w))
                sig = math.sqrt(1 / float(np.sum(w)))
                if len(per_dir) == 2:
                    asym[axis][byte] = (float(vs[0]), float(vs[1]))
                    sig = math.hypot(sig, (vs[0] - vs[1]) / 2)
                v = max(v, 0.0)
                dl = [f[2] for f in fits if f[2] is not None and abs(f[0]) > 3 * max(f[1], 1e-9)]
                d = float(np.median(dl)) if dl else None
                if d is not None:
                    delays.append((v, d))
                entries.append(SpeedEntry(byte, v, sig, True, d))
            tables[axis] = AxisTable(axis, tuple(entries))
        dead, accel = 0.0, None
        if len(delays) >= 3:
            V = np.array([x[0] for x in delays])
            Dl = np.array([x[1] for x in delays])
            A = np.column_stack([np.ones_like(V), V])
            (c0, c1), *_ = np.linalg.lstsq(A, Dl, rcond=None)
            if c1 > 1e-6:
                accel = 1.0 / (2.0 * c1)
                dead = max(float(c0), 0.0)
            else:
                dead = max(float(np.median(Dl)), 0.0)
        pa = axes["pan"]
        implied = math.degrees(math.atan2(pa[0], pa[2]))
        date = self.date or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        table = SpeedTable(tables["pan"], tables["tilt"], date=date, head=self.head,
                           source=f"foveatrack calibration: corner feature, {self.frames} frames, "
                                  f"{len(self.legs)} legs", dead_time_s=dead, accel_deg_s2=accel)
        report = CalibrationReport({a: dict(sorted(u.items())) for a, u in unmeasured.items()},
                                   {a: tuple(map(float, v)) for a, v in axes.items()}, implied, asym,
                                   dead, accel, self.frames, self.frames_with_feature)
        return table, report

    def result(self) -> SpeedTable:
        """The measured table (call when :attr:`done`)."""
        if self.failure:
            raise UserError(f"calibration failed: {self.failure}")
        if not self.done:
            raise RuntimeError("Calibrator.result() before done")
        t = self._table
        if all(not math.isfinite(t.axis(a).max_speed_deg_s(True)) or t.axis(a).max_speed_deg_s(True) <= 0
               for a in ("pan", "tilt")):
            # why, as the legs say it (it said "the corner was lost in every leg" of legs too short for
            # a steady stretch after the settle: a user's audit, --dwell-s 0.6)
            why = sorted({r for u in self.report.unmeasured.values() for r in u.values() if "plan" not in r})
            raise UserError("calibration measured no usable speed: " + ("; ".join(why) if why else
                                                                         "the corner was lost in every leg"))
        return t


class PriorAxisCalibrator(Calibrator):
    """A :class:`Calibrator` whose rotation-axis estimates are pulled toward the known mounting.

    The base class finds each head axis in the lidar frame as the smallest eigenvector ``v0`` of the
    pooled scatter of corner positions (eigenvalues ``w0 <= w1 <= w2``) and uses it as is.  With the
    excursions a lidar FoV allows (15 deg arcs) that direction is poorly determined toward ``v1``
    (the arc's sagitta): seen over several scene seeds the implied start tilt scattered by about
    1.5 deg, which biases every pan speed alike by ``tan(el) * d_axis`` (about 0.7 % for a corner
    15 deg above the pan plane).  Here the estimate is the inverse-variance combination of the data
    and the prior (pan: ``R_y(start_tilt) z``; tilt: lidar Y):

    .. math:: \\theta_j = \\frac{\\theta_{p,j}/\\sigma_p^2}{1/\\sigma_{d,j}^2 + 1/\\sigma_p^2},
              \\quad \\sigma_{d,j}^2 = \\frac{s^2\\, w_j}{(w_j - w_0)^2},\\quad s^2 = \\frac{w_0}{n - 3},
              \\quad j = 1, 2

    where ``theta_{p,j} = prior . v_j`` and the axis is ``v0 + sum_j theta_j v_j`` normalised
    (first-order perturbation of the eigenvector by noise of variance ``s^2`` per sample).  Only
    legs whose corner moved ``min_arc_rms_m`` (rms along the arc) are pooled: a slow leg adds the
    corner's anisotropic noise and no information (with all 18 tilt bytes pooled the tilt axis came
    out 50 deg off and every tilt speed +2.7 %).  Degenerate scatter (``w0 / w1 > 0.25``) -> prior.

    The prior is tested against the data first: were both right, each ``theta_{p,j}`` would be a
    normal deviate of variance ``sigma_{d,j}^2 + sigma_p^2`` (the assumption the combination above
    rests on), so

    .. math:: \\chi^2 = \\sum_{j=1,2} \\frac{\\theta_{p,j}^2}{\\sigma_{d,j}^2 + \\sigma_p^2}

    follows a chi-square law with 2 degrees of freedom.  Above ``PRIOR_CONFLICT_CHI2`` (13.8,
    p = 0.001) they cannot both be right, and the data's axis ``v0`` is used alone: a prior the data
    contradict is wrong (a ``tilt0_deg`` left from another mounting, a head not homed), and combining
    it with them by inverse variance gives an axis consistent with neither, near the prior since its
    0.5 deg outweighs the data's 2-5 deg (a start tilt of 35 deg for a true 6.5 made every pan speed
    25-33 % high; the data's axis alone: 0.4-4.2 % over 7 runs).  The report then says so
    (:meth:`_prior_warning`), naming what the data contradict, each angle tested alone: the start
    tilt (the one the data imply and the one given), the lean toward lidar Y, or both; degenerate
    scatter keeps the prior but is tested and said alike.  The test misses what the data cannot
    resolve: a start tilt 6.5 deg off (chi-square 12.6, one-byte plan) biased pan by 2 % unsaid.

    start_tilt_sigma_deg : float > 0 [deg]  how well the start tilt (``plan.start_tilt_deg``) is
        known: exact in simulation; a levelled head with a known zero about 0.5 deg; give 90 if unknown
        (it is also the tilt estimate's floor for the command gate: behind a gate with tilt stops, 90
        refuses every tilt leg, since the stops cannot be kept without knowing the tilt)
    mount_sigma_deg : float > 0 [deg]       lidar Y vs the tilt axis (mounting), about 0.5 deg
    min_arc_rms_m : float >= 0 [m]          legs whose corner moved less are left out of the axis fit
    """

    def __init__(self, plan: CalibrationPlan, feature: FeatureSpec, *, start_tilt_sigma_deg: float = 0.5,
                 mount_sigma_deg: float = 0.5, min_arc_rms_m: float = 0.1, **kw):
        super().__init__(plan, feature, **kw)
        if not (start_tilt_sigma_deg > 0 and mount_sigma_deg > 0):
            raise UserError("start_tilt_sigma_deg and mount_sigma_deg must be > 0 [deg]")
        self.prior_sigma_deg = {"pan": float(start_tilt_sigma_deg), "tilt": float(mount_sigma_deg)}
        self.start_tilt_sigma_deg = float(start_tilt_sigma_deg)
        self.min_arc_rms_m = float(min_arc_rms_m)
        self._fits: dict[str, AxisFit] = {}      # the last fit of each axis (_axis_estimate)
        self._start_tilt: tuple[float, float, bool] | None = None    # start_tilt_deg, once the pan legs are over

    def _axis_estimate(self, axis: str) -> np.ndarray:
        # kept: the estimate's warnings (_estimate) are of this fit, not of a second one
        self._fits[axis] = fit = self._axis_fit(axis)
        return fit.axis

    def start_tilt_deg(self) -> tuple[float, float, bool]:
        """The plan's start tilt until the pan legs are over; then, if their corner data contradict it
        (the start tilt's part of the pan prior's test: :meth:`_pan_prior_parts`), the start tilt
        they imply and its sigma (:meth:`AxisFit.implied_start_tilt_deg`), or NaN where the scatter
        is degenerate (the table keeps the prior's axis then, and the implied tilt is no estimate:
        137 +- 15 deg for a head at 48).  The pan legs come before the tilt legs, so the gate keeps
        the stops with the start tilt the data show, and refuses tilt where they cannot show it:
        counted from a wrong ``tilt0_deg`` the stops moved by its error (the simulated head at 6.5
        deg, told 54, was refused its tilt leg "at estimated tilt 57"; one at 48, told 20, was driven
        into its stop at 60 while the gate believed 32)."""
        if self._start_tilt is not None:
            return self._start_tilt
        pan_legs = [g for g in self.legs if g.axis == "pan"]
        if (not pan_legs or any(g.t_stop_s is None for g in pan_legs)
                or any(q[0] == "pan" for q in self._queue)):
            return super().start_tilt_deg()       # the pan legs have not shown it yet
        self._start_tilt = super().start_tilt_deg()
        fit = self._axis_fit("pan")
        if fit.conflict and self._pan_prior_parts(fit)[0]:
            tilt, tilt_sigma, _, _ = fit.implied_start_tilt_deg()
            self._start_tilt = (math.nan, math.nan, True) if fit.degenerate else (tilt, tilt_sigma, True)
        return self._start_tilt

    def _axis_fit(self, axis: str) -> AxisFit:
        """The axis estimate (class docstring), with the data's own axis and the test of the prior
        against it."""
        prior = self._prior_axis(axis)
        C, n = self._leg_scatter(axis, self.min_arc_rms_m)
        if n < 10:
            return AxisFit(axis, prior, prior, None, None, None, True)
        w, v = np.linalg.eigh(C)
        a = v[:, 0] if v[:, 0] @ prior > 0 else -v[:, 0]
        s2 = max(w[0], 0.0) / max(n - 3, 1)
        var_p = math.radians(self.prior_sigma_deg[axis]) ** 2
        var_d = [s2 * w[j] / (w[j] - w[0]) ** 2 if w[j] > w[0] else math.inf for j in (1, 2)]
        theta_p = [float(prior @ v[:, j]) for j in (1, 2)]
        chi2 = sum(th * th / (vd + var_p) for th, vd in zip(theta_p, var_d))
        cov = sum((vd if math.isfinite(vd) else 1e6) * np.outer(v[:, j], v[:, j]) for vd, j in zip(var_d, (1, 2)))
        if w[1] <= 0 or w[0] / w[1] > 0.25:
            # degenerate: the arcs do not tell the axis (the test above may still tell the prior wrong)
            return AxisFit(axis, prior, prior, a, cov, chi2, True)
        if chi2 > PRIOR_CONFLICT_CHI2:
            return AxisFit(axis, a, prior, a, cov, chi2, False)     # a prior the data contradict is wrong
        wp = 1.0 / var_p
        out = a.copy()
        for j, vd, th in zip((1, 2), var_d, theta_p):
            wd = 1.0 / vd if vd > 0 else math.inf
            out += (wp * th / (wd + wp) if math.isfinite(wd) else 0.0) * v[:, j]
        out /= np.linalg.norm(out)
        if out @ prior < math.cos(math.radians(30)):
            out = prior
        return AxisFit(axis, out, prior, a, cov, chi2, False)

    def _prior_warning(self, fit: AxisFit) -> str | None:
        """The report's sentence on a prior the data contradict (``fit.conflict``), else None."""
        if not fit.conflict:
            return None
        sp = self.prior_sigma_deg[fit.name]
        test = (f"chi-square {fit.chi2:.0f} for 2 degrees of freedom, above {PRIOR_CONFLICT_CHI2:g}: "
                f"p < 0.001 were both right")
        if fit.degenerate:
            used = (f"The legs are too short for the data's axis to replace the assumed one, so the table used "
                    f"the assumed one: every {fit.name} speed in it may be off alike.")
        else:
            used = (f"The table's {fit.name} speeds were measured about the data's axis, not the assumed one "
                    f"(which would bias them all alike).")
        if fit.name == "pan":
            return self._pan_prior_warning(fit, sp, test, used)
        off = math.degrees(math.acos(min(1.0, abs(float(fit.data_axis @ fit.prior)))))
        return (f"the tilt axis disagrees with the lidar's mounting: the corner turned about an axis "
                f"{off:.1f} deg from lidar Y, where the calibration assumes the tilt axis within {sp:g} deg "
                f"({test}).  {used}  Check that the lidar sits on the head with its Y axis along the tilt axis.")

    def _pan_prior_parts(self, fit: AxisFit) -> tuple[bool, bool]:
        """Which parts of a pan prior the data contradict (``fit.conflict``): ``(start tilt, lean)``,
        each angle tested alone; neither alone but the two together: both (either may be off)."""
        tilt_chi2, lean_chi2 = fit.start_tilt_and_lean_chi2(self.plan.start_tilt_deg, self.prior_sigma_deg["pan"])
        tilt_off, lean_off = tilt_chi2 > PRIOR_CONFLICT_CHI2_1DOF, lean_chi2 > PRIOR_CONFLICT_CHI2_1DOF
        return (True, True) if not (tilt_off or lean_off) else (tilt_off, lean_off)

    def _pan_prior_warning(self, fit: AxisFit, sp: float, test: str, used: str) -> str:
        """The warning on a pan prior the data contradict, naming the part of it they contradict: the
        start tilt (``tilt0_deg``), the lean toward lidar Y (the lidar's mounting), or both."""
        tilt, tilt_sigma, lean, lean_sigma = fit.implied_start_tilt_deg()
        t0 = self.plan.start_tilt_deg
        tilt_off, lean_off = self._pan_prior_parts(fit)
        said_tilt = (f"implies a start tilt of {tilt:.1f} +- {tilt_sigma:.1f} deg, but the calibration was told "
                     f"{t0:g} +- {sp:g} deg (tilt0_deg: [head] in a daemon config, [gimbal] in a scene)")
        said_lean = (f"leans {lean:+.1f} +- {lean_sigma:.1f} deg toward lidar Y, which no start tilt gives, where "
                     f"the calibration assumes 0 +- {sp:g} deg")
        fix_tilt = (f"If the head did not start at {t0:g} deg, measure its start tilt, set tilt0_deg to it and "
                    f"calibrate again: the daemon takes tilt0_deg as the head's start pose (a calibration's "
                    f"tilt stops count from it until the pan legs contradict it, then from the start tilt "
                    f"they imply, or, where they are too short to tell it, the gate refuses tilt).")
        fix_lean = ("Check that the lidar sits on the head with its Y axis along the tilt axis (a lidar rolled "
                    "about its X axis leans the pan axis so)")
        axis = "the head's pan axis as the corner turned about it"
        if not lean_off:
            return (f"the start tilt disagrees with the corner's motion: {axis} {said_tilt}; its lean toward "
                    f"lidar Y, {lean:+.1f} +- {lean_sigma:.1f} deg, agrees with the mounting ({test}).  {used}  "
                    f"{fix_tilt}")
        if not tilt_off:
            return (f"the pan axis leans toward lidar Y against the lidar's mounting: {axis} {said_lean}; its "
                    f"start tilt, {tilt:.1f} +- {tilt_sigma:.1f} deg, agrees with the {t0:g} deg given "
                    f"(tilt0_deg is not what is wrong; {test}).  {used}  {fix_lean}.")
        return (f"the start tilt and the lean toward lidar Y disagree with the corner's motion: {axis} "
                f"{said_tilt}, and {said_lean} ({test}).  {used}  {fix_lean}; and {fix_tilt[0].lower()}"
                f"{fix_tilt[1:]}")

    def _estimate(self):
        """The base estimate, then the head timing refitted from the legs' whole angle histories.

        The base class reads each entry's effective delay ``dead_time + v / (2 a)`` off the steady
        line's intercept and fits one acceleration to both axes; on the simulated PTS-303 (40 and
        10 deg/s^2, 40 ms) that gave 25-28 ms and 32/8.4 deg/s^2, and the reconstruction, which
        integrates every ramp of a P controller's decelerating approaches, drifted 1.9 deg in pan
        over 60 s (0.4 deg with the true timing).  Here the corner's angle over each whole leg
        (ramp included, up to its stop) is fitted with the head's model (App. D.4 timing as in
        :mod:`foveatrack.reconstruction`):

        .. math:: \\theta(t) = \\begin{cases} 0 & \\tau < 0 \\\\ a\\tau^2/2 & 0 \\le \\tau < v/a \\\\
                  v(\\tau - v/(2a)) & \\text{else} \\end{cases},\\quad
                  \\tau = t - t_{cmd} - \\text{latency} - d

        with ``v`` the entry's measured speed, one dead time ``d`` and one acceleration per axis
        (scipy ``least_squares``, soft-L1 loss), written into ``dead_time_s`` and each
        ``AxisTable.accel_deg_s2`` (the reconstruction uses them per axis).  Legs slower than
        ``0.2 deg/s`` carry no timing information and are left out.
        """
        from dataclasses import replace as _replace

        from scipy.optimize import least_squares

        table, report = super()._estimate()
        said = [self._prior_warning(self._fits[ax]) for ax in ("pan", "tilt")]     # the fits just used
        report = _replace(report, warnings=report.warnings + tuple(w for w in said if w))
        axes = {ax: np.asarray(report.axis_lidar[ax], float) for ax in ("pan", "tilt")}
        data = []
        for leg in self.legs:
            ax = table.axis(leg.axis)
            v = ax.speed_deg_s(leg.byte)
            if not ax.is_measured(leg.byte) or not v >= 0.2 or leg.t_stop_s is None or leg.ref_q is None:
                continue
            _, t, Q = _leg_samples(leg)
            if len(t) < self.plan.min_samples:
                continue
            ang = _angle_about_unwrapped(Q, axes[leg.axis], leg.ref_q)
            ang = _SIGN[leg.axis] * leg.direction * ang
            data.append((0 if leg.axis == "pan" else 1, v, t - leg.t_cmd_s - self.plan.latency_s, ang))
        if len(data) < 4 or len({d[0] for d in data}) < 2:
            return table, report

        def model(tau, v, a):
            tr = v / a
            return np.where(tau < 0, 0.0, np.where(tau < tr, 0.5 * a * tau ** 2, v * (tau - 0.5 * tr)))

        def resid(p):
            d, la_p, la_t = p
            acc = (math.exp(la_p), math.exp(la_t))
            return np.concatenate([ang - model(tau - d, v, acc[k]) for k, v, tau, ang in data])

        # the start inside the bounds: the delay line's slope can be ~0 (a few legs), its accel 1e4+
        la0 = min(max(math.log(report.accel_deg_s2 or 20.0), math.log(0.2)), math.log(5e3))
        x0 = [min(max(report.dead_time_s, 0.0), 0.9), la0, la0]
        fit = least_squares(resid, x0, loss="soft_l1", f_scale=0.1,
                            bounds=([0.0, math.log(0.1), math.log(0.1)], [1.0, math.log(1e4), math.log(1e4)]))
        if not fit.success:
            return table, report
        dead = float(fit.x[0])
        a_pan, a_tilt = math.exp(fit.x[1]), math.exp(fit.x[2])
        table = _replace(table, pan=_replace(table.pan, accel_deg_s2=a_pan),
                         tilt=_replace(table.tilt, accel_deg_s2=a_tilt), dead_time_s=dead,
                         accel_deg_s2=max(a_pan, a_tilt))
        report = _replace(report, dead_time_s=dead, accel_deg_s2=max(a_pan, a_tilt))
        self.axis_accel_deg_s2 = {"pan": a_pan, "tilt": a_tilt}
        return table, report
