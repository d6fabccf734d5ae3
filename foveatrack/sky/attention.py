"""Which track the fovea serves: the priority track, with saccades to every other confirmed drone
that has gone too long without the fovea (issue 28).

Threat score of a confirmed track (0 for tentative ones), with ``d`` its distance to the protected
point ``protected_xyz_m`` and ``s`` its closing speed on it (``-v . (p - c) / |p - c|``, > 0 when
it comes nearer; negative values count as 0)::

    score = class_weight[looks_like] * (1 + s / closing_ref_m_s) * distance_ref_m / (distance_ref_m + d)

``looks_like`` is what the classifier's rules say of the track now, before its label waits
(:mod:`foveatrack.sky.classify` rule 5): the fovea looks at a possible drone, and its resolution
helps decide what it is.  With ``keep_verdict`` (the default), while the rules say unknown because
the track's window holds too few hits -- the only way they say it, and what a track gets out of the
fovea, where the rosette is sparse -- it goes by its last label other than unknown
(:meth:`Attention.looks_like`): no news is not a verdict.  Without it a drone left for a revisit of
another soon looked unknown, lost the priority (the head turned back before it got there) and was no
longer revisited itself: on three blocks of 30 tuning seeds (+200..+289) the swarm's median longest
revisit gap 6.2 -> 5.3, 4.6 -> 4.6 and 5.2 -> 4.9 s with it, the flock's runs with every gap within
3 s 25 -> 25, 19 -> 20 and 22 -> 23, the crossing and the tree line unchanged.  The label, not the
look: a bird's track that looked like a drone for a frame and kept that look took the fovea from the
drone (flock, +260..+289: runs with every gap within 3 s 22 -> 19, id switches 22 -> 29); the label
waits for rule 5.

``class_weight``: drone 1.0, unknown 0.5 (not classified yet: a drone until shown otherwise, but
after the drones), bird 0.05, clutter 0.  So a drone closing at 10 m/s counts twice one hovering at
the same distance, and one at ``distance_ref_m`` half one at the protected point.  Ties go to the
lower id.

Schedule (evaluated after each frame, for the next):

* the *priority track* is the highest score (an operator's pin, :meth:`Attention.pin`, overrides it
  while the pinned track lives);
* a *revisit* is due for every other confirmed track that looks like a drone once its clock -- its
  last frame in the fovea, the end of its last revisit, or its confirmation -- is older than
  ``revisit_s``; for a track *labelled* drone, once it will be older by the time the head can have
  brought it into the fovea (its *saccade time*, below), unless its last revisit timed out before
  the fovea got there (then the saccade time is not taken off: a track the tilt cannot reach in time,
  at 2 deg/s, was due again the moment it was given up on).  The most overdue one is served first,
  and one revisit follows another without a return to the priority track while the next is due.  No
  revisit starts while the head is still turning to the priority track (until it has been in the
  fovea, or ``saccade_timeout_s`` after the turn began);
* with no confirmed track, the fovea goes to the tentative track with the most hits off the scenery
  (at least ``verify_min_hits``): a saccade to verify what the field's sparse rim only hints at;
* the priority track without a hit for ``drop_unseen_priority_s`` (1.5 s) since the fovea was
  given to it, or since its last hit, is set aside -- no priority -- until a hit comes: a coasting
  track whose object is gone (a bird's, flown on faster than its prediction, or left behind by it)
  had the head chase its prediction for up to ``lost_out_of_view_s`` (the track the fovea turns to
  is exempt from the loss clock in the field), 20-40 m from any object on drone-and-flock seed 2.
  A drone the head is turning to at the sparse rim may go that long without a hit too, and is set
  aside as well; a drone in the fovea is hit every frame or two.  Chosen on seeds +200..+229 of the
  four sky scenes (1.5 and 2 s, counted from the fovea's turn alone; then from the last hit too, a
  reviewer's find: a prediction the head had caught up with was never set aside): the flock's
  worst longest gap 17.9 -> 7.4 s, the frames of its drones' longest gaps with no track on the
  drone 335 -> 108, runs within 3 s 24 -> 26, the tree line's worst gap 9.9 -> 7.9 s; checked on
  +230..+259: the flock's longest gaps' frames 1164 -> 925, its worst 17.1 -> 14.7 s, runs within
  3 s 20 -> 21, id switches 19 -> 17; the crossing unchanged in both, the swarm's id switches within
  one.  0: never (as recordings made before it ran).  The unseen time is summed over every
  fixation since the track's last hit (``unseen_over_fixations``): two coasting tracks of birds the
  fovea was given to in turn each restarted the other's clock, and the head chased them 3.1 s (the
  flock, seed +201 with lone returns: track 18 from 5.1 to 8.3 s, 23 between).  False: counted from
  the last turn to it alone (recordings made before it).  On seeds +230..+259 of the flock without
  lone returns: runs with every revisit within 3 s 21 -> 24 of 30; the other scenes, and +200..+229,
  the same;
* with nothing to serve (no confirmed track that scores, no candidate), the head holds where it
  looks: the field keeps watching at its sparse density and a drone there is found again.  The
  paper tracker's lost-target search (its ``search``, a sweep at 5 deg/s in the last direction)
  is for a single target lost from a narrow D; run by the sky tracker it turned the head away from
  the field it watched (tree line, seed 220: the drone's first track was lost at the sparse rim and
  nothing was left to serve from 2.9 s; the head swept 81 deg by the run's end and the drone was
  never in the fovea again; held, a track on it was found at 6.1 s and it was in the fovea from
  9.1 s.  Seed 230 showed it first, before the priority's set-aside changed that run).  ``idle_search`` (default false) brings the sweep back, as
  recordings made before it ran;
* an operator's pin (:meth:`Attention.pin`) holds the fovea on the pinned track while it lives
  (``pin_holds_fovea``, default true): no revisit starts, and one in progress ends, its track's
  clock running on.  A pin is an operator locking on; the revisits, each followed at once by the next
  one due, took the fovea from a pinned track for 5-7 s at a time on the swarm (the daemon, a user's
  audit: in the fovea 97 of 256 pinned frames).  The other drones keep their tracks in the wide
  field.  False: the pinned track is the priority and the revisits go on (as recordings made
  before the key ran);
* a revisit fixation lasts until the track has been in the fovea for ``dwell_s``, or
  ``saccade_timeout_s`` after it started if the head never got there (a track the head cannot
  reach does not hold the fovea); then the fovea returns to the priority track.

A track is *in the fovea* when its predicted bearing lies within ``fovea_half_angle_deg`` of the
lidar's axis at the frame's mid pose (the rosette's dense centre, paper Fig. 5).

Saccade gain (``saccade_gain_1_s``, default None: Algorithm 2's own gain): while the fixated track is
off the fovea the head turns to it at this gain instead, ``v = min(k_s |e|, v_max)`` (the paper's
Algorithm 2 still tracks inside the fovea).  A measured trade-off, not the default: at 4 /s (with
``saccade_latency_s = 0.6``, what such saccades take) an hour of cold starts of each sky scene met the
3 s revisit in 102, 5 and 81 runs of 180 (tree line, crossing, flock; 94, 0 and 71 without), and made
43 false drone tracks near crowns and 27 near birds where Algorithm 2's gain made 33 and 17
(docs/sky-tracks-figures.md).

Saccade time (:func:`saccade_time_s`): the head turns each axis under the paper's Algorithm 2 (App.
D.3) at the saccade gain, ``v = min(k |e|, v_max)``, so an axis ``e`` away takes
``(e - max(v_max/k, h)) / v_max`` at full speed and then ``ln(min(e, v_max/k) / h) / k`` on the proportional tail (if that is above
``h``) to come within ``h`` (the fovea's half angle) of it; both axes turn at once (the longer
counts), plus ``saccade_latency_s`` (the next command's frame, the head's dead time and
acceleration).  Without it a revisit started when the clock had run out and the head's turn came on top: two drones 25-36 deg
apart were out of the fovea up to 6.4 s with a 3 s revisit time, 4.1 s with it, in the 32 runs it was
chosen on (over an hour of runs: median 4.0 -> 3.6 s; docs/sky-tracks-figures.md, which also gives
what it costs).  Only tracks labelled drone get it: a crown part that looks like a drone for a moment
is revisited no sooner than before.

With ``saccade_counts_motion`` (an option, not the default) each axis of a saccade time also counts the
track's own bearing rate there (from its velocity: one drawing away at ``w`` is closed at
``v_max - w``, and trails the proportional tail by ``w / k``) and the head's speed now (an axis
turning away from the track first stops, at its calibrated acceleration, while the error grows), and
no saccade is planned for longer than ``saccade_timeout_s``, how long a revisit waits for the head;
without it (what recordings made before it ran) all three are left out.  Revisits reached the fovea
a median 0.38 s later than planned without it on the crossing's tuning seeds +200..+214 (its drones
draw apart at up to 5 deg/s, and the head is often turning away from the one revisited), 0.15 s
with it; on the swarm's, 0.19 and 0.13 s.  A measured trade-off: the revisits start sooner, so the
priority drone's track leaves the fovea with fewer hits behind it, and one left 3.4 s at the sparse
rim drifted past the association's bound and took a new id (the crossing's cold hour, with
``keep_verdict``: id switches 10 -> 12 of 360 drone-runs, one of them on the eight report seeds,
seed 33; median longest gap 3.6 -> 3.4 s; docs/sky-tracks-figures.md).  The must-show asks for no
id switch on the crossing, so it stays off.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

import numpy as np
from numba import njit

from foveatrack.config_util import as_bool, as_float, as_vec, check_keys
from foveatrack.errors import UserError
from foveatrack.fixed_order import floats3, rows_T_times
from foveatrack.reconstruction import rotation_matrix

_NO_OFFSET = np.zeros(3)
CLASS_WEIGHT = {"drone": 1.0, "unknown": 0.5, "bird": 0.05, "clutter": 0.0}
#: the keys the attention has gained since recordings were made, at the values that behave as before
#: them: a recording's table without them replays as it ran (:func:`foveatrack.sky.controller.recorded_sky_table`)
ADDED_SINCE_RECORDED = {"saccade_counts_motion": False, "keep_verdict": False, "idle_search": True,
                        "drop_unseen_priority_s": 0.0, "unseen_over_fixations": False, "pin_holds_fovea": False}


@dataclass(frozen=True)
class AttentionConfig:
    """Parameters of :class:`Attention` (a ``[sky.attention]`` table; module docstring)."""
    protected_xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    distance_ref_m: float = 50.0
    closing_ref_m_s: float = 10.0
    revisit_s: float = 3.0
    dwell_s: float = 0.5
    saccade_timeout_s: float = 2.0
    fovea_half_angle_deg: float = 3.0
    verify_min_hits: float = 1.0
    saccade_latency_s: float = 0.3
    saccade_gain_1_s: float | None = None
    saccade_counts_motion: bool = False
    keep_verdict: bool = True
    idle_search: bool = False
    drop_unseen_priority_s: float = 1.5
    unseen_over_fixations: bool = True
    pin_holds_fovea: bool = True

    @classmethod
    def from_mapping(cls, data: Mapping, where: str) -> "AttentionConfig":
        check_keys(data, [f.name for f in fields(cls)], where)
        kw = {}
        for k, v in data.items():
            if k == "protected_xyz_m":
                kw[k] = as_vec(v, k, where, 3)
            elif k in ("saccade_counts_motion", "keep_verdict", "idle_search", "unseen_over_fixations",
                       "pin_holds_fovea"):
                kw[k] = as_bool(v, k, where)
            elif k in ("saccade_latency_s", "drop_unseen_priority_s"):
                kw[k] = as_float(v, k, where, lo=0)
            elif k == "saccade_gain_1_s" and v is None:     # a recording's table: Algorithm 2's own gain
                kw[k] = None
            else:
                kw[k] = as_float(v, k, where, lo=0, lo_open=True)
        return cls(**kw)


def axis_turn_s(error_deg: float, within_deg: float, gain_1_s: float, vmax_deg_s: float,
                rate_deg_s: float = 0.0, speed_deg_s: float = 0.0, accel_deg_s2: float | None = None) -> float:
    """Time [s] for an axis under Algorithm 2 (``v = min(gain |e|, vmax)``, no dead band) to bring
    an error of ``error_deg`` (signed: target minus axis) within ``within_deg`` (module docstring,
    "Saccade time").

    ``rate_deg_s``: the target's own bearing rate on this axis (signed like the error); one drawing
    away is closed at ``vmax - rate`` and trails Algorithm 2's tail by ``rate / gain``, so one that
    trails by ``within_deg`` or more is never brought within it (``inf``).  ``speed_deg_s``: the axis's
    speed now; turning away from the target, it first stops, at ``accel_deg_s2`` (None: at once),
    while the error grows.  With both 0 this is the module docstring's closed form, to the bit."""
    s = 1.0 if error_deg >= 0.0 else -1.0
    e = abs(error_deg)
    w = s * rate_deg_s            # > 0: the target draws away along this axis
    u = s * speed_deg_s           # < 0: the axis turns away from it now
    stop = 0.0
    if u < 0.0 and accel_deg_s2:
        stop = -u / accel_deg_s2
        e += u * u / (2.0 * accel_deg_s2) + w * stop
    if e <= within_deg:
        return stop
    close = vmax_deg_s - w
    if close <= 0.0:
        return math.inf
    knee = vmax_deg_s / gain_1_s          # below this error the speed is proportional
    full = (e - max(knee, within_deg)) / close if e > knee else 0.0
    e1, lag = min(e, knee), w / gain_1_s
    if e1 <= within_deg:
        return stop + full
    if within_deg <= lag:
        return math.inf
    return stop + full + math.log((e1 - lag) / (within_deg - lag)) / gain_1_s


