"""The PTS-303H device: Pelco bytes in (parsed, timed, dead time), the axes moved, replies out
(see :mod:`gimbal.pts303h`)."""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from gimbal.errors import GimbalError
from gimbal.framing import PelcoParser
from gimbal.pelco import (
    MAX_SPEED_BYTE,
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
from gimbal.pts303h.kinematics import _Axis
from gimbal.pts303h.params import _BYTE, AXES, FEEDBACK_MODES, HeadParams, HeadState, unit_speed_table


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
    speed_scale : float > 0, the unit's speeds now over its curve at the temperature it was
        calibrated at (thermal drift of the speed curve, ``1 + coefficient * delta_T``; 1: none).
        The unit's curve itself (:meth:`calibrated_speed_deg_s`) is unchanged
    dead_time_jitter_s : float >= 0 [s], width of the uniform spread of each command's dead time
        around ``params.dead_time_s`` (the head's controller starts a command on its next tick)
    dead_time_rng : numpy Generator, the jitter's own stream (one uniform per frame addressed to
        the head, in arrival order); needed when ``dead_time_jitter_s > 0``
    backlash_deg : float >= 0 [deg], the free play of each axis's worm gear: on a reversal the motor
        turns this far before the output follows (see :class:`~gimbal.pts303h.kinematics._Axis`);
        :meth:`pose_segments` then offers no constant-acceleration pieces (the output is not one)
    deflection : object or None, an elastic deflection of the output added to the geared motion (the
        wind's torque on the head over the drive's stiffness, :class:`sim.effects.WindOnHead`), a pure
        function of time: ``deflection.angles_deg(t_s) -> (pan_deg, tilt_deg)`` and
        ``deflection.rates_deg_s(t_s) -> (pan_deg_s, tilt_deg_s)`` for a float array of times.  Also
        no constant-acceleration pieces then
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
        speed_scale: float = 1.0,
        dead_time_jitter_s: float = 0.0,
        dead_time_rng: np.random.Generator | None = None,
        backlash_deg: float = 0.0,
        deflection=None,
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
        if not (math.isfinite(speed_scale) and speed_scale > 0):
            raise GimbalError(f"speed_scale={speed_scale!r} is not allowed; must be > 0")
        if not (math.isfinite(dead_time_jitter_s) and dead_time_jitter_s >= 0):
            raise GimbalError(f"dead_time_jitter_s={dead_time_jitter_s!r} is not allowed; must be >= 0")
        if not (math.isfinite(backlash_deg) and 0 <= backlash_deg <= 5):
            raise GimbalError(f"backlash_deg={backlash_deg!r} is not allowed; 0 <= backlash_deg <= 5")
        if dead_time_jitter_s > 0 and dead_time_rng is None:
            raise GimbalError("dead_time_jitter_s > 0 needs dead_time_rng (the jitter's random stream)")
        self.params = params
        self.speed_scale = float(speed_scale)
        self.backlash_deg = float(backlash_deg)
        self.deflection = deflection
        self.dead_time_jitter_s = float(dead_time_jitter_s)
        self._dead_time_rng = dead_time_rng if dead_time_jitter_s > 0 else None
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
        if self.speed_scale != 1.0:   # thermal drift: every speed of the curve by the same factor
            self._pan_table_now = self._pan_table * self.speed_scale
            self._tilt_table_now = self._tilt_table * self.speed_scale
        else:
            self._pan_table_now, self._tilt_table_now = self._pan_table, self._tilt_table
        self._pan_speeds = self._pan_table_now.tolist()
        self._tilt_speeds = self._tilt_table_now.tolist()
        rr = np.random.default_rng(s_ripple)
        f_pan, f_tilt = params.ripple_freq_hz * np.exp(0.1 * rr.standard_normal(2))
        ph_pan, ph_tilt = rr.uniform(0, 2 * np.pi, 2)
        self._garbage_rng = np.random.default_rng(s_garbage)
        self._ripple = (2 * np.pi * f_pan, float(ph_pan), 2 * np.pi * f_tilt, float(ph_tilt))
        self._power_on_deg = (float(pan0_deg), float(tilt0_deg))
        self._power_up(t0_s)
        self.power_cycles = 0
        self._parser = PelcoParser("DP")
        self._presets: dict[int, tuple[float, float]] = {}
        self._t_now = float(t0_s)
        self._t_rx_last = -math.inf  # time of the last byte received
        self._rx_times: deque[float] = deque(maxlen=9)
        self.frames_received = 0
        self.frames_ignored = 0

    def _power_up(self, t_s: float) -> None:
        """Both axes at rest at the power-on pose from ``t_s``."""
        p = self.params
        w_pan, ph_pan, w_tilt, ph_tilt = self._ripple
        play = self.backlash_deg
        self._pan = _Axis("pan", self._power_on_deg[0], p.pan_accel_deg_s2, None, w_pan, ph_pan, t_s, play)
        self._tilt = _Axis("tilt", self._power_on_deg[1], p.tilt_accel_deg_s2, (p.tilt_min_deg, p.tilt_max_deg),
                           w_tilt, ph_tilt, t_s, play)

    def power_cycle(self, t_s: float) -> None:
        """The head lost power and came back at ``t_s`` (a brown-out, a loose supply plug; its serial
        link may stay up): it stands at its power-on pose (``pan0_deg``, ``tilt0_deg``), with no memory of
        its motion (angles before ``t_s`` are no longer known to the model) and a fresh frame parser;
        its presets, kept in non-volatile memory, survive."""
        t_s = max(float(t_s), self._t_now)
        self._power_up(t_s)
        self._parser = PelcoParser("DP")
        self._rx_times.clear()
        self._t_now = t_s
        self.power_cycles += 1

    # -- facts about the unit --------------------------------------------------------------
    def true_speed_deg_s(self, axis: str, byte: int) -> float:
        """The unit's true (ripple-free, steady) speed [deg/s] for a speed byte on an axis, now
        (with the thermal drift ``speed_scale``)."""
        self._check_axis_byte(axis, byte)
        return float((self._pan_table_now if axis == "pan" else self._tilt_table_now)[byte])

    def calibrated_speed_deg_s(self, axis: str, byte: int) -> float:
        """The unit's speed curve at the temperature it was calibrated at (no thermal drift): what a
        perfect calibration made then holds."""
        self._check_axis_byte(axis, byte)
        return float((self._pan_table if axis == "pan" else self._tilt_table)[byte])

    def _check_axis_byte(self, axis: str, byte: int) -> None:
        if axis not in AXES:
            raise GimbalError(f"axis={axis!r}; use 'pan' or 'tilt'")
        if not isinstance(byte, (int, np.integer)) or not 0 <= byte <= 255:
            raise GimbalError(f"speed byte {byte!r} out of range 0-255")

    def speed_table(self, axis: str) -> np.ndarray:
        """Copy of the unit's speed per byte (256 entries) for ``axis``, now (thermal drift included)."""
        return (self._pan_table_now if axis == "pan" else self._tilt_table_now).copy()

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
        if self.deflection is not None:
            d_pan, d_tilt = self.deflection.angles_deg(flat)
            pan, tilt = pan + d_pan, tilt + d_tilt
        self.advance_to(float(flat.max()))
        return (wrap_pan_deg(pan) if wrap_pan else pan).reshape(t.shape), tilt.reshape(t.shape)

    def pose_segments(self, t0_s: float, t1_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The exact motion over ``[t0_s, t1_s]`` as constant-acceleration pieces, or None if the
        speed ripple or the backlash is on (then use :meth:`angles_at`).

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
            if ripple or axis.half_play or self.deflection is not None:   # no constant-acceleration pieces
                return None
            out.append(table)
        self.advance_to(t1_s)
        return out[0], out[1]

    def rates_at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """True (pan_speed_deg_s, tilt_speed_deg_s) at each time (vectorised, ripple included)."""
        t = np.asarray(t_s, dtype=float)
        flat = t.reshape(-1)
        vp, vt = self._pan.eval(flat)[1], self._tilt.eval(flat)[1]
        if self.deflection is not None and flat.size:
            d_pan, d_tilt = self.deflection.rates_deg_s(flat)
            vp, vt = vp + d_pan, vt + d_tilt
        out = vp.reshape(t.shape), vt.reshape(t.shape)
        if t.size:
            self.advance_to(float(t.max()))
        return out

    def state_at(self, t_s: float) -> HeadState:
        t = np.array([float(t_s)])
        pan, vp = self._pan.eval(t)
        tilt, vt = self._tilt.eval(t)
        if self.deflection is not None:
            (d_pan, d_tilt), (r_pan, r_tilt) = self.deflection.angles_deg(t), self.deflection.rates_deg_s(t)
            pan, tilt, vp, vt = pan + d_pan, tilt + d_tilt, vp + r_pan, vt + r_tilt
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
            if data[i] == SYNC_D and i + 7 <= n and parser.idle:
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
        if self._dead_time_rng is not None:   # one draw per frame for this head, whatever its kind
            te = max(t, te + self.dead_time_jitter_s * (self._dead_time_rng.random() - 0.5))
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
            self._pan.goto(te, pan, self._pan_table_now[MAX_SPEED_BYTE])
            self._tilt.goto(te, tilt, self._tilt_table_now[MAX_SPEED_BYTE])
            return []
        if kind in ("set_pan", "set_tilt"):
            if self._line_quiet_before_frame(cmd) < p.abs_set_quiet_s or not word_is_angle(
                cmd.word
            ):
                self.frames_ignored += 1
                return []
            self._check_causal(te)
            if kind == "set_pan":
                self._pan.goto(te, word_to_pan_deg(cmd.word), self._pan_table_now[MAX_SPEED_BYTE])
            else:
                tilt = word_to_tilt_deg(cmd.word, p.tilt_zero)
                self._tilt.goto(te, tilt, self._tilt_table_now[MAX_SPEED_BYTE])
            return []
        if kind in ("query_pan", "query_tilt"):
            return self._answer(cmd, t)
        self.frames_ignored += 1  # camera functions, replies from others, unknown extended
        return []

    def angles_now(self, t: float) -> tuple[float, float]:
        pan, tilt = self._pan.output_at(t), self._tilt.output_at(t)
        if self.deflection is not None:
            d_pan, d_tilt = self.deflection.angles_deg(np.array([float(t)]))
            pan, tilt = pan + float(d_pan[0]), tilt + float(d_tilt[0])
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
