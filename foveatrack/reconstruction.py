"""Head-angle dead reckoning and world-frame trajectory reconstruction (paper Fig. 14c, App. D.4).

The head reports no orientation, so its angles are estimated by integrating the calibrated speed of
each command actually sent: "the rotation speed is determined from the command and then integrated
to produce the angle estimate" (App. D.4).

Timing model (per axis)
-----------------------
A command written at ``t_s`` takes effect at ``t_s + latency_s + dead_time_s`` (latency: the link,
e.g. 7.29 ms for a Pelco-D frame at 9600 baud, plus adapter delays; dead time: the head's own).
From then the speed ramps to the table speed of the new byte at ``accel_deg_s2`` (None: at once),
integrated exactly (piecewise constant acceleration).  Tilt stops at ``tilt_limits_deg`` (the head
physically stops there); the stop absorbs the speed, so after a hit the speed ramps from rest toward
the commanded one (a reversal that braked into the stop leaves it at once), as in the head model
(:mod:`gimbal.pts303h`, "Travel").

Uncertainty growth (1 sigma, per axis, independent axes)
--------------------------------------------------------
.. math:: \\sigma^2(t) = \\sigma_0^2 + \\sum_b \\big(\\sigma_b\\, S_b(t)\\big)^2
          + \\sum_i (\\Delta v_i\\, \\sigma_t)^2 + q\\,(t - t_0)

* ``S_b`` = signed time spent at byte ``b`` (direction x duration): a table error of byte ``b`` is a
  *systematic* bias that repeats every time the byte is used, so it adds linearly in time at that
  byte and cancels between left and right (the table is direction-symmetric);
* ``sigma_t`` = timing uncertainty of each speed change ``Delta v_i`` (``timing_sigma_s``);
* ``q`` = random-walk rate [deg^2/s] for speed ripple (``random_walk_deg2_s``).

World frame convention
----------------------
The world frame is the head's base: origin at the head centre (intersection of the axes), Z up,
X = the direction of pan 0 / tilt 0.  The lidar sits on the tilt stage with its axes parallel to the
stage's and its origin at ``lidar_offset_m`` from the head centre (stage coordinates).  Then

.. math:: p_{world} = R_z(pan)\\, R_y(-tilt)\\, (p_{lidar} + o)

i.e. pan about world Z, then tilt about the pan-rotated Y axis; tilt up turns the optical axis to
``(cos t cos p, cos t sin p, sin t)``.  R is rebuilt from the (wrapped) angles each time, never
accumulated as a product, so it stays orthonormal to machine precision over any duration.
"""

from __future__ import annotations

import abc
import bisect
import itertools
import math
from dataclasses import dataclass

import numpy as np

from foveatrack.control import HeadCommand
from foveatrack.detection import Detection, wrap_deg
from foveatrack.fixed_order import mat3_vec, norm3, rows_times_mat3T
from foveatrack.speed_table import TURBO, AxisTable, SpeedTable


def head_trig(pan_deg: float, tilt_deg: float) -> tuple[float, float, float, float]:
    """``(cos pan, sin pan, cos tilt, sin tilt)`` of a head pose [deg]: what :func:`rotation_matrix`
    is made of (the box kernel, :func:`foveatrack.kernels.box_median_kernel`, makes R from them)."""
    p = math.radians(pan_deg if -180.0 < pan_deg <= 180.0 else wrap_deg(pan_deg))   # wrap_deg keeps these
    t = math.radians(tilt_deg)
    return math.cos(p), math.sin(p), math.cos(t), math.sin(t)


def rotation_entries(pan_deg: float, tilt_deg: float) -> tuple[float, ...]:
    """The nine entries of ``R_z(pan) @ R_y(-tilt)``, row by row, as floats: the one place the
    rotation is written (:func:`rotation_rows`, :func:`rotation_matrix` and the sky tracker's node
    rotations take them)."""
    cp, sp, ct, st = head_trig(pan_deg, tilt_deg)
    return (cp * ct, -sp, -cp * st, sp * ct, cp, -sp * st, st, 0.0, ct)


def rotation_rows(pan_deg: float, tilt_deg: float) -> tuple[tuple[float, float, float], ...]:
    """:func:`rotation_matrix`'s rows as floats (cheaper than the array for one product)."""
    e = rotation_entries(pan_deg, tilt_deg)
    return e[0:3], e[3:6], e[6:9]


