"""The head's pose checked against the world the lidar sees (issue 26).

The head reports no angles: every driver dead-reckons them from the commands it sent (paper App. D.4,
:mod:`foveatrack.reconstruction`).  That estimate drifts with the speed table's error (a table of
another unit: pan 8.6 deg off after 30 s), and it is simply wrong after the head lost power behind a
live link (it comes back at its power-on pose; the estimate stays where it was).  The static
background -- ground, walls, trees -- is a witness: it does not move, so the lidar's points of it,
turned into the world at the estimated pose, must land where they landed before.

The map
-------
A coarse world-frame range map of the background, seen from the head's centre: cells of
``cell_deg`` in azimuth and elevation, each holding the smallest and largest range of the points that
fell in it (a min/max interval, not a mean: a cell at grazing incidence on the ground, or on an edge
with the ground behind it, spans metres of range, and an interval holds both).  It is built from
frames at a *known* pose -- the start pose, head at rest, before the first command (the daemon waits
``map_frames`` frames for it) -- and afterwards extended, in cells not mapped yet, by frames whose
check found them within ``extend_below_deg`` of the estimate.

The check (rotation only: the head turns about its centre)
----------------------------------------------------------
A frame's points ``p`` (lidar frame) are turned into the world as the tracker turns them (module
docstring of :mod:`foveatrack.reconstruction`),

.. math:: w = R_z(pan + \\delta_p)\\, R_y(-(tilt + \\delta_t))\\, (p + o)

and a point *matches* when its cell is mapped and its range lies in the cell's interval widened by
``range_tol_m + range_tol_rel * range``.  The offset ``(delta_p, delta_t)`` [deg] with the most matches
is searched on a grid of ``coarse_step_deg`` over ``+-search_deg`` and refined on ``fine_step_deg``
around the best (two parameters: a grid is exact enough, needs no gradient, and cannot be caught by
a local optimum inside the window).  Each point is turned at the estimated pose of its own
time (the head moves within a frame); frames are checked while the estimate turns slower than
``slow_deg_s``, at most one per ``period_s``.

Outcomes (:class:`PoseCheckResult` ``kind``):

* ``inconclusive`` -- too few points, or fewer than ``min_coverage`` of them on mapped cells at the
  estimate (the head looks where the map has nothing yet): nothing is said.
* ``ok`` -- the best offset is within ``bound_deg`` on each axis the background makes observable,
  and at least ``min_match`` of the points on mapped cells match there: the offset is the dead
  reckoning's drift, and the driver corrects it (:meth:`foveatrack.tracker.Tracker.correct_pose`), by
  ``correction_gain`` of it (each check is a fresh measurement against the map: half of each averages
  their noise, ~0.1-0.2 deg in pan, and still follows a drift).
* ``mismatch`` -- the best offset is beyond ``bound_deg``, or nothing in the window matches: the
  pose is unknown (the daemon's ``head_pose_unknown``, STOP, re-homing where ``[head] on_reconnect =
  "home"``).

The score of an offset is the *fraction* of the points on mapped cells that match (with at least
``min_coverage`` of the points on mapped cells), not their count: shifting the points along the edge
of the map changes how many are covered, which says nothing about the pose.

Observability: rotating a flat ground about the vertical axis changes nothing, so a ground alone
says nothing about pan.  An axis along which the best match stands less than ``min_contrast`` above the median match
through it is *unobservable* in that frame: it is neither corrected nor taken as
a mismatch.  Pan is checked only where the background has structure in azimuth (walls, trees,
poles, buildings).

A speed table from another unit: the pan drift between two checks is, to first order, the table's
relative error times the pan travel between them.  :class:`ScaleWitness` fits that ratio and warns
when it exceeds ``table_warn_rel`` (and 4 of its standard errors) over at least
``table_warn_travel_deg`` of travel.

The hot loop (every point of a frame, for every candidate offset) is the numba kernel
:func:`match_counts_kernel`; its plain-numpy twin is in ``tests/test_pose_check.py``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np
from numba import njit

from foveatrack.errors import UserError

KINDS = ("inconclusive", "ok", "mismatch")


@dataclass(frozen=True)
class PoseCheckConfig:
    """Settings of the pose check (the daemon's ``[pose_check]`` table; every key optional).

    enabled : bool                     run the check (default off)
    cell_deg : float in (0, 5] [deg]   map cell in azimuth and elevation
    bound_deg : float > 0 [deg]        an offset beyond this is a pose mismatch; within it, drift corrected
    search_deg : float >= bound_deg    half-width of the searched window [deg]
    coarse_step_deg, fine_step_deg     the two search grids [deg]
    range_tol_m : float >= 0 [m], range_tol_rel : float >= 0   widening of a cell's range interval
    min_range_m : float >= 0 [m]       nearer points are left out (the mount, the head itself)
    max_points : int >= 100            a frame's points are thinned to at most this many (fixed stride)
    min_points : int >= 10             fewer usable points: inconclusive
    min_coverage : float in (0, 1]     fraction of points on mapped cells needed to say anything
    min_match : float in (0, 1]        fraction of those that must match at the best offset
    min_contrast : float in (0, 1]     an axis is observable when the best match stands this far above the
                                       median match along it
    min_correction_deg : float >= 0    smaller offsets are left alone (noise)
    correction_gain : float in (0, 1]  the share of an offset applied: each check measures the pose anew
                                       against the map, so a gain below 1 averages the checks' noise (0.5:
                                       the error's spread 1/sqrt(3) of one check's) and still follows a drift
    plateau_frac : float in [0, 0.1]   offsets whose match is within this of the best are its plateau
    extend_below_deg : float >= 0      frames at rest checked within this extend the map
    map_frames : int >= 1              frames at rest at the start pose that make the first map
    slow_deg_s : float > 0 [deg/s]     a frame is checked only if the estimate turns slower (default: the
                                       PTS family's top speed, turbo aside: every frame but a turbo's)
    rest_deg_s : float > 0 [deg/s]     a frame slower than this is "at rest" (it may extend the map)
    period_s : float >= 0 [s]          least time between two checks (sensor time)
    table_warn_rel, table_warn_travel_deg   the speed-table warning (:class:`ScaleWitness`)
    """

    enabled: bool = False
    cell_deg: float = 0.5
    bound_deg: float = 3.0
    search_deg: float = 6.0
    coarse_step_deg: float = 1.0
    fine_step_deg: float = 0.1
    range_tol_m: float = 0.15
    range_tol_rel: float = 0.01
    min_range_m: float = 1.0
    max_points: int = 1000
    min_points: int = 200
    min_coverage: float = 0.3
    min_match: float = 0.6
    min_contrast: float = 0.08
    min_correction_deg: float = 0.1
    correction_gain: float = 0.5
    plateau_frac: float = 0.003
    extend_below_deg: float = 0.5
    map_frames: int = 10
    slow_deg_s: float = 16.0
    rest_deg_s: float = 1.0
    period_s: float = 0.5
    table_warn_rel: float = 0.1
    table_warn_travel_deg: float = 30.0

    @classmethod
    def from_mapping(cls, data: Mapping, where: str = "[pose_check]") -> "PoseCheckConfig":
        """Validated settings; a UserError naming ``where``, the key and the allowed values otherwise."""
        known = {f.name: f for f in fields(cls)}
        kw = {}
        for k, v in data.items():
            if k not in known:
                raise UserError(f"{where}: unknown key {k!r}; allowed: {', '.join(sorted(known))}")
            want = type(getattr(cls(), k))
            if want is bool:
                if not isinstance(v, bool):
                    raise UserError(f"{where}: {k} = {v!r} must be true or false")
            elif want is int:
                if isinstance(v, bool) or not isinstance(v, int):
                    raise UserError(f"{where}: {k} = {v!r} must be an integer")
            elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise UserError(f"{where}: {k} = {v!r} must be a finite number")
            kw[k] = want(v)
        c = cls(**kw)
        checks = [("cell_deg", 0 < c.cell_deg <= 5, "in (0, 5]"), ("bound_deg", c.bound_deg > 0, "> 0"),
                  ("search_deg", c.search_deg >= c.bound_deg, f">= bound_deg ({c.bound_deg})"),
                  ("coarse_step_deg", 0 < c.coarse_step_deg <= c.search_deg, "in (0, search_deg]"),
                  ("fine_step_deg", 0 < c.fine_step_deg <= c.coarse_step_deg, "in (0, coarse_step_deg]"),
                  ("range_tol_m", c.range_tol_m >= 0, ">= 0"), ("range_tol_rel", c.range_tol_rel >= 0, ">= 0"),
                  ("min_range_m", c.min_range_m >= 0, ">= 0"), ("max_points", c.max_points >= 100, ">= 100"),
                  ("min_points", c.min_points >= 10, ">= 10"),
                  ("min_coverage", 0 < c.min_coverage <= 1, "in (0, 1]"), ("min_match", 0 < c.min_match <= 1, "in (0, 1]"),
                  ("min_contrast", 0 < c.min_contrast <= 1, "in (0, 1]"),
                  ("min_correction_deg", c.min_correction_deg >= 0, ">= 0"),
                  ("correction_gain", 0 < c.correction_gain <= 1, "in (0, 1]"),
                  ("plateau_frac", 0 <= c.plateau_frac <= 0.1, "in [0, 0.1]"),
                  ("extend_below_deg", c.extend_below_deg >= 0, ">= 0"), ("map_frames", c.map_frames >= 1, ">= 1"),
                  ("slow_deg_s", c.slow_deg_s > 0, "> 0"), ("rest_deg_s", c.rest_deg_s > 0, "> 0"), ("period_s", c.period_s >= 0, ">= 0"),
                  ("table_warn_rel", c.table_warn_rel > 0, "> 0"),
                  ("table_warn_travel_deg", c.table_warn_travel_deg > 0, "> 0")]
        for k, ok, allowed in checks:
            if not ok:
                raise UserError(f"{where}: {k} = {getattr(c, k)!r} is not allowed; use a value {allowed}")
        return c


# ------------------------------------------------------------------------------------------ kernel
@njit(cache=True)
def match_counts_kernel(q, pan_rad, tilt_rad, dtilts_rad, dpans_rad, rmin, rmax, cell_rad, tol_abs_m, tol_rel,
                        matched, covered):
    """Matches of points ``q`` (N, 3) [m] (head-centre coordinates of the tilt stage: lidar point +
    lidar offset), each seen at the pose ``(pan_rad[k], tilt_rad[k])`` (N,), against the map
    ``rmin``/``rmax`` (E, A) [m] (unmapped: ``rmin = inf``), for every offset ``(dpans_rad[j],
    dtilts_rad[i])``.  Adds to ``matched[i, j]`` and ``covered[i, j]`` (int64).

    Per tilt, a point is turned by ``R_y(-tilt)`` (the rows of
    :func:`foveatrack.reconstruction.rotation_matrix` at pan 0); its elevation and azimuth follow, and
    pan only adds to the azimuth.  Cells: ``floor((az + pi) / cell) mod A``, ``floor((el + pi/2) /
    cell)`` clamped to ``[0, E)``.
    """
    n = q.shape[0]
    n_el, n_az = rmin.shape
    half_pi = 0.5 * math.pi
    for i in range(dtilts_rad.shape[0]):
        for k in range(n):
            t = tilt_rad[k] + dtilts_rad[i]
            ct = math.cos(t)
            st = math.sin(t)
            x = q[k, 0]
            y = q[k, 1]
            z = q[k, 2]
            ux = ct * x - st * z
            uz = st * x + ct * z
            r = math.sqrt(ux * ux + y * y + uz * uz)
            if not r > 0.0:
                continue
            ie = int(math.floor((math.asin(min(max(uz / r, -1.0), 1.0)) + half_pi) / cell_rad))
            if ie < 0:
                ie = 0
            elif ie >= n_el:
                ie = n_el - 1
            az0 = math.atan2(y, ux) + pan_rad[k] + math.pi
            tol = tol_abs_m + tol_rel * r
            for j in range(dpans_rad.shape[0]):
                ia = int(math.floor((az0 + dpans_rad[j]) / cell_rad)) % n_az
                lo = rmin[ie, ia]
                if lo == math.inf:
                    continue
                covered[i, j] += 1
                if lo - tol <= r and r <= rmax[ie, ia] + tol:
                    matched[i, j] += 1


def match_counts(q, pan_deg, tilt_deg, dtilts_deg, dpans_deg, bg: "BackgroundMap", tol_abs_m, tol_rel):
    """(matched, covered), each (len(dtilts_deg), len(dpans_deg)) int64, by :func:`match_counts_kernel`;
    ``pan_deg``, ``tilt_deg``: each point's pose (N,) or one for all [deg]."""
    n = len(q)
    pan = np.ascontiguousarray(np.broadcast_to(np.radians(np.asarray(pan_deg, float)), (n,)))
    tilt = np.ascontiguousarray(np.broadcast_to(np.radians(np.asarray(tilt_deg, float)), (n,)))
    dt = np.radians(np.asarray(dtilts_deg, float))
    dp = np.radians(np.asarray(dpans_deg, float))
    matched = np.zeros((len(dt), len(dp)), np.int64)
    covered = np.zeros_like(matched)
    match_counts_kernel(np.ascontiguousarray(q, float), pan, tilt, dt, dp, bg.rmin, bg.rmax,
                        math.radians(bg.cell_deg), float(tol_abs_m), float(tol_rel), matched, covered)
    return matched, covered


