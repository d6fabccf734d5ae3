r"""A PTS-303H pan/tilt head as the tracker meets it: Pelco bytes in, motion (and maybe replies) out.

The paper (Appendix D, Fig. 16) drives a PTS-303H over a UART; its API sets each motor's rotation
*speed* and reports no orientation, so the authors calibrated a command -> speed lookup table and
integrated it ("Gimbal angle calibration").  This model is what makes that calibration necessary:

* **Unit-specific speed curve.**  Each speed byte ``b`` maps to a true speed through a monotone,
  nonlinear curve with a dead zone ``b <= b0`` (zero speed) and a separate turbo speed (pan byte
  0xFF).  A unit seed draws the unit's gain, exponent, dead-zone byte and per-byte steps, so two
  units differ.  Nominal curve, for ``b0 < b <= 63``:

  .. math:: v(b) = g\,v_{max} \left(\frac{b - b_0}{63 - b_0}\right)^{\gamma}

  with per-byte increments jittered (log-normal) and renormalised, so the unit curve stays
  strictly increasing above the dead zone.  Bytes 0x40-0xFE act as 0x3F.
* **Dead time.**  A command takes effect ``dead_time_s`` after its frame's last byte arrives.
* **Acceleration limit.**  The base speed moves toward the commanded speed at constant
  acceleration ``accel`` (piecewise-constant acceleration segments).
* **Ripple.**  The true speed is the base speed times ``1 + r sin(omega t + phi)``; the frequency
  and phase are drawn per unit.  Because the ripple is a fixed function of time, the angle has a
  closed form on each segment (below) and no integration step exists to change the answer.
* **Travel.**  Pan is continuous (wraps to (-180, 180]); tilt stops at ``tilt_min_deg`` /
  ``tilt_max_deg`` and holds there (speed 0) while commanded into the stop.
* **Feedback.**  ``'none'`` (the paper: queries go unanswered), ``'at-rest'`` (the family's bench
  notes: correct only when stopped, checksum-valid garbage while moving), ``'always'``.  Replies go
  out in the envelope (D or P) the query came in.
* **Quirks** (switchable in :class:`HeadParams`): absolute sets (0x4B/0x4D) ignored unless the
  line was quiet for ``abs_set_quiet_s``; the tilt word convention (``tilt_zero='zenith'``).

Exact integration
-----------------
On a segment starting at ``t0`` with position ``p0``, base speed ``v0`` and acceleration ``a``
(``D = tau - t0``, ``theta(u) = omega u + phi``):

.. math::

   p(\tau) = p_0 + v_0 D + \tfrac12 a D^2
           + r\Big[-\frac{v_0}{\omega}(\cos\theta_\tau - \cos\theta_0)
                   - \frac{a D}{\omega}\cos\theta_\tau
                   + \frac{a}{\omega^2}(\sin\theta_\tau - \sin\theta_0)\Big]

Segment boundaries are set only by commands, by reaching the commanded speed, by the base speed
crossing zero and by stop hits (found by bracketed root finding on the closed form), never by
how often the model is advanced or queried.

Conventions: pan_deg positive = CCW seen from above = LEFT; tilt_deg positive = UP; Pelco "left"
and "up" increase them.  Time is virtual and always an argument.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import brentq

from gimbal.errors import GimbalError
from gimbal.framing import PelcoParser
from gimbal.pelco import (
    MAX_SPEED_BYTE,
    PAN_TURBO,
    SYNC_D,
    PelcoCommand,
    encode_pan_reply,
    encode_tilt_reply,
    pan_deg_to_word,
    tilt_deg_to_word,
    word_is_angle,
    word_to_pan_deg,
    word_to_tilt_deg,
    wrap_pan_deg,
)

FEEDBACK_MODES = ("none", "at-rest", "always")
_BYTE = [bytes((b,)) for b in range(256)]
AXES = ("pan", "tilt")


@dataclass(frozen=True)
class HeadParams:
    """Parameters of a head family (nominal values; a unit seed perturbs some of them).

    Defaults are the PTS-303 family as far as the facts go: pan 0-15 deg/s and tilt 0-2 deg/s
    from a family member's listing; accelerations, dead time, ripple and quirks are assumptions
    typical of worm-gear heads.  See :data:`HEAD_FAMILIES` for a faster heavy head.

    pan_speed_max_deg_s : float > 0 [deg/s], nominal pan speed at byte 0x3F
    pan_turbo_deg_s : float > pan_speed_max_deg_s [deg/s], nominal turbo (byte 0xFF) pan speed
    tilt_speed_max_deg_s : float > 0 [deg/s], nominal tilt speed at byte 0x3F (no tilt turbo)
    pan_accel_deg_s2, tilt_accel_deg_s2 : float > 0 [deg/s^2], |acceleration| while changing speed
    dead_time_s : float >= 0 [s], from a frame's last byte to the start of its effect
    dead_zone_byte : int 0-62, nominal last byte giving zero speed (unit: +-1)
    curve_gamma : float > 0, nominal exponent of the speed curve
    unit_gain_spread : float >= 0, relative std of a unit's gain
    unit_gamma_spread : float >= 0, log-std of a unit's exponent
    unit_step_spread : float >= 0, log-std of the per-byte speed increments
    ripple_rel : float in [0, 0.5), relative speed ripple amplitude
    ripple_freq_hz : float > 0 [Hz], nominal ripple frequency (unit: +-10 %)
    tilt_min_deg, tilt_max_deg : [deg], the tilt stop brackets (tilt positive = up)
    abs_set_quiet_s : float >= 0 [s], line-quiet time an absolute set needs (0 = always obeyed)
    reply_delay_s : float >= 0 [s], turnaround from a query's last byte to the reply
    tilt_zero : 'zenith' (family quirk: native tilt word 0 = zenith) or 'level'
    garbage_margin_deg : float > 0 [deg], garbage replies are at least this far from the truth
    history_s : float > 0 [s], how far back :meth:`PTS303H.angles_at` can answer
    """

    family: str = "pts-303"
    pan_speed_max_deg_s: float = 15.0
    pan_turbo_deg_s: float = 20.0
    tilt_speed_max_deg_s: float = 2.0
    pan_accel_deg_s2: float = 40.0
    tilt_accel_deg_s2: float = 10.0
    dead_time_s: float = 0.04
    dead_zone_byte: int = 2
    curve_gamma: float = 1.5
    unit_gain_spread: float = 0.08
    unit_gamma_spread: float = 0.15
    unit_step_spread: float = 0.2
    ripple_rel: float = 0.02
    ripple_freq_hz: float = 1.5
    tilt_min_deg: float = -30.0
    tilt_max_deg: float = 60.0
    abs_set_quiet_s: float = 0.2
    reply_delay_s: float = 0.003
    tilt_zero: str = "zenith"
    garbage_margin_deg: float = 2.0
    history_s: float = 2.0

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> GimbalError:
            return GimbalError(
                f"head parameter {name}={getattr(self, name)!r} is not allowed; {allowed}"
            )

        for name in ("pan_speed_max_deg_s", "tilt_speed_max_deg_s", "pan_accel_deg_s2",
                     "tilt_accel_deg_s2", "curve_gamma", "ripple_freq_hz", "history_s",
                     "garbage_margin_deg"):
            if not getattr(self, name) > 0:
                raise bad(name, "must be > 0")
        for name in ("dead_time_s", "unit_gain_spread", "unit_gamma_spread", "unit_step_spread",
                     "abs_set_quiet_s", "reply_delay_s"):
            if not getattr(self, name) >= 0:
                raise bad(name, "must be >= 0")
        if not self.pan_turbo_deg_s > self.pan_speed_max_deg_s:
            raise bad("pan_turbo_deg_s", "must exceed pan_speed_max_deg_s")
        if not 0 <= self.ripple_rel < 0.5:
            raise bad("ripple_rel", "allowed 0 <= ripple_rel < 0.5")
        if not (isinstance(self.dead_zone_byte, int) and 0 <= self.dead_zone_byte <= 61):
            raise bad("dead_zone_byte", "allowed integers 0-61")
        if not self.tilt_min_deg < 0 < self.tilt_max_deg:
            raise bad("tilt_min_deg", "need tilt_min_deg < 0 < tilt_max_deg")
        if self.tilt_zero not in ("zenith", "level"):
            raise bad("tilt_zero", "use 'zenith' or 'level'")

    @classmethod
    def for_family(cls, name: str, **overrides) -> "HeadParams":
        """Parameters of a named family from :data:`HEAD_FAMILIES`, with field overrides."""
        if name not in HEAD_FAMILIES:
            raise GimbalError(f"unknown head family {name!r}; known: {', '.join(HEAD_FAMILIES)}")
        return replace(HEAD_FAMILIES[name], **overrides)


HEAD_FAMILIES: dict[str, HeadParams] = {
    # PTS-303 family listing: pan 0-15 deg/s, tilt 0-2 deg/s.
    "pts-303": HeadParams(),
    # A heavier worm-gear head of the BIT-PT850 class: pan 0.01-30 deg/s, tilt 0.01-15 deg/s.
    "heavy-worm": HeadParams(
        family="heavy-worm", pan_speed_max_deg_s=30.0, pan_turbo_deg_s=40.0,
        tilt_speed_max_deg_s=15.0, pan_accel_deg_s2=60.0, tilt_accel_deg_s2=40.0,
        dead_zone_byte=1, tilt_min_deg=-45.0, tilt_max_deg=75.0,
    ),
}


@dataclass(frozen=True)
class HeadState:
    """True head state at ``t_s`` (speeds include the ripple)."""

    t_s: float
    pan_deg: float
    tilt_deg: float
    pan_speed_deg_s: float
    tilt_speed_deg_s: float

    def as_dict(self) -> dict:
        return {
            "t_s": self.t_s,
            "pan_deg": self.pan_deg,
            "tilt_deg": self.tilt_deg,
            "pan_speed_deg_s": self.pan_speed_deg_s,
            "tilt_speed_deg_s": self.tilt_speed_deg_s,
        }


# ------------------------------------------------------------------------------------------------
# the unit's speed curve
# ------------------------------------------------------------------------------------------------
def unit_speed_table(
    rng: np.random.Generator, vmax: float, turbo: float | None, p: HeadParams
) -> np.ndarray:
    """Speed [deg/s] for each byte 0-255 of one axis of one unit (turbo at 0xFF if given).

    Bytes 0x40-0xFE act as 0x3F; without a turbo 0xFF acts as 0x3F too.
    """
    b0 = int(np.clip(p.dead_zone_byte + rng.integers(-1, 2), 0, 61))
    gamma = p.curve_gamma * math.exp(p.unit_gamma_spread * rng.standard_normal())
    gain = max(0.5, 1.0 + p.unit_gain_spread * rng.standard_normal())
    b = np.arange(b0, MAX_SPEED_BYTE + 1)
    x = (b - b0) / (MAX_SPEED_BYTE - b0)
    nominal = x**gamma
    steps = np.diff(nominal) * np.exp(p.unit_step_spread * rng.standard_normal(len(b) - 1))
    curve = np.concatenate(([0.0], np.cumsum(steps)))
    curve /= curve[-1]
    table = np.empty(256)
    table[: b0 + 1] = 0.0
    table[b0:MAX_SPEED_BYTE + 1] = gain * vmax * curve
    table[MAX_SPEED_BYTE + 1:] = table[MAX_SPEED_BYTE]
    if turbo is not None:
        t_gain = max(0.5, 1.0 + p.unit_gain_spread * rng.standard_normal())
        table[PAN_TURBO] = max(t_gain * turbo, 1.05 * table[MAX_SPEED_BYTE])
    return table


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

    ``segs`` changes only through :meth:`prune`, :meth:`_cut` and :meth:`_append`, which keep a
    mirror of the segments' ``(t0, p0, v0, a, r)`` in the columns ``_lo ..`` of ``_cols`` (a
    segment's fields other than ``t1`` never change once appended) and the number of kept
    segments with ripple, so the tables of :meth:`arrays` / :meth:`pieces` are one slice copy when
    the motion changed (``_table`` None), and reused while it has not.
    """

    _COLS0 = 64

    def __init__(self, name, p0, accel, stops, omega, phi, t_start=0.0):
        self.name = name
        self.accel = accel
        self.stops = stops  # (lo, hi) or None
        self.omega = omega
        self.phi = phi
        self.segs: list[_Seg] = []
        self.target_speed = 0.0
        self._set_cols(np.empty((5, self._COLS0)))
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
        s = self.segs[self._find(t)]
        p = _pos1(s.t0, s.p0, s.v0, s.a, s.r, self.omega, self.phi, t)
        return p, s.v0 + s.a * (t - s.t0), s

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
            self._arrays = tuple(self._table)
        return self._arrays

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
        return p, v

    def eval_position(self, t: np.ndarray) -> np.ndarray:
        """:meth:`eval`'s position alone; without ripple on the segments the ripple terms (two
        trigonometric arrays) are skipped: they are multiplied by zero there (the closed loop asks
        this for every frame)."""
        t0, p0, v0, a, r = self.arrays()
        idx = self._segment_of(t0, t)
        if self._n_ripple:   # some kept segment has ripple (times may come in any order)
            return _pos(t0[idx], p0[idx], v0[idx], a[idx], r[idx], self.omega, self.phi, t)
        d = t - t0[idx]
        return p0[idx] + v0[idx] * d + 0.5 * a[idx] * d * d   # _pos's order: the same bits

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
        """Append planned segments (NaN p0 = continue from the previous one), cutting at a stop."""
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
                    pushed = self.target_speed * side > 0
                    self._append(_Seg(t_hit, _INF, stop, 0.0, 0.0, 0.0, side if pushed else 0))
                    return
            self._append(s)

    def _append(self, s: _Seg) -> None:
        segs = self.segs
        if segs and segs[-1].t0 >= s.t0:  # a zero-length predecessor: replace it
            if segs.pop().r != 0:
                self._n_ripple -= 1
        if segs:
            segs[-1].t1 = s.t0
        segs.append(s)
        if s.r != 0:
            self._n_ripple += 1
        n = len(segs)
        cap = self._cap
        if self._lo + n > cap:   # out of columns: move the kept ones to the front (or grow)
            cols = np.empty((5, 2 * cap)) if 2 * n > cap else self._cols
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