def saccade_time_s(e_pan_deg: float, e_tilt_deg: float, cfg: "AttentionConfig", head,
                   rates=(0.0, 0.0), speeds=(0.0, 0.0), accels=(None, None)) -> float:
    """Time [s] for the head to bring a bearing ``e_pan_deg`` / ``e_tilt_deg`` off its axis into the
    fovea: both axes at once, plus ``cfg.saccade_latency_s``; with ``cfg.saccade_counts_motion``,
    never more than that plus ``cfg.saccade_timeout_s``, how long the attention waits for a saccade
    (without it ``rates``, ``speeds`` and ``accels`` are not used, and there is no bound).  ``head``: (pan gain [1/s],
    pan top speed [deg/s], tilt gain, tilt top speed); ``rates``, ``speeds``, ``accels``: per axis
    (pan, tilt), :func:`axis_turn_s`'s."""
    kp, vp, kt, vt = head
    h = cfg.fovea_half_angle_deg
    if not cfg.saccade_counts_motion:
        return cfg.saccade_latency_s + max(axis_turn_s(e_pan_deg, h, kp, vp), axis_turn_s(e_tilt_deg, h, kt, vt))
    pan = axis_turn_s(e_pan_deg, h, kp, vp, rates[0], speeds[0], accels[0])
    tilt = axis_turn_s(e_tilt_deg, h, kt, vt, rates[1], speeds[1], accels[1])
    cap = cfg.saccade_timeout_s
    # an axis's time NaN (a bearing or its rate unknown) plans the longest saccade, as one the head
    # cannot close on: a NaN lead is past no clock, and the track was never revisited again
    turn = max(pan, tilt) if pan <= cap and tilt <= cap else cap
    return cfg.saccade_latency_s + turn