# ------------------------------------------------------------------------------------------- the map
class BackgroundMap:
    """World-frame range intervals per (elevation, azimuth) cell of ``cell_deg`` (module docstring)."""

    def __init__(self, cell_deg: float = 0.5):
        self.cell_deg = float(cell_deg)
        self.n_az = int(round(360.0 / cell_deg))
        self.n_el = int(round(180.0 / cell_deg))
        self.rmin = np.full((self.n_el, self.n_az), np.inf)
        self.rmax = np.full((self.n_el, self.n_az), -np.inf)
        self.frames = 0

    @property
    def cells_mapped(self) -> int:
        return int(np.isfinite(self.rmin).sum())

    def cells(self, q, pan_deg, tilt_deg):
        """(flat cell index, range [m]) of head-centre points ``q`` (N, 3), each at its pose ``pan_deg``,
        ``tilt_deg`` ((N,) or one for all) [deg]: the kernel's formulas, in numpy."""
        q = np.asarray(q, float).reshape(-1, 3)
        t = np.radians(np.asarray(tilt_deg, float))
        ct, st = np.cos(t), np.sin(t)
        ux = ct * q[:, 0] - st * q[:, 2]
        uz = st * q[:, 0] + ct * q[:, 2]
        r = np.sqrt(ux * ux + q[:, 1] * q[:, 1] + uz * uz)
        cell = math.radians(self.cell_deg)
        ok = r > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            ie = np.clip(np.floor((np.arcsin(np.clip(uz / r, -1, 1)) + 0.5 * np.pi) / cell), 0, self.n_el - 1)
        az0 = np.arctan2(q[:, 1], ux) + np.radians(np.asarray(pan_deg, float)) + np.pi
        ia = np.floor(az0 / cell).astype(np.int64) % self.n_az
        return (ie[ok].astype(np.int64) * self.n_az + ia[ok]), r[ok]

    def add(self, q, pan_deg, tilt_deg, only_new: bool = False) -> int:
        """Put points ``q`` seen at known poses (as :meth:`cells`) into the map; ``only_new``: into
        unmapped cells only.
        Returns the number of cells newly mapped."""
        idx, r = self.cells(q, pan_deg, tilt_deg)
        lo, hi = self.rmin.reshape(-1), self.rmax.reshape(-1)
        before = np.isfinite(lo)
        if only_new:
            keep = ~before[idx]
            idx, r = idx[keep], r[keep]
        np.minimum.at(lo, idx, r)
        np.maximum.at(hi, idx, r)
        self.frames += 1
        return int(np.isfinite(lo).sum() - before.sum())