# ------------------------------------------------------------------------------------------------
# the head
# ------------------------------------------------------------------------------------------------
class PTS303H:
    """The device model: bytes in at virtual times, motion and replies out.

    params : HeadParams, the family
    unit_seed : int, picks the unit (speed curves, ripple, garbage replies)
    feedback : 'none' | 'at-rest' | 'always'
    address : int, logical (DIP-switch) address; frames for other addresses are ignored
    pan0_deg, tilt0_deg : [deg] initial pose (tilt within the stops)
    t0_s : [s] virtual time the head starts at (at rest)
    """

    def __init__(
        self,
        params: HeadParams = HeadParams(),
        unit_seed: int = 0,
        feedback: str = "none",
        address: int = 1,
        pan0_deg: float = 0.0,
        tilt0_deg: float = 0.0,
        t0_s: float = 0.0,
    ) -> None:
        if feedback not in FEEDBACK_MODES:
            raise GimbalError(f"feedback={feedback!r} is not allowed; use one of {FEEDBACK_MODES}")
        if not isinstance(address, int) or not 0 <= address <= 256:
            raise GimbalError(f"address={address!r} is not allowed; use 0-256")
        if not params.tilt_min_deg <= tilt0_deg <= params.tilt_max_deg:
            raise GimbalError(
                f"tilt0_deg={tilt0_deg} is outside the stops "
                f"[{params.tilt_min_deg}, {params.tilt_max_deg}]"
            )
        self.params = params
        self.unit_seed = int(unit_seed)
        self.feedback = feedback
        self.address = address
        ss = np.random.SeedSequence([0x303, self.unit_seed])
        s_pan, s_tilt, s_ripple, s_garbage = ss.spawn(4)
        self._pan_table = unit_speed_table(
            np.random.default_rng(s_pan), params.pan_speed_max_deg_s, params.pan_turbo_deg_s, params
        )
        self._tilt_table = unit_speed_table(
            np.random.default_rng(s_tilt), params.tilt_speed_max_deg_s, None, params
        )
        self._pan_speeds = self._pan_table.tolist()
        self._tilt_speeds = self._tilt_table.tolist()
        rr = np.random.default_rng(s_ripple)
        f_pan, f_tilt = params.ripple_freq_hz * np.exp(0.1 * rr.standard_normal(2))
        ph_pan, ph_tilt = rr.uniform(0, 2 * np.pi, 2)
        self._garbage_rng = np.random.default_rng(s_garbage)
        self._pan = _Axis("pan", float(pan0_deg), params.pan_accel_deg_s2, None,
                          2 * np.pi * f_pan, float(ph_pan), t0_s)
        self._tilt = _Axis("tilt", float(tilt0_deg), params.tilt_accel_deg_s2,
                           (params.tilt_min_deg, params.tilt_max_deg),
                           2 * np.pi * f_tilt, float(ph_tilt), t0_s)
        self._parser = PelcoParser("DP")
        self._presets: dict[int, tuple[float, float]] = {}
        self._t_now = float(t0_s)
        self._t_rx_last = -math.inf  # time of the last byte received
        self._rx_times: deque[float] = deque(maxlen=9)
        self.frames_received = 0
        self.frames_ignored = 0

    # -- facts about the unit --------------------------------------------------------------
    def true_speed_deg_s(self, axis: str, byte: int) -> float:
        """The unit's true (ripple-free, steady) speed [deg/s] for a speed byte on an axis."""
        if axis not in AXES:
            raise GimbalError(f"axis={axis!r}; use 'pan' or 'tilt'")
        if not isinstance(byte, (int, np.integer)) or not 0 <= byte <= 255:
            raise GimbalError(f"speed byte {byte!r} out of range 0-255")
        return float((self._pan_table if axis == "pan" else self._tilt_table)[byte])

    def speed_table(self, axis: str) -> np.ndarray:
        """Copy of the unit's speed per byte (256 entries) for ``axis``."""
        return (self._pan_table if axis == "pan" else self._tilt_table).copy()

    @property
    def ripple_freq_hz(self) -> tuple[float, float]:
        return self._pan.omega / (2 * np.pi), self._tilt.omega / (2 * np.pi)

    @property
    def t_now_s(self) -> float:
        """Latest virtual time the model has been advanced or asked about."""
        return self._t_now

    # -- time --------------------------------------------------------------------------------
    def advance_to(self, t_s: float) -> None:
        """Declare that virtual time has reached ``t_s``; later commands may not act before it.

        Also forgets segments older than ``params.history_s`` before ``t_s``.
        """
        t_s = float(t_s)
        if t_s > self._t_now:
            self._t_now = t_s
        keep = self._t_now - self.params.history_s
        self._pan.prune(keep)
        self._tilt.prune(keep)

    def angles_at(self, t_s, wrap_pan: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """True (pan_deg, tilt_deg) at each time in ``t_s`` (vectorised; any shape).

        Times may go back ``params.history_s`` before the latest time the model was advanced to
        or asked about; asking advances the model to ``max(t_s)`` (after answering).  Pan is wrapped
        to (-180, 180], or with ``wrap_pan=False`` continuous (no jump at +-180: what an
        interpolation between times needs).
        """
        t = np.asarray(t_s, dtype=float)
        flat = t.reshape(-1)
        if not flat.size:
            return flat.reshape(t.shape), flat.reshape(t.shape)
        pan = self._pan.eval_position(flat)
        tilt = self._tilt.eval_position(flat)
        self.advance_to(float(flat.max()))
        return (wrap_pan_deg(pan) if wrap_pan else pan).reshape(t.shape), tilt.reshape(t.shape)

    def pose_segments(self, t0_s: float, t1_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The exact motion over ``[t0_s, t1_s]`` as constant-acceleration pieces, or None if the
        speed ripple is on (then use :meth:`angles_at`).

        Returns ``(pan, tilt)``, each (4, S) float64: rows ``t_start_s, angle_deg, speed_deg_s,
        accel_deg_s2`` of the kept pieces in time order (the one in force at ``t0_s`` among them;
        read-only, shared until the next command);
        the angle at ``t`` in piece ``i`` is ``angle + speed d + accel d^2 / 2`` with
        ``d = t - t_start``, the very expression of :meth:`angles_at` (pan unwrapped).  Like
        :meth:`angles_at`, asking advances the model to ``t1_s``.
        """
        out = []
        for axis in (self._pan, self._tilt):
            table, ripple = axis.pieces()
            if table[0, 0] > t0_s:
                raise ValueError(f"{axis.name}: time {t0_s} is before the kept history (starts {table[0, 0]})")
            if ripple:
                return None
            out.append(table)
        self.advance_to(t1_s)
        return out[0], out[1]

    def rates_at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """True (pan_speed_deg_s, tilt_speed_deg_s) at each time (vectorised, ripple included)."""
        t = np.asarray(t_s, dtype=float)
        flat = t.reshape(-1)
        out = self._pan.eval(flat)[1].reshape(t.shape), self._tilt.eval(flat)[1].reshape(t.shape)
        if t.size:
            self.advance_to(float(t.max()))
        return out

    def state_at(self, t_s: float) -> HeadState:
        t = np.array([float(t_s)])
        pan, vp = self._pan.eval(t)
        tilt, vt = self._tilt.eval(t)
        self.advance_to(float(t_s))
        return HeadState(float(t_s), float(wrap_pan_deg(pan[0])), float(tilt[0]),
                         float(vp[0]), float(vt[0]))

    def at_rest(self, t_s: float) -> bool:
        """Both axes stationary and not pushing into a stop at ``t_s``."""
        for ax in (self._pan, self._tilt):
            s = ax.segs[ax._find(t_s)]
            v = s.v0 + s.a * (t_s - s.t0)
            if v != 0 or s.a != 0 or s.pinned:
                return False
        return True

    # -- bytes in ----------------------------------------------------------------------------
    def receive(self, data: bytes, t_s) -> list[tuple[float, bytes]]:
        """Bytes arriving at virtual time ``t_s`` (one time for the chunk, or one per byte).

        Returns the replies as ``(send_time_s, frame_bytes)``.  Times must not decrease, and a
        command may not take effect before a time already asked about (``ValueError``).
        """
        data = bytes(data)
        if isinstance(t_s, (int, float, np.floating)):
            times = [float(t_s)] * len(data)
        else:
            times = [float(x) for x in t_s]
            if len(times) != len(data):
                raise ValueError(f"{len(times)} byte times for {len(data)} bytes")
        replies: list[tuple[float, bytes]] = []
        parser = self._parser
        n = len(data)
        i = 0
        while i < n:
            # Fast path: a clean Pelco-D frame at once (the closed loop's every frame).  It leaves
            # parser, receive times and head as the byte-by-byte route below would (tested).
            if data[i] == SYNC_D and i + 7 <= n and not parser._buf:
                j = i + 7
                ts = times[i:j]
                last = self._t_rx_last
                for t in ts:
                    if t < last:
                        break
                    last = t
                else:
                    cmd = parser.take_clean_d(data, i, times)
                    if cmd is not None:
                        self._t_rx_last = last
                        self._rx_times.extend(ts)
                        replies.extend(self._handle(cmd, last))
                        i = j
                        continue
            b = data[i]
            t = times[i]
            i += 1
            if t < self._t_rx_last:
                raise ValueError(f"bytes must arrive in time order: {t} < {self._t_rx_last}")
            self._t_rx_last = t
            self._rx_times.append(t)
            for cmd in parser.feed(_BYTE[b], t):
                replies.extend(self._handle(cmd, t))
        return replies

    def _line_quiet_before_frame(self, cmd: PelcoCommand) -> float:
        n = 7 if cmd.protocol == "D" else 8
        times = list(self._rx_times)
        if len(times) < n + 1:
            return math.inf
        return times[-n] - times[-n - 1]

    def _handle(self, cmd: PelcoCommand, t: float) -> list[tuple[float, bytes]]:
        if cmd.address != self.address:
            return []
        self.frames_received += 1
        p = self.params
        te = t + p.dead_time_s
        kind = cmd.kind
        if kind == "pan_tilt" or kind == "stop":
            self._check_causal(te)
            # Python floats of the tables: the same products as with the numpy scalars
            vp = cmd.pan_dir * self._pan_speeds[cmd.pan_byte]
            vt = cmd.tilt_dir * self._tilt_speeds[cmd.tilt_byte]
            self._pan.set_speed(te, vp, p.ripple_rel)
            self._tilt.set_speed(te, vt, p.ripple_rel)
            return []
        if kind == "set_preset":
            pan, tilt = self.angles_now(t)
            self._presets[cmd.preset] = (pan, tilt)
            return []
        if kind == "clear_preset":
            self._presets.pop(cmd.preset, None)
            return []
        if kind == "goto_preset":
            if cmd.preset not in self._presets:
                self.frames_ignored += 1
                return []
            self._check_causal(te)
            pan, tilt = self._presets[cmd.preset]
            self._pan.goto(te, pan, self._pan_table[MAX_SPEED_BYTE])
            self._tilt.goto(te, tilt, self._tilt_table[MAX_SPEED_BYTE])
            return []
        if kind in ("set_pan", "set_tilt"):
            if self._line_quiet_before_frame(cmd) < p.abs_set_quiet_s or not word_is_angle(
                cmd.word
            ):
                self.frames_ignored += 1
                return []
            self._check_causal(te)
            if kind == "set_pan":
                self._pan.goto(te, word_to_pan_deg(cmd.word), self._pan_table[MAX_SPEED_BYTE])
            else:
                tilt = word_to_tilt_deg(cmd.word, p.tilt_zero)
                self._tilt.goto(te, tilt, self._tilt_table[MAX_SPEED_BYTE])
            return []
        if kind in ("query_pan", "query_tilt"):
            return self._answer(cmd, t)
        self.frames_ignored += 1  # camera functions, replies from others, unknown extended
        return []

    def angles_now(self, t: float) -> tuple[float, float]:
        pan, _, _ = self._pan.state(t)
        tilt, _, _ = self._tilt.state(t)
        return float(wrap_pan_deg(pan)), tilt

    def _answer(self, cmd: PelcoCommand, t: float) -> list[tuple[float, bytes]]:
        if self.feedback == "none":
            return []
        pan, tilt = self.angles_now(t)
        is_pan = cmd.kind == "query_pan"
        truth = pan if is_pan else tilt
        to_word = pan_deg_to_word if is_pan else (
            lambda d: tilt_deg_to_word(d, self.params.tilt_zero)
        )
        if self.feedback == "at-rest" and not self.at_rest(t):
            word = self._garbage_word(truth, is_pan)
        else:
            word = to_word(truth)
        enc = encode_pan_reply if is_pan else encode_tilt_reply
        return [(t + self.params.reply_delay_s, enc(cmd.address, word, cmd.protocol))]

    def _garbage_word(self, truth_deg: float, is_pan: bool) -> int:
        """A checksum-valid reply word that does not decode to within the margin of the truth."""
        while True:
            word = int(self._garbage_rng.integers(0, 1 << 16))
            if not word_is_angle(word):
                return word
            dec = word_to_pan_deg(word) if is_pan else word_to_tilt_deg(word, self.params.tilt_zero)
            if abs(wrap_pan_deg(dec - truth_deg)) > self.params.garbage_margin_deg:
                return word

    def _check_causal(self, te: float) -> None:
        if te < self._t_now:
            raise ValueError(
                f"a command taking effect at t={te:.9f} s arrived after the model was asked "
                f"about t={self._t_now:.9f} s; feed bytes before asking about later times"
            )