@njit(cache=True)
def _axis_turn_still_s(error_deg, within_deg, gain_1_s, vmax_deg_s):
    """:func:`axis_turn_s` with no bearing rate, the axis at rest and no acceleration given: its
    operations in their order, less those of the zero terms, which change no bit (its stop time 0.0
    added to a time that is >= 0 or NaN, its rate +-0 taken from the top speed, its lag +-0 from the
    errors; a gain > 0, as the configuration has it); Python's ``min``/``max`` as written: the first
    unless the second is smaller/larger, NaN too."""
    e = abs(error_deg)
    if e <= within_deg:
        return 0.0
    if vmax_deg_s <= 0.0:
        return math.inf
    knee = vmax_deg_s / gain_1_s
    if e > knee:
        full = (e - (within_deg if within_deg > knee else knee)) / vmax_deg_s
    else:
        full = 0.0
    e1 = knee if knee < e else e
    if e1 <= within_deg:
        return full
    if within_deg <= 0.0:
        return math.inf
    return full + math.log(e1 / within_deg) / gain_1_s


@njit(cache=True)
def fovea_turns_kernel(P, mid, mid_off, end, end_off, within_deg, latency_s, kp, vp, kt, vt, q_mid, turn):
    """Per confirmed track at the world point ``P[i]`` (N, 3): the point in the lidar frame at the mid
    pose into ``q_mid[i]`` (:func:`in_lidar` of ``mid``, the rotation's rows flat (9,), and ``mid_off``
    (3,)), and its saccade time from the end pose (``end``, ``end_off``) into ``turn[i]``:
    :func:`saccade_time_s` of :func:`foveatrack.detection.bearing_deg` of :func:`in_lidar`, without
    the motion (``saccade_counts_motion`` off), the head ``(kp, vp, kt, vt)``.  The same operations
    in their order, libm's atan2, hypot and log as CPython's math and numpy call them (twins: those
    functions; ``tests/sky/test_attention.py``)."""
    for i in range(P.shape[0]):
        x = P[i, 0]
        y = P[i, 1]
        z = P[i, 2]
        q_mid[i, 0] = mid[0] * x + mid[3] * y + mid[6] * z - mid_off[0]
        q_mid[i, 1] = mid[1] * x + mid[4] * y + mid[7] * z - mid_off[1]
        q_mid[i, 2] = mid[2] * x + mid[5] * y + mid[8] * z - mid_off[2]
        qx = end[0] * x + end[3] * y + end[6] * z - end_off[0]
        qy = end[1] * x + end[4] * y + end[7] * z - end_off[1]
        qz = end[2] * x + end[5] * y + end[8] * z - end_off[2]
        az = math.degrees(math.atan2(qy, qx + 0.0))
        if not (-180.0 < az <= 180.0):      # wrap_deg's scalar form (C fmod)
            w = np.fmod(az + 180.0, 360.0)
            w = (w + 360.0 if w < 0.0 else w) - 180.0
            az = 180.0 if w == -180.0 else w
        el = math.degrees(math.atan2(qz, math.hypot(qx, qy)))
        pan = _axis_turn_still_s(az, within_deg, kp, vp)
        tilt = _axis_turn_still_s(el, within_deg, kt, vt)
        turn[i] = latency_s + (tilt if tilt > pan else pan)