# ----------------------------------------------------------------------------------------- the check
@dataclass(frozen=True)
class PoseCheckResult:
    """One check: ``kind`` (KINDS), the best offset [deg] (estimate + offset = where the background
    says the head points; 0 on an unobservable axis), the fractions it rests on, and whether each
    axis was observable."""
    kind: str
    dpan_deg: float = 0.0
    dtilt_deg: float = 0.0
    points: int = 0
    coverage: float = 0.0     # points on mapped cells at the estimate / points
    match: float = 0.0        # matches at the best offset / points on mapped cells there
    match_at_estimate: float = 0.0
    pan_observable: bool = False
    tilt_observable: bool = False

    def vouches(self, within_deg: float = 1.0) -> bool:
        """Whether this check vouches for the pose the detections before it were placed with: "ok" with
        an offset within ``within_deg`` (drift between two checks is ~0.1 deg; a larger offset says the
        pose was going wrong, e.g. a check of the frame in which the head lost power, "ok" at 2.85 deg,
        match 0.65, after which the detections carried the dead reckoning's 13 deg/s)."""
        return self.kind == "ok" and max(abs(self.dpan_deg), abs(self.dtilt_deg)) <= within_deg

    def as_event(self) -> dict:
        return {"kind": self.kind, "dpan_deg": round(self.dpan_deg, 3), "dtilt_deg": round(self.dtilt_deg, 3),
                "points": self.points, "coverage": round(self.coverage, 3), "match": round(self.match, 3),
                "match_at_estimate": round(self.match_at_estimate, 3), "pan_observable": self.pan_observable,
                "tilt_observable": self.tilt_observable}


