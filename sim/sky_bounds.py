"""What no tracker and no schedule could have beaten in a run of the multi-object tracker (issue 28),
from the truth and the head alone: the earliest confirmation the scan's rays on a drone allowed
(:func:`scan_allows_confirm_s`), and the shortest revisit gaps the head's speeds allowed
(:func:`head_allows_revisit_s`).  They say what part of a slow confirmation or a long gap is the
rosette's or the PTS-303's, and what part the tracker's (:mod:`sim.sky_summary` reports them beside
the measured figures).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import minimum_filter1d

from foveatrack.detection import wrap_deg
from foveatrack.speed_table import TURBO


def scan_allows_confirm_s(times_s, tracked, rays, min_points: int, confirm_hits: int,
                          confirm_window: int, reported_from: int = 0, lone_returns: bool = False) -> float | None:
    """The earliest a track built from one drone's own returns could be confirmed, from the rays the
    scan put on it (:mod:`foveatrack.sky.tracks`' rule: ``confirm_hits`` frames, each with an object of
    ``min_points`` returns or more, within ``confirm_window`` frames of the first), counted from its
    first frame hit by a ray; None: never in the run.

    A bound no tracker with that rule can beat on the drone's own returns, whatever its background
    or association: the rays are counted before the effects (a ray may return nothing) and every one
    is taken as the drone's object, off the scenery.  An object that holds other returns too (a
    second drone's a metre away, a stray's) can make ``min_points`` sooner: in swarm-of-five (seeds
    31 and 38) two drones were confirmed 0.5 and 0.9 s in where their own rays allowed 2.7 s.
    ``tracked`` (T,) bool: the frames the tracker tracks (after its warm-up; all of them for the
    bound without it).  ``reported_from``: the first frame a confirmation can be
    reported at (a tracker that tracks its warm-up's frames at the warm-up's end counts their hits,
    and says so at the first frame after it).  ``lone_returns``: the tracker's rule with lone returns
    (:class:`foveatrack.sky.tracks.SkyTrackerConfig`): the track starts at a frame of ``min_points``
    rays or more, and from then on a frame with one ray or more is a hit (the tracker takes a cluster
    of one return or an object: with ``min_points`` above 2 a frame of 2 rays counts here and not
    there, which keeps the bound a bound).  What part of a slow
    confirmation is the scan's (the rosette's sparse periphery, paper Fig. 5) and what part the
    tracker's."""
    t = np.asarray(times_s, np.float64)
    n = np.asarray(rays, np.int64)
    seen = np.flatnonzero(n > 0)
    if seen.size == 0:
        return None
    first = int(seen[0])
    tracked = np.asarray(tracked, bool)
    start = (n >= min_points) & tracked                 # a frame that can start a track
    hit = (n >= (1 if lone_returns else min_points)) & tracked
    for k in range(first, t.size):
        if not hit[k]:
            continue
        # a track started at s is confirmed at k if it has confirm_hits hits in its first
        # confirm_window frames (s itself the first)
        for s in range(max(first, k - confirm_window + 1), k + 1):
            if start[s] and int(hit[s:k + 1].sum()) >= confirm_hits:
                return float(t[max(k, reported_from)] - t[first])
    return None