def fovea_turns(points, mid_pose, end_pose, cfg: "AttentionConfig", head) -> tuple[list, list[float]]:
    """:func:`fovea_turns_kernel` of the world points ``points`` (N, 3): each one's lidar-frame point
    at the mid pose (3 floats) and its saccade time from the end pose (poses as
    :meth:`foveatrack.sky.controller.SkyController._pose_rows` gives them: rows and offset), without
    the motion.  One call for a frame's confirmed tracks, not a dozen Python calls each."""
    (m_rows, m_off), (e_rows, e_off) = mid_pose, end_pose
    n = points.shape[0]
    q_mid = np.empty((n, 3))
    turn = np.empty(n)
    kp, vp, kt, vt = head
    fovea_turns_kernel(np.ascontiguousarray(points, np.float64).reshape(n, 3),
                       np.array(m_rows[0] + m_rows[1] + m_rows[2], np.float64), np.array(m_off, np.float64),
                       np.array(e_rows[0] + e_rows[1] + e_rows[2], np.float64), np.array(e_off, np.float64),
                       float(cfg.fovea_half_angle_deg), float(cfg.saccade_latency_s), float(kp), float(vp), float(kt),
                       float(vt), q_mid, turn)
    return q_mid.tolist(), turn.tolist()


def threat_score(view, cfg: AttentionConfig, looks_like: str | None = None) -> float:
    """The module docstring's score of a :class:`~foveatrack.sky.tracks.TrackView`; ``looks_like``:
    the class it goes by (:meth:`Attention.looks_like`; None: the view's own)."""
    if not view.confirmed:
        return 0.0
    c = cfg.protected_xyz_m
    px, py, pz = view.xyz_m.tolist()
    vx, vy, vz = view.velocity_m_s.tolist()
    dx, dy, dz = px - c[0], py - c[1], pz - c[2]
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    closing = max(0.0, -(vx * dx + vy * dy + vz * dz) / d) if d > 0 else 0.0
    return (CLASS_WEIGHT.get(view.looks_like if looks_like is None else looks_like, 0.0)
            * (1.0 + closing / cfg.closing_ref_m_s)
            * cfg.distance_ref_m / (cfg.distance_ref_m + d))