def rotation_matrix(pan_deg: float, tilt_deg: float) -> np.ndarray:
    """``R_z(pan) @ R_y(-tilt)``: head (tilt-stage) coordinates -> world (see module docstring)."""
    return np.array(rotation_entries(pan_deg, tilt_deg)).reshape(3, 3)


@dataclass(slots=True)
class _Knot:
    t: float            # effect time [s]
    angle: float        # angle at t [deg] (pan kept wrapped)
    v: float            # actual speed at t [deg/s]
    v_tgt: float        # target speed from t on [deg/s, signed]
    idx: int            # byte index 0..64 of the target (64 = turbo), -1 = stop
    direction: int
    S: np.ndarray       # signed time per byte index up to t [s]
    var_timing: float   # accumulated sum (dv sigma_t)^2 [deg^2]
    var_bytes: float = 0.0  # sum over bytes (sigma_b S_b)^2 at t [deg^2] (set by the integrator)
    sig_run: float = 0.0    # sigma_b of the running byte (idx >= 0), as a float for ``state``
    s_run: float = 0.0      # S of the running byte at t [s]


_axis_angles_kernel = None


class _AxisIntegrator:
    def __init__(self, table: AxisTable, angle0: float, sigma0: float, t0: float, accel: float | None,
                 limits: tuple[float, float] | None, wrap: bool, timing_sigma_s: float, q: float,
                 history_s: float):
        self.table = table
        self.accel = accel
        self.limits = limits
        self.wrap = wrap
        self.sig_b = np.nan_to_num(table.speeds_array()[1], nan=0.0)
        self._sig_b_list = self.sig_b.tolist()
        self.sigma0 = sigma0
        self._var0 = sigma0 ** 2
        self.timing_sigma_s = timing_sigma_s
        self.q = q
        self.t0 = t0
        self.history_s = history_s
        self.knots = [_Knot(t0, angle0, 0.0, 0.0, -1, 0, np.zeros(65), 0.0)]
        self.times = [t0]
        self.forgot_before = -math.inf   # the motion before this time was trimmed from the history

    def _advance(self, k: _Knot, t: float) -> tuple[float, float]:
        """Angle and speed at time t >= k.t."""
        tau = t - k.t
        dv = k.v_tgt - k.v
        if self.accel is None or dv == 0.0:
            ang, v = k.angle + k.v_tgt * tau, k.v_tgt
            if self.accel is None and k.v != k.v_tgt and tau == 0.0:
                v = k.v
        else:
            a = math.copysign(self.accel, dv)
            T = abs(dv) / self.accel
            if tau <= T:
                ang, v = k.angle + k.v * tau + 0.5 * a * tau * tau, k.v + a * tau
            else:
                ang = k.angle + k.v * T + 0.5 * a * T * T + k.v_tgt * (tau - T)
                v = k.v_tgt
        if self.limits is not None:
            if self.accel is not None and k.v * k.v_tgt < 0.0:   # a reversal: did it reach a stop?
                hit = self._reversal_at_stop(k, tau)
                if hit is not None:
                    ang, v = hit
            lo, hi = self.limits
            if ang > hi or ang < lo:   # monotone motion into a stop: held there
                ang, v = min(max(ang, lo), hi), 0.0
        return ang, v

    def _reversal_at_stop(self, k: _Knot, tau: float) -> tuple[float, float] | None:
        """Angle and speed ``tau`` after knot ``k`` if the deceleration of a reversal carried the head
        into a stop first, else None.

        The stop absorbs the speed (the device model's rule, :mod:`gimbal.pts303h.kinematics`): from
        the hit the speed ramps from rest toward the (reversed) target, so the head leaves the stop
        at once.  In closed form: with speed ``u`` toward the stop, gap ``g`` and deceleration ``b``,
        the hit is at ``tau_h = 2g / (u + sqrt(u^2 - 2bg))`` (the earlier root, without cancellation).
        """
        side = 1.0 if k.v > 0.0 else -1.0
        stop = self.limits[1] if side > 0 else self.limits[0]
        u, b = abs(k.v), self.accel
        g = max(side * (stop - k.angle), 0.0)
        t_turn = u / b
        reach = u * min(tau, t_turn) - 0.5 * b * min(tau, t_turn) ** 2   # travel toward the stop
        if reach <= g:
            return None
        tau_hit = 2.0 * g / (u + math.sqrt(max(u * u - 2.0 * b * g, 0.0)))
        s = tau - tau_hit
        w = abs(k.v_tgt)
        t_ramp = w / b
        if s <= t_ramp:
            away, v = 0.5 * b * s * s, b * s
        else:
            away, v = 0.5 * b * t_ramp * t_ramp + w * (s - t_ramp), w
        return stop - side * away, -side * v

    def _knot_at(self, t: float) -> tuple[_Knot, float] | None:
        """The knot in force at ``t`` and the instant to advance it to (:meth:`state` and
        :meth:`angle`); None before the kept history."""
        times = self.times
        if t >= times[-1]:   # the usual: since the newest knot
            return self.knots[-1], t
        i = bisect.bisect_right(times, t) - 1
        if i >= 0:
            return self.knots[i], t
        if self.forgot_before > -math.inf:   # the commands in force then are forgotten
            return None
        k = self.knots[0]   # before the start pose: the head rested there (homed) until then
        return k, k.t

    def _knot_before(self, t: float) -> _Knot | None:
        i = bisect.bisect_right(self.times, t) - 1
        return self.knots[i] if i >= 0 else None

    def state(self, t: float) -> tuple[float, float, float]:
        """(angle, speed, sigma) at t; before the kept history (``history_s`` behind the newest
        command), unknown: NaN angle and speed with infinite sigma."""
        found = self._knot_at(t)
        if found is None:
            return math.nan, math.nan, math.inf
        k, t = found
        ang, v = self._advance(k, t)
        var_b = k.var_bytes
        if k.idx >= 0:   # only the running byte's time has grown since the knot
            sb = k.sig_run
            s0 = k.s_run
            var_b += (sb * (s0 + k.direction * (t - k.t))) ** 2 - (sb * s0) ** 2
        var = self._var0 + var_b + k.var_timing
        if self.q:   # the ripple's random walk (none by default: adding q * dt = 0.0 would change no bit)
            var += self.q * max(t - self.t0, 0.0)
        var = max(var, 0.0)
        if self.wrap and not -180.0 < ang <= 180.0:   # in range: wrap_deg returns it unchanged
            ang = wrap_deg(ang)
        return ang, v, math.sqrt(var)

    def angle(self, t: float) -> float:
        """``state(t)[0]`` (the same bits) without the speed's and the variance's work: the knot picked
        and advanced as :meth:`state` does."""
        found = self._knot_at(t)
        if found is None:
            return math.nan
        ang, _ = self._advance(*found)
        if self.wrap and not -180.0 < ang <= 180.0:
            ang = wrap_deg(ang)
        return ang

    def angles_into(self, ts: np.ndarray, t_min: float, out: np.ndarray, col: int) -> None:
        """``out[i, col] = angle(ts[i])`` (the same bits) for the instants ``ts`` (K,) float64, the
        earliest ``t_min``: the knots in force from then passed to one kernel call
        (:func:`foveatrack.kernels.axis_angles_kernel`), where eleven calls of :meth:`angle` were
        most of a frame's node poses.  Instants before the kept knots, and a knot whose reversal may
        carry the head into a stop, are :meth:`angle`'s own."""
        global _axis_angles_kernel
        if _axis_angles_kernel is None:     # numba loads on first use, not on import
            from foveatrack.kernels import axis_angles_kernel as _axis_angles_kernel
        times = self.times
        if not t_min >= times[0]:
            for i, t in enumerate(ts.tolist()):
                out[i, col] = self.angle(t)
            return
        K = np.array([(k.t, k.angle, k.v, k.v_tgt) for k in self.knots[bisect.bisect_right(times, t_min) - 1:]])
        py = np.zeros(ts.size, np.bool_)
        lo, hi = self.limits if self.limits is not None else (0.0, 0.0)
        if _axis_angles_kernel(K, 0.0 if self.accel is None else float(self.accel), self.accel is not None, float(lo),
                               float(hi), self.limits is not None, self.wrap, ts, out, col, py):
            for i in np.flatnonzero(py).tolist():
                out[i, col] = self.angle(float(ts[i]))

    def command(self, t_eff: float, direction: int, byte: int) -> None:
        last = self.knots[-1]
        if t_eff < last.t:
            raise ValueError(f"commands must come in time order (effect time {t_eff} < {last.t})")
        if t_eff == last.t and len(self.knots) > 1:
            # A second command at the same instant replaces the first (a driver's gate limited it,
            # its write failed, the head is frozen): one change of speed, not two, so its timing
            # variance is counted once.
            self.knots.pop()
            self.times.pop()
            last = self.knots[-1]
        idx = -1 if direction == 0 else (64 if byte == TURBO else byte)
        if idx == last.idx and direction == last.direction:   # the same speed (its byte was checked then)
            return
        v_tgt = 0.0 if direction == 0 else direction * self.table.speed_deg_s(byte)
        if not math.isfinite(v_tgt):
            raise ValueError(f"byte {byte} has no known speed in the {self.table.axis} table")
        ang, v = self._advance(last, t_eff)
        if last.idx >= 0:
            S = last.S.copy()
            S[last.idx] += last.direction * (t_eff - last.t)
            var_bytes = float(((self.sig_b * S) ** 2).sum())
        else:   # the axis was stopped: no byte's time grew (a knot's S is never written after this)
            S, var_bytes = last.S, last.var_bytes
        dv = v_tgt - last.v_tgt
        var_t = last.var_timing + (dv * self.timing_sigma_s) ** 2
        if self.wrap:
            ang = wrap_deg(ang)
        self.knots.append(_Knot(t_eff, ang, v, v_tgt, idx, direction, S, var_t, var_bytes,
                                self._sig_b_list[idx] if idx >= 0 else 0.0, float(S[idx]) if idx >= 0 else 0.0))
        self.times.append(t_eff)
        # bound memory: keep knots within history_s of the newest (always >= 2)
        cut = bisect.bisect_left(self.times, t_eff - self.history_s) - 1
        if cut > 0:
            del self.knots[:cut]
            del self.times[:cut]
            self.forgot_before = self.times[0]


    def shift(self, t: float, d: float) -> None:
        """From ``t`` on, the angle is ``d`` [deg] more: a correction of the dead reckoning by an outside
        witness (:mod:`foveatrack.pose_check`).  A knot at ``t`` continues the motion in force there
        (speed, ramp, byte time) from the shifted angle; the later knots move by ``d`` with it."""
        i = bisect.bisect_right(self.times, t)
        if i == 0:                       # before the start pose: the whole history moves
            later = self.knots
        else:
            k = self.knots[i - 1]
            ang, v = self._advance(k, t)
            if k.idx >= 0:
                S = k.S.copy()
                S[k.idx] += k.direction * (t - k.t)
                var_bytes = float(((self.sig_b * S) ** 2).sum())
            else:
                S, var_bytes = k.S, k.var_bytes
            ang += d
            if self.wrap:
                ang = wrap_deg(ang)
            knot = _Knot(t, ang, v, k.v_tgt, k.idx, k.direction, S, k.var_timing, var_bytes, k.sig_run,
                         float(S[k.idx]) if k.idx >= 0 else 0.0)
            self.knots.insert(i, knot)
            self.times.insert(i, t)
            later = self.knots[i + 1:]
        for k in later:
            k.angle = wrap_deg(k.angle + d) if self.wrap else k.angle + d


