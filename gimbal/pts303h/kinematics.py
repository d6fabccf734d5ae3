"""The head's exact motion per axis: closed-form angle on constant-acceleration segments with the
ripple, stop hits by bracketed root finding (see :mod:`gimbal.pts303h`, "Exact integration")."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from gimbal.pelco import wrap_pan_deg


# ------------------------------------------------------------------------------------------------
# one axis: a list of exact segments
# ------------------------------------------------------------------------------------------------
_INF = math.inf
_RTOL = 4 * np.finfo(float).eps   # brentq's tightest relative tolerance


@dataclass(slots=True)
class _Seg:
    t0: float
    t1: float
    p0: float
    v0: float
    a: float
    r: float  # ripple amplitude on this segment (0 for closed-loop position moves)
    pinned: int = 0  # +1 / -1: held at the upper / lower stop while pushed into it
    slack0: float = 0.0  # backlash: motor - output angle at t0, in [-play/2, play/2] (set on append)


def _pos(t0, p0, v0, a, r, omega, phi, tau):
    """Closed-form position on a segment (scalars or numpy arrays)."""
    d = tau - t0
    th0 = omega * t0 + phi
    th = omega * tau + phi
    c, s = np.cos(th), np.sin(th)
    ripple = -v0 * (c - np.cos(th0)) / omega - a * d * c / omega + a * (s - np.sin(th0)) / omega**2
    return p0 + v0 * d + 0.5 * a * d * d + r * ripple


def _pos1(t0, p0, v0, a, r, omega, phi, tau) -> float:
    """``float(_pos(...))`` for one time, bit for bit, without trigonometry when ``r == 0``.

    ``_pos`` ends with ``+ r * ripple``; with ``r == 0`` and a finite ripple that adds a signed
    zero, which leaves every finite non-zero sum unchanged.  A zero sum (whose sign the added
    zero may flip) or a non-finite one takes the full expression.
    """
    if r == 0.0:
        d = tau - t0
        base = p0 + v0 * d + 0.5 * a * d * d
        if base != 0.0 and d - d == 0.0 and base - base == 0.0:
            return float(base)
    return float(_pos(t0, p0, v0, a, r, omega, phi, tau))


def _speed(t0, v0, a, r, omega, phi, tau):
    return (v0 + a * (tau - t0)) * (1.0 + r * np.sin(omega * tau + phi))


class _Axis:
    """One axis's motion: the kept segments ``segs`` in time order, and the plan after them.

    The segments are the motor's motion (commands, acceleration, stops act on it).  With a backlash
    (``play_deg`` > 0, the worm gear's free play) the output angle lags it: the slack ``motor -
    output`` stays in ``[-play/2, play/2]`` and the output moves only while the motor pushes the slack
    against an end.  Every segment is monotone in motor angle (plans split at speed zero crossings;
    the ripple, below 50 %, never reverses a speed), so on a segment starting with slack ``s0`` at motor
    angle ``m0`` the output is, exactly, ``m(t) - clip(s0 + m(t) - m0, -play/2, play/2)`` (a play
    operator).  At power-on the slack is 0: mid-play.

    ``segs`` changes only through :meth:`prune`, :meth:`_cut` and :meth:`_append`, which keep a
    mirror of the segments' ``(t0, p0, v0, a, r)`` in the columns ``_lo ..`` of ``_cols`` (a
    segment's fields other than ``t1`` never change once appended) and the number of kept
    segments with ripple, so the tables of :meth:`arrays` / :meth:`pieces` are one slice copy when
    the motion changed (``_table`` None), and reused while it has not.
    """

    _COLS0 = 64

    def __init__(self, name, p0, accel, stops, omega, phi, t_start=0.0, play_deg=0.0):
        self.name = name
        self.half_play = 0.5 * play_deg
        self.accel = accel
        self.stops = stops  # (lo, hi) or None
        self.omega = omega
        self.phi = phi
        self.segs: list[_Seg] = []
        self.target_speed = 0.0
        self._set_cols(np.empty((6, self._COLS0)))
        self._lo = 0
        self._n_ripple = 0   # kept segments with r != 0
        self._table = None   # (5, S) copy of the mirror, None after a change
        self._append(_Seg(t_start, _INF, p0, 0.0, 0.0, 0.0))

    def _set_cols(self, cols: np.ndarray) -> None:
        self._cols = cols
        self._cap = cols.shape[1]
        self._mv = memoryview(cols).cast("B").cast("d")   # flat: element (k, j) at k * cap + j

    def __getstate__(self):   # a memoryview does not pickle / deepcopy: rebuilt from _cols
        state = self.__dict__.copy()
        del state["_mv"]
        return state

    def __setstate__(self, state) -> None:
        self.__dict__.update(state)
        self._set_cols(self._cols)

    # -- evaluation ------------------------------------------------------------------------
    def _find(self, t: float) -> int:
        for i in range(len(self.segs) - 1, -1, -1):
            if self.segs[i].t0 <= t:
                return i
        raise ValueError(
            f"{self.name}: time {t} is before the kept history (starts {self.segs[0].t0})"
        )

    def state(self, t: float) -> tuple[float, float, _Seg]:
        """The motor's angle and base speed at ``t``, and its segment."""
        s = self.segs[self._find(t)]
        p = _pos1(s.t0, s.p0, s.v0, s.a, s.r, self.omega, self.phi, t)
        return p, s.v0 + s.a * (t - s.t0), s

    def output_at(self, t: float) -> float:
        """The output angle at ``t`` (the motor's, less the backlash's slack)."""
        p, _, s = self.state(t)
        if not self.half_play:
            return p
        h = self.half_play
        return p - min(max(s.slack0 + (p - s.p0), -h), h)

    def _tables(self) -> None:
        if self._table is None:   # after a change of the motion: one slice copy of the mirror
            table = self._cols[:, self._lo:self._lo + len(self.segs)].copy()
            self._table = table
            self._arrays = None
            self._pieces = (table[:4], self._n_ripple > 0)

    def arrays(self):
        """The kept segments as five rows ``(t0, p0, v0, a, r)``, shared until the motion changes."""
        self._tables()
        if self._arrays is None:
            self._arrays = tuple(self._table[:5])
        return self._arrays

    def _output(self, m: np.ndarray, idx: np.ndarray, p0: np.ndarray) -> np.ndarray:
        """Output angles from motor angles ``m`` on segments ``idx`` (the play operator)."""
        h = self.half_play
        return m - np.clip(self._table[5][idx] + (m - p0[idx]), -h, h)

    def pieces(self) -> tuple[np.ndarray, bool]:
        """All kept segments as a (4, S) table (t0, p0, v0, a) and whether any has ripple."""
        self._tables()
        return self._pieces

    def eval(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t0, p0, v0, a, r = self.arrays()
        idx = self._segment_of(t0, t)
        args = (t0[idx], v0[idx], a[idx], r[idx])
        p = _pos(t0[idx], p0[idx], v0[idx], a[idx], r[idx], self.omega, self.phi, t)
        v = _speed(*args, self.omega, self.phi, t)
        if self.half_play:   # the output moves only with the slack against an end
            slack = self._table[5][idx] + (p - p0[idx])
            v = np.where(np.abs(slack) >= self.half_play, v, 0.0)
            p = self._output(p, idx, p0)
        return p, v

    def eval_position(self, t: np.ndarray) -> np.ndarray:
        """:meth:`eval`'s position alone; without ripple on the segments the ripple terms (two
        trigonometric arrays) are skipped: they are multiplied by zero there (the closed loop asks
        this for every frame)."""
        t0, p0, v0, a, r = self.arrays()
        idx = self._segment_of(t0, t)
        if self._n_ripple:   # some kept segment has ripple (times may come in any order)
            m = _pos(t0[idx], p0[idx], v0[idx], a[idx], r[idx], self.omega, self.phi, t)
        else:
            d = t - t0[idx]
            m = p0[idx] + v0[idx] * d + 0.5 * a[idx] * d * d   # _pos's order: the same bits
        return self._output(m, idx, p0) if self.half_play else m

    def _segment_of(self, t0: np.ndarray, t: np.ndarray) -> np.ndarray:
        idx = np.searchsorted(t0, t, side="right") - 1
        if idx.size and idx.min() < 0:
            raise ValueError(
                f"{self.name}: times before the kept history (starts {t0[0]}) were asked for"
            )
        return idx

    def prune(self, t_keep: float) -> None:
        segs = self.segs
        while len(segs) > 1 and segs[1].t0 <= t_keep and segs[0].t1 < t_keep:
            if segs.pop(0).r != 0:
                self._n_ripple -= 1
            self._lo += 1
            self._table = None

    # -- commands --------------------------------------------------------------------------
    def _cut(self, te: float) -> tuple[float, float, _Seg]:
        """State at ``te``; forget the planned segments after it (the next plan starts there)."""
        segs = self.segs
        i = self._find(te)
        s = segs[i]
        p = _pos1(s.t0, s.p0, s.v0, s.a, s.r, self.omega, self.phi, te)
        v = s.v0 + s.a * (te - s.t0)
        if i + 1 < len(segs):
            for dropped in segs[i + 1:]:
                if dropped.r != 0:
                    self._n_ripple -= 1
            del segs[i + 1:]
            self._table = None
        return p, v, s

    def set_speed(self, te: float, v_target: float, ripple: float) -> None:
        """From ``te`` on, drive the base speed toward ``v_target`` at the acceleration limit."""
        self.target_speed = v_target
        p, v, s = self._cut(te)
        if s.pinned and v_target * s.pinned > 0:  # still pushed into the stop: hold
            self._extend([_Seg(te, _INF, p, 0.0, 0.0, 0.0, s.pinned)])
            return
        plan: list[_Seg] = []
        t = te
        if v != v_target:
            acc = math.copysign(self.accel, v_target - v)
            t_reach = te + abs(v_target - v) / self.accel
            if v * v_target < 0:  # split at the zero crossing so each piece is monotone
                t_zero = te + abs(v) / self.accel
                plan.append(_Seg(te, t_zero, p, v, acc, ripple))
                plan.append(_Seg(t_zero, t_reach, math.nan, 0.0, acc, ripple))
            else:
                plan.append(_Seg(te, t_reach, p, v, acc, ripple))
            t = t_reach
        plan.append(_Seg(t, _INF, p if t == te else math.nan, v_target, 0.0, ripple))
        self._extend(plan)

    def goto(self, te: float, p_target: float, vmax: float) -> None:
        """Closed-loop positioning move (trapezoid, no ripple) ending at rest on ``p_target``."""
        self.target_speed = 0.0
        p, v, _ = self._cut(te)
        plan: list[_Seg] = []
        t = te
        if v != 0:
            t_stop = te + abs(v) / self.accel
            plan.append(_Seg(te, t_stop, p, v, -math.copysign(self.accel, v), 0.0))
            p = p + v * abs(v) / (2 * self.accel)  # exact for a constant-deceleration stop
            t = t_stop
        if self.stops is not None:
            p_target = min(max(p_target, self.stops[0]), self.stops[1])
        else:  # shortest way round
            p_target = p + wrap_pan_deg(p_target - p)
        d = p_target - p
        if d != 0:
            sgn = math.copysign(1.0, d)
            t_acc = vmax / self.accel
            if abs(d) >= vmax * t_acc:
                t_cruise = (abs(d) - vmax * t_acc) / vmax
                peak = vmax
            else:
                t_acc = math.sqrt(abs(d) / self.accel)
                t_cruise = 0.0
                peak = self.accel * t_acc
            plan.append(_Seg(t, t + t_acc, p, 0.0, sgn * self.accel, 0.0))
            t += t_acc
            if t_cruise > 0:
                plan.append(_Seg(t, t + t_cruise, math.nan, sgn * peak, 0.0, 0.0))
                t += t_cruise
            plan.append(_Seg(t, t + t_acc, math.nan, sgn * peak, -sgn * self.accel, 0.0))
            t += t_acc
        plan.append(_Seg(t, _INF, p_target, 0.0, 0.0, 0.0))
        self._extend(plan)

    def _extend(self, plan: list[_Seg]) -> None:
        """Append planned segments (NaN p0 = continue from the previous one), cutting at a stop.

        A stop absorbs the head's speed: at a hit the rest of the plan (made for motion through the
        stop) is dropped, and from the hit the base speed ramps again from rest toward the commanded
        speed.  Commanded into the stop, the head is held there (pinned); commanded away (a reversal
        whose deceleration still carried the head into the stop), it leaves at once; commanded to
        stop, it rests there.
        """
        for s in plan:
            if s.t1 <= s.t0:
                continue
            if math.isnan(s.p0):
                prev = self.segs[-1]
                s.p0 = _pos1(prev.t0, prev.p0, prev.v0, prev.a, prev.r,
                             self.omega, self.phi, s.t0)
            if self.stops is not None and not s.pinned:
                hit = self._stop_hit(s)
                if hit is not None:
                    t_hit, side, stop = hit
                    if t_hit > s.t0:
                        s.t1 = t_hit
                        self._append(s)
                    v_target = self.target_speed
                    if v_target * side < 0:   # commanded away: ramp from rest at the stop
                        t_reach = t_hit + abs(v_target) / self.accel
                        self._extend([
                            _Seg(t_hit, t_reach, stop, 0.0, math.copysign(self.accel, v_target), s.r),
                            _Seg(t_reach, _INF, math.nan, v_target, 0.0, s.r),
                        ])
                    else:
                        pushed = v_target * side > 0
                        self._append(_Seg(t_hit, _INF, stop, 0.0, 0.0, 0.0, side if pushed else 0))
                    return
            self._append(s)

    def _append(self, s: _Seg) -> None:
        segs = self.segs
        if segs and segs[-1].t0 >= s.t0:  # a zero-length predecessor: replace it
            if segs.pop().r != 0:
                self._n_ripple -= 1
        if segs:
            prev = segs[-1]
            prev.t1 = s.t0
            if self.half_play:   # the slack carried over the previous (monotone) segment
                h = self.half_play
                s.slack0 = min(max(prev.slack0 + (s.p0 - prev.p0), -h), h)
        segs.append(s)
        if s.r != 0:
            self._n_ripple += 1
        n = len(segs)
        cap = self._cap
        if self._lo + n > cap:   # out of columns: move the kept ones to the front (or grow)
            cols = np.empty((6, 2 * cap)) if 2 * n > cap else self._cols
            cols[:, :n - 1] = self._cols[:, self._lo:self._lo + n - 1]
            self._mv.release()
            self._set_cols(cols)
            self._lo = 0
            cap = self._cap
        j = self._lo + n - 1
        mv = self._mv
        mv[j] = s.t0
        mv[cap + j] = s.p0
        mv[2 * cap + j] = s.v0
        mv[3 * cap + j] = s.a
        mv[4 * cap + j] = s.r
        mv[5 * cap + j] = s.slack0
        self._table = None

    def _stop_hit(self, s: _Seg):
        lo, hi = self.stops
        v_start = s.v0
        v_end = s.v0 + s.a * ((s.t1 - s.t0) if s.t1 != _INF else 0.0)
        direction = v_start if v_start != 0 else (s.a if s.a != 0 else v_end)
        if direction == 0:
            return None
        side = 1 if direction > 0 else -1
        stop = hi if side > 0 else lo
        f = lambda tau: _pos1(s.t0, s.p0, s.v0, s.a, s.r, self.omega, self.phi, tau) - stop  # noqa: E731,E501
        if side * f(s.t0) >= 0:
            return s.t0, side, stop
        if s.t1 == _INF:
            if s.a != 0 or s.v0 == 0:
                return None
            t_end = s.t0 + abs(stop - s.p0) / (abs(s.v0) * (1 - s.r)) * 1.01 + 1e-9
        else:
            t_end = s.t1
        if side * f(t_end) < 0:
            return None
        t_hit = brentq(f, s.t0, t_end, xtol=1e-13, rtol=_RTOL, maxiter=200)
        return t_hit, side, stop