@njit(cache=True)
def threat_scores_kernel(P, V, W, centre, closing_ref_m_s, distance_ref_m, out):
    """:func:`threat_score` of confirmed tracks at the world points ``P`` (N, 3) with velocities ``V``
    (N, 3) and class weights ``W`` (N,) into ``out`` (N,): its operations on each in their order
    (square roots, products, sums and quotients only: IEEE's correctly rounded results, Python's
    float bits; twin :func:`threat_score`, ``tests/sky/test_attention.py``).  Python's
    ``max(0.0, c)``: ``c`` only where it is greater (not NaN, not -0.0)."""
    for i in range(P.shape[0]):
        dx = P[i, 0] - centre[0]
        dy = P[i, 1] - centre[1]
        dz = P[i, 2] - centre[2]
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        closing = 0.0
        if d > 0:
            c = -(V[i, 0] * dx + V[i, 1] * dy + V[i, 2] * dz) / d
            if c > 0.0:
                closing = c
        out[i] = W[i] * (1.0 + closing / closing_ref_m_s) * distance_ref_m / (distance_ref_m + d)


def threat_scores(views, looks_like, cfg: AttentionConfig, points: np.ndarray | None = None) -> list[float]:
    """:func:`threat_score` of each of the confirmed ``views`` with its class ``looks_like[i]`` (the
    same bits), by one :func:`threat_scores_kernel` call: per track a Python call of ~0.9 us cost
    ~25 us a frame of the swarm with the flock's ~28 confirmed tracks.  ``points``: the views'
    positions (N, 3) where the caller has gathered them."""
    n = len(views)
    out = np.empty(n)
    P = np.array([v.xyz_m for v in views], np.float64) if points is None else points
    threat_scores_kernel(np.ascontiguousarray(P, np.float64).reshape(n, 3),
                         np.array([v.velocity_m_s for v in views], np.float64).reshape(n, 3),
                         np.array([CLASS_WEIGHT.get(c, 0.0) for c in looks_like], np.float64),
                         np.array(cfg.protected_xyz_m, np.float64).reshape(3), float(cfg.closing_ref_m_s),
                         float(cfg.distance_ref_m), out)
    return out.tolist()