class HeadPose(abc.ABC):
    """What a source of head angles gives the tracker once it has ``angles_at(t_s)`` -> ``(pan_deg,
    tilt_deg, sigma_pan_deg, sigma_tilt_deg)`` and ``lidar_offset_m``: the head's rotation, points and
    detections in the world.  Shared by the commands' dead reckoning (:class:`Reconstructor`) and the
    gyro's (:class:`foveatrack.gyro_attitude.GyroAttitude`), so both place a detection the same way."""

    lidar_offset_m: np.ndarray

    @abc.abstractmethod
    def angles_at(self, t_s: float) -> tuple[float, float, float, float]:
        """``(pan_deg, tilt_deg, sigma_pan_deg, sigma_tilt_deg)`` of the head at ``t_s`` [s]."""

    @abc.abstractmethod
    def speeds_at(self, t_s: float) -> tuple[float, float]:
        """The head's (pan, tilt) speeds [deg/s] at ``t_s`` (the sky schedule's saccade times)."""

    @abc.abstractmethod
    def accels_deg_s2(self) -> tuple[float | None, float | None]:
        """The (pan, tilt) accelerations [deg/s^2] the head turns at (None: at once)."""

    def rotation_at(self, t_s: float) -> np.ndarray:
        p, t, _, _ = self.angles_at(t_s)
        return rotation_matrix(p, t)

    def lidar_to_world(self, xyz: np.ndarray, t_s: float) -> np.ndarray:
        """Points (N, 3) in the lidar frame at one time -> world frame (``(xyz + offset) @ R.T``, turned
        as the box kernel turns them: :func:`foveatrack.fixed_order.rows_times_mat3T`)."""
        return rows_times_mat3T(np.asarray(xyz, float).reshape(-1, 3) + self.lidar_offset_m, self.rotation_at(t_s))

    def to_world(self, detection: Detection) -> tuple[np.ndarray, float]:
        """World position of a detection and its 1-sigma position uncertainty [m] from the head-angle
        uncertainty: ``sigma^2 = (rho sigma_pan)^2 + (r sigma_tilt)^2`` with ``rho`` the horizontal
        distance from the pan axis and ``r`` the distance from the head centre (radians inside)."""
        p, t, sp, st = self.angles_at(detection.t_s)
        q = np.asarray(detection.xyz, float) + self.lidar_offset_m
        w = mat3_vec(rotation_rows(p, t), q)   # R @ q in a fixed order (BLAS's differs per CPU)
        w0, w1, _ = w.tolist()
        rho = math.hypot(w0, w1)
        r = norm3(q)
        sigma = math.hypot(rho * math.radians(sp), r * math.radians(st))
        return w, sigma