def pointing_deg(xyz_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The head's pan and tilt [deg] that put world points ``xyz_m`` (..., 3) on the lidar's axis:
    :func:`foveatrack.reconstruction.rotation_matrix` turns the axis to ``(cos t cos p, cos t sin p,
    sin t)`` (the lidar's offset from the head's centre left out, as :func:`drone_truth` does)."""
    x, y, z = xyz_m[..., 0], xyz_m[..., 1], xyz_m[..., 2]
    return np.degrees(np.arctan2(y, x)), np.degrees(np.arctan2(z, np.hypot(x, y)))


def _pan_half_deg(tilt_deg: np.ndarray, half_deg: float) -> np.ndarray:
    """The widest pan [deg] a cone of half-angle ``half_deg`` spans at a point of tilt ``tilt_deg``
    on its rim or inside it: ``asin(sin h / cos e)`` with the axis's elevation ``e`` taken as far from
    the horizon as the cone lets it (``|tilt| + h``), so that it bounds every such cone."""
    e = np.radians(np.minimum(np.abs(tilt_deg) + half_deg, 89.9))
    return np.degrees(np.arcsin(np.minimum(1.0, np.sin(np.radians(half_deg)) / np.cos(e))))


def _pair_bound_s(tau_s: np.ndarray, dt: float) -> float:
    """The pair's bound over one run of frames both drones are in (:func:`head_allows_revisit_s`):
    if neither gap exceeded ``G = n dt``, every window of ``2 n + 2`` frames holds a trip there and
    back, so twice its smallest ``tau`` is at most ``G`` (one frame given for the frames' sampling).
    The bound is ``(n + 1) dt`` for the largest ``n`` some window breaks that for.  A wider window's
    least ``tau`` is no larger while ``G`` grows, so the windows that break it are those up to some
    ``n``: found by bisection, each width's window minima in one pass (an hour's run is 36 000
    frames; trying every width was cubic in them)."""
    def broken(n: int) -> bool:
        w = 2 * n + 2
        mins = minimum_filter1d(tau_s, w, mode="nearest", origin=-(w // 2))[:tau_s.size - w + 1]
        return 2.0 * float(mins.max()) - dt > n * dt + 1e-9

    lo, hi = 0, (tau_s.size - 2) // 2        # broken(lo) or lo == 0; the answer is in [lo, hi]
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if broken(mid):
            lo = mid
        else:
            hi = mid - 1
    return (lo + 1) * dt if lo >= 1 or (tau_s.size >= 2 and broken(0)) else 0.0


def _leg_s(d_deg: np.ndarray, v: float, a: float) -> np.ndarray:
    """The least time [s] an axis of top speed ``v`` and acceleration ``a`` takes to turn ``d_deg``
    starting or ending at rest: ``d / v + v / (2 a)``, or ``sqrt(2 d / a)`` if it never reaches ``v``."""
    d = np.maximum(d_deg, 0.0)
    return np.where(d >= v * v / (2.0 * a), d / v + v / (2.0 * a), np.sqrt(2.0 * d / a))


def head_allows_revisit_s(times_s, head_pan_deg, head_tilt_deg, drones: dict, head_limits,
                          fovea_half_deg: float) -> dict:
    """Lower bounds, from the head's top speeds alone, on the longest revisit gaps
    (:func:`foveatrack.sky.metrics.drone_metrics`' ``longest_revisit_gap_s``) of a run: what no
    schedule of the fovea could have beaten with this head, as :func:`scan_allows_confirm_s` is for
    the confirmation.

    ``drones``: id -> ``xyz_m`` (T, 3) (NaN where absent), ``in_field`` (T,) bool and ``first_s`` (the
    time its first confirmed track was matched, None: never; its gaps are counted from then on, up to
    its last frame in the field).  ``head_pan_deg``, ``head_tilt_deg``: the head's true pose per frame.
    ``head_limits``: top speeds [deg/s] and accelerations [deg/s^2], ``(pan v, tilt v, pan a, tilt a)``.
    The fovea is the cone of ``fovea_half_deg`` about the axis.

    * ``acquire_s`` (per drone): from the head's pose at ``first_s``, the first frame at which both
      axes, turning at top speed from then on (whatever they were doing then, so no acceleration
      counted), could have put the drone in the fovea (tilt within
      ``h``, pan within :func:`_pan_half_deg`); its first gap lasts at least that long (the whole
      window if never);
    * ``pairs`` (per two drones, both past ``first_s`` and in the field over a run of ``W`` s): the
      fovea holds both at once only if their axes differ by under ``2 h``; else going from one to the
      other and back turns an axis by its excess over ``2 h`` each way, with a stop between, so each
      way takes at least ``tau`` (:func:`_leg_s`, the longer axis).  If neither
      drone's gap exceeded ``G < W / 2``, the first ``G`` s of the run hold a visit to each, say to A
      before B; the ``G`` s after that visit to B hold another to A, and A's gap around B's visit is
      at least ``2 tau``, ``tau``'s least over those ``2 G`` s: the longer of their longest gaps is
      over ``G`` wherever some ``2 G`` s of the run have ``2 tau > G`` (:func:`_pair_bound_s`);
    * ``bound_s``: the largest of all of these: this run's longest gap could not have been shorter.

    The head's dead time and the frame's latency are left out (and the acceleration where said): each
    only adds."""
    t = np.asarray(times_s, np.float64)
    T = t.size
    dt = float(np.median(np.diff(t))) if T > 1 else 0.0
    vp, vt, ap, at = (float(v) for v in head_limits)
    h = float(fovea_half_deg)
    pan0 = np.asarray(head_pan_deg, np.float64)
    tilt0 = np.asarray(head_tilt_deg, np.float64)
    win, aim = {}, {}
    for d, a in drones.items():
        field = np.asarray(a["in_field"], bool)
        if a.get("first_s") is None or not field.any():
            continue
        k0 = int(np.searchsorted(t, a["first_s"] - 1e-9))
        end = int(np.flatnonzero(field)[-1]) + 1
        if k0 >= end:
            continue
        win[d] = (k0, end)
        aim[d] = pointing_deg(np.asarray(a["xyz_m"], np.float64))
    acquire = {}
    for d, (k0, end) in win.items():
        p, q = aim[d]
        ks = np.arange(k0, end)
        dpan = np.abs(wrap_deg(p[ks] - pan0[k0])) - _pan_half_deg(q[ks], h)
        dtilt = np.abs(q[ks] - tilt0[k0]) - h
        reach = t[ks] - t[k0]
        with np.errstate(invalid="ignore"):     # NaN where the drone is absent: not reachable there
            ok = (dpan <= vp * reach + 1e-9) & (dtilt <= vt * reach + 1e-9)
        acquire[d] = float(t[ks[np.argmax(ok)]] - t[k0]) if ok.any() else (end - k0) * dt
    pairs = {}
    ids = sorted(win)
    for i, a in enumerate(ids):
        for b in ids[i + 1:]:
            both = np.zeros(T, bool)
            lo, hi = max(win[a][0], win[b][0]), min(win[a][1], win[b][1])
            if hi <= lo:
                continue
            both[lo:hi] = (np.asarray(drones[a]["in_field"], bool)[lo:hi]
                           & np.asarray(drones[b]["in_field"], bool)[lo:hi])
            (pa, qa), (pb, qb) = aim[a], aim[b]
            dpan = np.abs(wrap_deg(pa - pb)) - 2.0 * _pan_half_deg(
                np.maximum(np.abs(qa), np.abs(qb)), h)
            with np.errstate(invalid="ignore"):
                tau = np.maximum(_leg_s(dpan, vp, ap), _leg_s(np.abs(qa - qb) - 2.0 * h, vt, at))
            k = np.flatnonzero(both)
            runs = np.split(k, np.flatnonzero(np.diff(k) > 1) + 1)      # the stretches both are in
            pairs[(a, b)] = max(_pair_bound_s(tau[run], dt) for run in runs)
    bound = max(list(acquire.values()) + list(pairs.values()), default=None)
    return {"acquire_s": acquire, "pairs": pairs, "bound_s": bound}


def head_limits(loop) -> tuple[float, float, float, float]:
    """The simulated head's true top speeds [deg/s] over the bytes its tracker may send (pan's turbo
    byte only where the tracker may use it) and its accelerations [deg/s^2]: pan v, tilt v, pan a,
    tilt a."""
    head = loop.head
    pan = [head.true_speed_deg_s("pan", b) for b in range(64)]
    if loop.tracker.config.allow_turbo:
        pan.append(head.true_speed_deg_s("pan", TURBO))
    p = head.params
    return (max(pan), max(head.true_speed_deg_s("tilt", b) for b in range(64)),
            p.pan_accel_deg_s2, p.tilt_accel_deg_s2)