@dataclass
class Attention:
    """The fixation schedule (module docstring).  :meth:`update` after each frame; :attr:`target`
    is the track id the fovea serves next (None: no confirmed track)."""
    cfg: AttentionConfig = field(default_factory=AttentionConfig)
    target: int | None = None
    priority: int | None = None
    revisit: int | None = None           # the track of the current revisit fixation, if any
    pinned: int | None = None
    served_s: dict = field(default_factory=dict)
    _revisit_start_s: float = 0.0
    _revisit_dwell_s: float = 0.0
    unreached: set = field(default_factory=set)   # tracks whose last revisit timed out before the fovea got there
    _target_since_s: float = 0.0         # when the fovea was last given to another track
    _target_reached: bool = False        # ... and whether that track has been in the fovea since
    verifying: int | None = None         # the candidate the fovea is turned to while nothing is confirmed
    _verify_start_s: float = 0.0
    _verify_dwell_s: float = 0.0
    _verdict: dict = field(default_factory=dict)   # per track, its last label other than unknown
    set_aside: set = field(default_factory=set)    # priority tracks the head turned to and never saw, until seen again
    _target_seen_s: float = -math.inf    # the last hit of the track the fovea was last given, since then
    _unseen_before_s: dict = field(default_factory=dict)  # per track, its unseen time in earlier fixations since its last hit

    def looks_like(self, view) -> str:
        """The class the schedule goes by (module docstring): what the classifier's rules say of the
        track now; with ``keep_verdict``, while they say unknown (its window holds too few hits:
        out of the fovea, where the rosette is sparse) its last label other than unknown."""
        now = view.looks_like
        if not self.cfg.keep_verdict:
            return now
        if view.label != "unknown":
            self._verdict[view.track_id] = view.label
        if now != "unknown":
            return now
        return self._verdict.get(view.track_id, now)

    def pin(self, track_id: int | None) -> None:
        """An operator's choice: this track is the priority while it lives (None: unpin)."""
        self.pinned = track_id

    def update(self, t_s: float, views, in_fovea: set[int], dt_s: float,
               turn_s: Mapping[int, float] | None = None, scores: Mapping[int, float] | None = None,
               looks: Mapping[int, str] | None = None) -> int | None:
        """``turn_s``: each confirmed track's saccade time from the head's pose now (module
        docstring; missing: 0, a revisit then starts only when its clock has run out).  ``scores``:
        every confirmed track's :func:`threat_score`, and ``looks`` its :meth:`looks_like` this frame,
        if the caller has them."""
        cfg = self.cfg
        turn_s = turn_s or {}
        if self.target in in_fovea:
            self._target_reached = True
        live = {v.track_id: v for v in views if v.confirmed}
        for tid in live:            # a new track's clock starts when it is confirmed
            self.served_s.setdefault(tid, t_s)
        for tid in in_fovea:
            if tid in live:
                self.served_s[tid] = t_s
                self.unreached.discard(tid)
        self.served_s = {k: t for k, t in self.served_s.items() if k in live}
        self._verdict = {k: c for k, c in self._verdict.items() if k in live}
        self.unreached &= set(live)
        if self.pinned is not None and self.pinned not in live:
            self.pinned = None
        if scores is None:
            scores = {tid: threat_score(v, cfg, self.looks_like(v)) for tid, v in live.items()}
        self._set_aside_unseen(t_s, views, live)
        ranked = sorted((-scores[tid], tid) for tid in live if tid not in self.set_aside)
        best = ranked[0][1] if ranked and ranked[0][0] < 0.0 else None
        self.priority = self.pinned if self.pinned is not None else best
        # an operator's pin holds the fovea (pin_holds_fovea): no revisit, and one in progress ends
        # unserved (its clock runs on)
        held = self.pinned is not None and cfg.pin_holds_fovea
        if held:
            self.revisit = None
        # the revisit in progress: count its time in the fovea, end it when served or timed out
        if self.revisit is not None:
            if self.revisit not in live:
                self.revisit = None
            else:
                if self.revisit in in_fovea:
                    self._revisit_dwell_s += dt_s
                if self._fixation_over(t_s, self._revisit_start_s, self._revisit_dwell_s):
                    self.served_s[self.revisit] = t_s     # served, or given up on: its clock restarts
                    if self._revisit_dwell_s < cfg.dwell_s:
                        self.unreached.add(self.revisit)
                    self.revisit = None
        # the head on its way back to the priority track is not sent elsewhere before it gets there
        # (or gives up, as a revisit does): the tilt turns at 2 deg/s, and a revisit that cut in sent
        # the fovea to a crown part while the drone it was turning to waited another 5 s
        in_transit = (self.target is not None and self.target == self.priority and not self._target_reached
                      and t_s - self._target_since_s < cfg.saccade_timeout_s)
        if self.revisit is None and self.priority is not None and not in_transit and not held:
            first = {}
            for tid, v in live.items():
                if tid != self.priority and (self.looks_like(v) if looks is None else looks[tid]) == "drone":
                    first[tid] = self.served_s[tid]
            # due once the clock will have run out by the time the head gets there (a track the head
            # did not reach last time: once it has run out, or it would be due again at once)
            lead = {tid: turn_s.get(tid, 0.0) if live[tid].label == "drone" and tid not in self.unreached else 0.0
                    for tid in first}
            due = sorted((t - lead[tid], tid) for tid, t in first.items() if t_s + lead[tid] - t > cfg.revisit_s)
            if due:
                self.revisit = due[0][1]
                self._revisit_start_s = t_s
                self._revisit_dwell_s = 0.0
        target = self.revisit if self.revisit is not None else self.priority
        if target is None:
            target = self._verify(t_s, views, in_fovea, dt_s)
        else:
            self.verifying = None
        if target != self.target:
            self._leave_target(t_s, live)
            self._target_since_s, self._target_reached, self._target_seen_s = t_s, False, -math.inf
        self.target = target
        return self.target

    def _set_aside_unseen(self, t_s: float, views, live: Mapping) -> None:
        """The priority track without a hit for ``drop_unseen_priority_s`` since the fovea was given to
        it, or since its last hit, is set aside (no priority) until it is seen again: a coasting track
        whose object is gone, chased by the head (module docstring).  0: never."""
        limit = self.cfg.drop_unseen_priority_s
        if limit <= 0.0:
            return
        hit = {v.track_id for v in views if v.hit}
        if self.target in hit:
            self._target_seen_s = t_s
        self.set_aside = {tid for tid in self.set_aside if tid in live and tid not in hit}
        self._unseen_before_s = {tid: s for tid, s in self._unseen_before_s.items() if tid in live and tid not in hit}
        if (self.target is not None and self.target == self.priority and self.target != self.pinned
                and self._unseen_before_s.get(self.target, 0.0) + self._unseen_now_s(t_s) >= limit):
            self.set_aside.add(self.target)

    def _leave_target(self, t_s: float, live: Mapping) -> None:
        """The fovea leaves its track: with ``unseen_over_fixations``, the time it was given to it
        unseen (since the turn, or its last hit) is kept until the track's next hit, so that the
        next fixation goes on counting (module docstring)."""
        if not (self.cfg.unseen_over_fixations and self.cfg.drop_unseen_priority_s > 0.0):
            return
        if self.target is not None and self.target in live:
            self._unseen_before_s[self.target] = self._unseen_before_s.get(self.target, 0.0) + self._unseen_now_s(t_s)

    def _unseen_now_s(self, t_s: float) -> float:
        """How long the fovea's present track has gone unseen in this fixation: since the fovea was
        given to it, or since its last hit."""
        return t_s - max(self._target_since_s, self._target_seen_s)

    def _fixation_over(self, t_s: float, start_s: float, dwell_s: float) -> bool:
        """A fixation (a revisit, or a look at a candidate) ends once its track has been ``dwell_s`` in
        the fovea, or ``saccade_timeout_s`` after it started."""
        return dwell_s >= self.cfg.dwell_s or t_s - start_s >= self.cfg.saccade_timeout_s

    def _verify(self, t_s: float, views, in_fovea: set[int], dt_s: float) -> int | None:
        """Nothing confirmed: look at the likeliest candidate (the most hits off the scenery, then the
        lower id), so that the fovea resolves what the sparse rim of the field only hints at.  Held
        like a revisit, until it has been in the fovea for ``dwell_s`` or ``saccade_timeout_s`` has
        passed (re-chosen every frame, the head turned to one rim candidate and back to another and
        neither was ever in the fovea)."""
        cfg = self.cfg
        cands = {v.track_id: v for v in views if not v.confirmed and v.clear_hits >= cfg.verify_min_hits}
        if self.verifying is not None:
            if self.verifying in cands:
                if self.verifying in in_fovea:
                    self._verify_dwell_s += dt_s
                if not self._fixation_over(t_s, self._verify_start_s, self._verify_dwell_s):
                    return self.verifying
            self.verifying = None
        order = sorted((-v.clear_hits, tid) for tid, v in cands.items())
        if order:
            self.verifying = order[0][1]
            self._verify_start_s, self._verify_dwell_s = t_s, 0.0
        return self.verifying