class Reconstructor(HeadPose):
    """Estimate the head angles from the commands sent, and place detections in the world.

    Parameters
    ----------
    speed_table : SpeedTable          calibrated (or nominal) speeds and per-byte sigma
    pan0_deg, tilt0_deg : float       head angles at ``t0_s`` (e.g. after homing) [deg]
    sigma0_deg : float >= 0           their uncertainty [deg]
    latency_s : float >= 0            link latency from send to arrival of the frame [s]
    dead_time_s, accel_deg_s2         head timing; default: the table's values
    tilt_limits_deg : (lo, hi)        the tilt stops [deg]
    timing_sigma_s : float >= 0       uncertainty of each command's effect time [s]
    random_walk_deg2_s : float >= 0   speed-ripple random walk [deg^2/s]
    lidar_offset_m : (3,)             lidar origin in tilt-stage coordinates [m]
    history_s : float > 0             how far back ``angles_at`` can look [s]: commands older than this
                                      before the newest are forgotten, and an instant before the kept
                                      ones is answered NaN with infinite sigma (unknown), never with
                                      a confident angle
    """

    def __init__(self, speed_table: SpeedTable, *, pan0_deg: float = 0.0, tilt0_deg: float = 0.0,
                 sigma0_deg: float = 0.0, t0_s: float = 0.0, latency_s: float = 0.0,
                 dead_time_s: float | None = None, accel_deg_s2: float | None = None,
                 tilt_limits_deg: tuple[float, float] = (-90.0, 90.0), timing_sigma_s: float = 0.002,
                 random_walk_deg2_s: float = 0.0, lidar_offset_m=(0.0, 0.0, 0.0), history_s: float = 60.0):
        self.table = speed_table
        self.latency_s = latency_s
        self.dead_time_s = speed_table.dead_time_s if dead_time_s is None else dead_time_s
        self.lidar_offset_m = np.asarray(lidar_offset_m, float)
        # the table's per-axis accelerations, unless one is given here for both
        acc_pan = speed_table.axis_accel_deg_s2("pan") if accel_deg_s2 is None else accel_deg_s2
        acc_tilt = speed_table.axis_accel_deg_s2("tilt") if accel_deg_s2 is None else accel_deg_s2
        self.pan = _AxisIntegrator(speed_table.pan, wrap_deg(pan0_deg), sigma0_deg, t0_s, acc_pan, None, True,
                                   timing_sigma_s, random_walk_deg2_s, history_s)
        self.tilt = _AxisIntegrator(speed_table.tilt, tilt0_deg, sigma0_deg, t0_s, acc_tilt,
                                    tuple(tilt_limits_deg), False, timing_sigma_s, random_walk_deg2_s, history_s)
        self.last_command: HeadCommand | None = None
        self.last_send_t_s: float | None = None
        self._memo: dict[float, tuple[float, float, float, float]] = {}
        self._n_carried = 0   # the memo's first entries, carried over the last command

    @property
    def effect_delay_s(self) -> float:
        return self.latency_s + self.dead_time_s

    def on_command(self, t_s: float, cmd: HeadCommand) -> None:
        """Record that ``cmd`` was written to the head at ``t_s`` (commands in time order)."""
        t_eff = t_s + self.effect_delay_s
        memo, self._memo = self._memo, {}
        if cmd is not self.last_command or t_eff <= max(self.pan.times[-1], self.tilt.times[-1]):
            # (the same command later changes neither axis: each would return at its first test)
            self.pan.command(t_eff, cmd.pan_dir, cmd.pan_byte)
            self.tilt.command(t_eff, cmd.tilt_dir, cmd.tilt_byte)
        self.last_command = cmd
        self.last_send_t_s = t_s
        # A command changes nothing before its effect time: answers for earlier instants still
        # hold (same knot), unless the trim of old history moved an instant before the first knot.
        # Only the instants asked since the previous command are carried (older ones are not asked
        # again in practice, and the memo stays small).
        t_first = max(self.pan.times[0], self.tilt.times[0])
        # (a loop: a comprehension's own call costs more than it saves over these few entries)
        carried = self._memo
        for t, ans in itertools.islice(memo.items(), self._n_carried, None):
            if t_first <= t < t_eff:
                carried[t] = ans
        self._n_carried = len(carried)

    def shift(self, t_s: float, dpan_deg: float, dtilt_deg: float) -> None:
        """From ``t_s`` on, the estimated angles are ``(dpan_deg, dtilt_deg)`` more (the pose check's
        correction of the drift, :mod:`foveatrack.pose_check`); the commands' timing is kept."""
        self.pan.shift(t_s, dpan_deg)
        self.tilt.shift(t_s, dtilt_deg)
        self._memo = {}
        self._n_carried = 0

    def angles_at(self, t_s: float) -> tuple[float, float, float, float]:
        """(pan_deg, tilt_deg, sigma_pan_deg, sigma_tilt_deg) at ``t_s``; pan wrapped to (-180, 180].

        Before the start time ``t0_s``: the start pose (the head rested there).  Older than the kept
        history (``history_s`` before the newest command, once that has forgotten anything): NaN
        angles with infinite sigmas.  The drivers only ask about the current frame and the next
        command's effect, well inside the history."""
        # A frame asks about a few instants several times (D's frame, the detection, the command's
        # effect, the driver's log); an answer only changes with a command effective before it.
        hit = self._memo.get(t_s)
        if hit is not None:
            return hit
        p, _, sp = self.pan.state(t_s)
        t, _, st = self.tilt.state(t_s)
        if len(self._memo) >= 8:
            self._memo.clear()
            self._n_carried = 0
        ans = self._memo[t_s] = (p, t, sp, st)
        return ans

    def pan_tilt_many(self, times) -> list[tuple[float, float]]:
        """``angles_at(t)[:2]`` at each of ``times`` (the same bits), without the sigmas: the twin of
        :meth:`pan_tilt_array`, by which a frame's per-point turn asks eleven instants
        (:func:`foveatrack.sky.world_points.node_rotations`).  An instant the memo holds is answered
        from it; the others are not put in it (a pure cache: the answers do not depend on what it
        holds)."""
        memo = self._memo
        out = []
        for t in times:
            hit = memo.get(t)
            out.append((hit[0], hit[1]) if hit is not None else (self.pan.angle(t), self.tilt.angle(t)))
        return out

    def pan_tilt_array(self, times, increasing: bool = False) -> np.ndarray:
        """:meth:`pan_tilt_many`'s angles as a (K, 2) float64 array (the same bits), each axis by one
        kernel call (:meth:`_AxisIntegrator.angles_into`): the sky tracker's eleven node poses a
        frame, ~12 us in pan_tilt_many's calls.  The memo is neither read nor written (its answers
        are the same bits).  ``increasing``: the caller's word that ``times`` never decrease (the
        first is the earliest; a frame's nodes), which spares their minimum's search."""
        ts = np.ascontiguousarray(times, np.float64).reshape(-1)
        out = np.empty((ts.size, 2))
        if ts.size:
            t_min = float(ts[0]) if increasing else float(ts.min())
            self.pan.angles_into(ts, t_min, out, 0)
            self.tilt.angles_into(ts, t_min, out, 1)
        return out

    def tilt_at(self, t_s: float) -> tuple[float, float]:
        """(tilt_deg, sigma_tilt_deg) at ``t_s``: ``angles_at(t_s)[1::2]`` without integrating pan."""
        hit = self._memo.get(t_s)
        if hit is not None:
            return hit[1], hit[3]
        t, _, st = self.tilt.state(t_s)
        return t, st

    def speeds_at(self, t_s: float) -> tuple[float, float]:
        """Estimated actual (pan, tilt) speeds [deg/s] at ``t_s``."""
        return self.pan.state(t_s)[1], self.tilt.state(t_s)[1]

    def accels_deg_s2(self) -> tuple[float | None, float | None]:
        """The (pan, tilt) accelerations [deg/s^2] the dead reckoning ramps the speed at (None: at once)."""
        return self.pan.accel, self.tilt.accel