def head_points(xyz, lidar_offset_m, min_range_m: float, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """The usable points of a frame in head-centre coordinates (finite, not "no return", beyond
    ``min_range_m``), thinned to at most ``max_points`` by a fixed stride (same frame, same points);
    and their indices in ``xyz``."""
    p = np.asarray(xyz, float).reshape(-1, 3)
    with np.errstate(invalid="ignore"):
        q = p + np.asarray(lidar_offset_m, float)
        ok = np.isfinite(p).all(axis=1) & (p != 0.0).any(axis=1) & ((q * q).sum(axis=1) >= min_range_m ** 2)
    idx = np.flatnonzero(ok)
    if len(idx) > max_points:
        idx = idx[:: int(math.ceil(len(idx) / max_points))]
    return np.ascontiguousarray(q[idx]), idx


def check_pose(q, pan_deg, tilt_deg, bg: BackgroundMap, cfg: PoseCheckConfig) -> PoseCheckResult:
    """Register head-centre points ``q`` against the map around the estimated pose (module docstring):
    ``pan_deg``, ``tilt_deg`` each point's estimated pose ((N,) or one for all) [deg]."""
    n = len(q)
    if n < cfg.min_points or bg.frames == 0:
        return PoseCheckResult("inconclusive", points=n)
    tol = (cfg.range_tol_m, cfg.range_tol_rel)
    m0, c0 = match_counts(q, pan_deg, tilt_deg, [0.0], [0.0], bg, *tol)
    coverage = c0[0, 0] / n
    at_est = m0[0, 0] / max(c0[0, 0], 1)
    if coverage < cfg.min_coverage:
        return PoseCheckResult("inconclusive", points=n, coverage=coverage, match_at_estimate=at_est)
    k = int(round(cfg.search_deg / cfg.coarse_step_deg))
    grid = np.arange(-k, k + 1) * cfg.coarse_step_deg
    least = max(1, int(cfg.min_coverage * n))

    def fraction(matched, covered):
        """Matches per point on mapped cells; 0 where too few points land on mapped cells.  A fraction,
        not a count: shifting the points along the edge of the map changes how many are covered, which
        says nothing about the pose (a ground alone would make pan look observable)."""
        return np.where(covered >= least, matched / np.maximum(covered, 1), 0.0)

    f = fraction(*match_counts(q, pan_deg, tilt_deg, grid, grid, bg, *tol))
    i, j = np.unravel_index(int(np.argmax(f)), f.shape)    # first of equal maxima: the row-major order
    # observability: how far the best stands above the typical offset along each axis (a peak, not a
    # slope: along the edge of the map the match drifts by a few hundredths even on a flat ground)
    pan_obs = bool(f[i].max() - np.median(f[i]) >= cfg.min_contrast)
    tilt_obs = bool(f[:, j].max() - np.median(f[:, j]) >= cfg.min_contrast)
    dt0 = grid[i] if tilt_obs else 0.0
    dp0 = grid[j] if pan_obs else 0.0
    # Refined one axis at a time (the axes hardly couple: pan turns about the vertical, tilt about the
    # stage's y; a joint fine grid cost 5x more for the same answer).  The match forms a plateau around
    # the truth (a cell's interval absorbs a shift within it): its centre, not its first maximum, is
    # the estimate.
    kf = int(round(cfg.coarse_step_deg / cfg.fine_step_deg))
    fine = np.arange(-kf, kf + 1) * cfg.fine_step_deg
    dp = dp0
    if pan_obs:
        fp = fraction(*match_counts(q, pan_deg, tilt_deg, [dt0], dp0 + fine, bg, *tol))[0]
        dp = float((dp0 + fine)[fp >= fp.max() - cfg.plateau_frac].mean())
    dt = dt0
    if tilt_obs:
        ft = fraction(*match_counts(q, pan_deg, tilt_deg, dt0 + fine, [dp], bg, *tol))[:, 0]
        dt = float((dt0 + fine)[ft >= ft.max() - cfg.plateau_frac].mean())
    mf, cf = match_counts(q, pan_deg, tilt_deg, [dt], [dp], bg, *tol)
    match = mf[0, 0] / max(cf[0, 0], 1)
    beyond = (pan_obs and abs(dp) > cfg.bound_deg) or (tilt_obs and abs(dt) > cfg.bound_deg)
    kind = "mismatch" if beyond or match < cfg.min_match else "ok"
    return PoseCheckResult(kind, dp, dt, n, float(coverage), float(match), float(at_est), bool(pan_obs), bool(tilt_obs))


class ScaleWitness:
    """Fits ``pan drift = k * pan travel`` (least squares through 0) over the checks, each a point of
    the drift the dead reckoning alone would have had by then (the offset found plus every correction
    applied) against the pan travel it reckoned (signed, unwrapped), both since a reference check;
    ``-k`` is the speed table's relative error (a table 10 % fast overestimates every turn by 10 %: the
    background finds the head 10 % of the travel short of the estimate).  Cumulative, so one check's
    noise is not differenced into every step.  The table's error depends on the byte (units
    differ most at low bytes: unit 7's speeds are 40 % above unit 3's at byte 10, 4 % at byte 50), so
    ``k`` is the error of the bytes the run used, weighted by their travel.

    It warns once the travel reaches ``warn_travel_deg``, ``|k|`` reaches ``warn_rel``, and ``k`` stands
    at least ``sigmas`` standard errors from 0 (each check's pan offset is noisy by ~0.1-0.2 deg)."""

    def __init__(self, warn_rel: float, warn_travel_deg: float, sigmas: float = 4.0):
        self.warn_rel, self.warn_travel_deg, self.sigmas = warn_rel, warn_travel_deg, sigmas
        self.sxy = self.sxx = self.syy = 0.0
        self.n = 0
        self.travel_deg = 0.0
        self.warned = False
        self._last_travel = 0.0

    def restart(self) -> None:
        """A new reference (the tracker was rebased): the next point's travel counts from 0 again."""
        self._last_travel = 0.0

    def add(self, travel_deg: float, drift_deg: float) -> None:
        """The dead reckoning's pan travel [deg] since the reference and its drift [deg] (true - estimate,
        corrections undone) since then."""
        self.sxy += travel_deg * drift_deg
        self.sxx += travel_deg * travel_deg
        self.syy += drift_deg * drift_deg
        self.n += 1
        self.travel_deg += abs(travel_deg - self._last_travel)
        self._last_travel = travel_deg

    @property
    def table_error_rel(self) -> float | None:
        """The speed table's relative error seen so far (+ = the table's speeds too high), or None."""
        return -self.sxy / self.sxx if self.sxx > 0 else None

    @property
    def table_error_sigma(self) -> float | None:
        """The standard error of :attr:`table_error_rel`, or None."""
        if self.n < 3 or self.sxx <= 0:
            return None
        ss = max(self.syy - self.sxy * self.sxy / self.sxx, 0.0)
        return math.sqrt(ss / (self.n - 1) / self.sxx)

    def warning(self) -> str | None:
        """A warning, once, when the table looks like another unit's."""
        e, s = self.table_error_rel, self.table_error_sigma
        if (self.warned or e is None or s is None or self.travel_deg < self.warn_travel_deg
                or abs(e) < self.warn_rel or abs(e) < self.sigmas * s):
            return None
        self.warned = True
        return (f"the background says the pan speed table is {100 * e:+.0f} % (+-{100 * s:.0f} %) off over "
                f"{self.travel_deg:.0f} deg of pan travel: a speed table of another unit, or a head that slips? "
                "Measure this head's table (foveatrack calibrate) and set [head] speed_table")


class PoseCheck:
    """The pose check of one driver run: the map, the pace of checks, the witness of the speed table.

    Drivers call :meth:`map_frame` at the known start pose until :attr:`mapped`, then :meth:`on_frame`
    with each frame and the tracker's dead reckoning (``angles_at(t_s) -> (pan, tilt, ...)``); the result
    is None (not checked) or a :class:`PoseCheckResult`, whose offset the driver applies (``ok``:
    :meth:`correction`, which also tells the witness of the speed table what was applied) or takes as an
    unknown pose (``mismatch``).
    """

    def __init__(self, cfg: PoseCheckConfig, lidar_offset_m=(0.0, 0.0, 0.0)):
        self.cfg = cfg
        self.offset = np.asarray(lidar_offset_m, float)
        self.map = BackgroundMap(cfg.cell_deg)
        self.next_check_s = -math.inf
        self.not_before_s = -math.inf     # no check of a frame begun before the last rebase (rebased)
        self.checks = {k: 0 for k in KINDS}
        self.witness = ScaleWitness(cfg.table_warn_rel, cfg.table_warn_travel_deg)
        self._applied_pan = 0.0          # pan corrections applied since the reference [deg]
        self._ref: list | None = None    # [uncorrected pan at the last check, travel so far, drift at the reference]

    @property
    def mapped(self) -> bool:
        return self.map.frames >= self.cfg.map_frames

    def _points(self, xyz):
        c = self.cfg
        return head_points(xyz, self.offset, c.min_range_m, c.max_points)

    def map_frame(self, xyz, pan_deg: float, tilt_deg: float) -> None:
        """A frame at a known pose, head at rest, into the map."""
        self.map.add(self._points(xyz)[0], pan_deg, tilt_deg)

    def at_pose(self, xyz, pan_deg: float, tilt_deg: float) -> PoseCheckResult | None:
        """One frame checked against the map with the head taken to be at rest at ``(pan_deg,
        tilt_deg)``, nothing else changed (no map extension, no period): a homing's wait ends when
        the background shows the head at the goal (:mod:`foveatrack.daemon.homing_plan`).  None
        before the map is made."""
        if not self.mapped:
            return None
        return check_pose(self._points(xyz)[0], pan_deg, tilt_deg, self.map, self.cfg)

    def rebased(self, t0_s: float = -math.inf) -> None:
        """The tracker restarted at sensor time ``t0_s`` (a homing, a new lidar clock): the next check may
        come with the first frame that starts at ``t0_s`` or later, and the pan travel starts again from
        the new pose.  A frame begun before ``t0_s`` is not checked: its first points belong to the
        time before the restart (in a suite run sharing two cores with three other processes, the first
        check after a homing took a frame begun 31 ms before it ended, found "ok" at pan +0.0 / tilt
        +1.3 deg with match 0.62, and so verified a head the lidar does not sit on; every later check
        put the lidar 7 deg away)."""
        self.next_check_s = -math.inf
        self.not_before_s = t0_s
        self._applied_pan = 0.0
        self._ref = None
        self.witness.restart()

    def on_frame(self, xyz, t_ns, t_start_s: float, t_end_s: float, angles_at) -> PoseCheckResult | None:
        """Check one frame (points ``xyz`` (N, 3) lidar frame, times ``t_ns`` (N,)) against the map,
        each point at the estimated pose of its own time (``angles_at``, sampled at the frame's start,
        middle and end and interpolated: the head's speed changes little within a frame)."""
        c = self.cfg
        if not self.mapped or t_end_s < self.next_check_s or t_start_s < self.not_before_s:
            return None
        knots = np.array([t_start_s, 0.5 * (t_start_s + t_end_s), t_end_s])
        poses = np.array([angles_at(float(t))[:2] for t in knots])
        pans = np.unwrap(np.radians(poses[:, 0])) * 180.0 / math.pi
        dur = max(t_end_s - t_start_s, 1e-3)
        turn = max(abs(pans[2] - pans[0]), abs(poses[2, 1] - poses[0, 1]))
        if not (np.isfinite(poses).all() and turn <= c.slow_deg_s * dur):
            return None
        self.next_check_s = t_end_s + c.period_s
        q, idx = self._points(xyz)
        t_pt = np.asarray(t_ns, np.int64)[idx] * 1e-9
        pan = np.interp(t_pt, knots, pans)
        tilt = np.interp(t_pt, knots, poses[:, 1])
        res = check_pose(q, pan, tilt, self.map, c)
        self.checks[res.kind] += 1
        if res.kind == "ok":
            if res.pan_observable:
                # the dead reckoning without the corrections: where it would say the head is, and how far
                # the background puts the head from that
                u = float(pans[1]) - self._applied_pan
                drift = res.dpan_deg + self._applied_pan
                if self._ref is None:
                    self._ref = [u, 0.0, drift]
                else:
                    self._ref[1] += ((u - self._ref[0] + 180.0) % 360.0) - 180.0
                    self._ref[0] = u
                    self.witness.add(self._ref[1], drift - self._ref[2])
            at_rest = turn <= c.rest_deg_s * dur
            if at_rest and max(abs(res.dpan_deg), abs(res.dtilt_deg)) <= c.extend_below_deg:
                self.map.add(q, pan + res.dpan_deg, tilt + res.dtilt_deg, only_new=True)
        return res

    def correction(self, res: PoseCheckResult) -> tuple[float, float]:
        """The offset [deg] a driver applies for an ``ok`` result: ``correction_gain`` of the offset
        found, (0, 0) below ``min_correction_deg``."""
        if res.kind != "ok" or max(abs(res.dpan_deg), abs(res.dtilt_deg)) < self.cfg.min_correction_deg:
            return 0.0, 0.0
        g = self.cfg.correction_gain
        self._applied_pan += g * res.dpan_deg      # the driver applies it: the witness undoes it
        return g * res.dpan_deg, g * res.dtilt_deg