def bearing_off_axis_deg(p_world, rows, offset) -> float:
    """Angle [deg] between the lidar's axis (pose ``rows``: :func:`foveatrack.reconstruction.rotation_rows`)
    and the world point ``p_world``."""
    return off_axis_deg(*in_lidar(floats3(p_world), rows, floats3(offset)))


def in_lidar(p_world, rows, offset) -> tuple[float, float, float]:
    """A world point (3 floats) in the lidar frame of the pose ``rows`` (the head's rotation,
    :func:`foveatrack.reconstruction.rotation_rows`) and ``offset`` (the lidar's, 3 floats):
    ``R.T p - offset`` in floats (:func:`foveatrack.fixed_order.rows_T_times`, then the offset)."""
    qx, qy, qz = rows_T_times(rows, *p_world)
    ox, oy, oz = offset
    return qx - ox, qy - oy, qz - oz


def off_axis_deg(qx: float, qy: float, qz: float) -> float:
    """Angle [deg] between the lidar's axis and a point ``(qx, qy, qz)`` of the lidar frame."""
    return math.degrees(math.atan2(math.hypot(qy, qz), qx))


def true_off_axis_deg(xyz_m, pan_deg, tilt_deg) -> np.ndarray:
    """Per frame, the angle [deg] between world points ``xyz_m`` (T, 3) and the lidar's true axis at
    the head's true pose ``pan_deg``, ``tilt_deg`` (T,), the lidar's offset from the head's centre
    left out; NaN where a point is absent (NaN).  What the simulator's and a replay's truth call "in
    the fovea" and "in the field"."""
    xyz = np.asarray(xyz_m, np.float64).reshape(-1, 3)
    out = np.full(len(xyz), np.nan)
    for k in range(len(xyz)):
        if np.all(np.isfinite(xyz[k])):
            out[k] = bearing_off_axis_deg(xyz[k], rotation_matrix(pan_deg[k], tilt_deg[k]).tolist(), _NO_OFFSET)
    return out

