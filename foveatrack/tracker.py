"""The tracker: frames in, neutral head commands out (paper Algorithms 1 and 2, App. D).

One object for every driver (closed-loop simulator, replay, daemon)::

    tracker = Tracker(TrackerConfig.from_mapping(scene["tracker"], where="scene.toml [tracker]"), table)
    for frame in slicer.push(xyz, t_ns):
        out = tracker.process(frame)            # detection, command, state, errors, head estimate
        port.write(pelco_encode(out.command))   # the driver encodes the neutral command

``process`` registers the command with the head reconstruction as written at
``frame.t_end_s + send_delay_s`` unless the driver passes the actual ``send_t_s``.

States (:class:`TrackState`)
----------------------------
``WAITING``   no target seen yet (or the search timed out): head stopped.
``TRACKING``  a detection this frame: Algorithm 2 (or the predictive controller).
``HOLDING``   lost for less than ``hold_s``: paper controller stops the head (a brief dropout must
              not send it off); predictive controller coasts at the filtered target rate.
``SEARCHING`` lost for longer: pan sweeps at ``search_pan_speed_deg_s`` in the direction the target
              was last moving (or last seen, if its rate is unknown), tilt moves toward
              ``search_tilt_deg`` (if set) at the P-gain, both kept off the stops; after
              ``search_timeout_s`` the head stops and the tracker waits (``WAITING``).

Stops: every tilt command (and pan, if ``pan_limits_deg`` is set) is limited so the reconstructed
angle + 2 sigma stays ``tilt_margin_deg`` inside the stops ``stop_lookahead_s`` ahead
(:func:`foveatrack.control.limit_for_stops`).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace

import numpy as np

from foveatrack.config_util import as_bool, as_choice, as_float, as_vec, check_keys
from foveatrack.control import (STOP, HeadCommand, deadband_p, head_command, head_errors_deg,
                                limit_for_stops, speed_to_axis)
from foveatrack.detection import LEVEL, Detection, box_bounds, box_detection, detect, frozen_maker, wrap_deg
from foveatrack.errors import UserError
from foveatrack.frames import Frame
from foveatrack.gyro_attitude import GyroAttitude
from foveatrack.predictive import BearingFilter
from foveatrack.reconstruction import Reconstructor, head_trig
from foveatrack.space_of_interest import Box, SpaceOfInterest, space_from_mapping, space_to_mapping
from foveatrack.speed_table import SpeedTable
from gimbal.head_facts import DEFAULT_HEAD


_ZERO3 = np.zeros(3)


class TrackState(enum.Enum):
    WAITING = "waiting"
    TRACKING = "tracking"
    HOLDING = "holding"
    SEARCHING = "searching"


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker parameters (a scene's ``[tracker]`` table or the daemon config).

    rate_hz : float > 0 [Hz]                 frame rate (paper 10 Hz)
    deadband_pan_deg, deadband_tilt_deg : >= 0 [deg]   dead band per axis (paper 2 deg);
                                             mapping key ``deadband_deg`` sets both
    gain_pan_1_s, gain_tilt_1_s : > 0 [1/s]  proportional gains k (``gain_1_s`` sets both)
    max_pan_speed_deg_s, max_tilt_speed_deg_s : > 0 or None [deg/s]  saturation (None: table max)
    allow_turbo : bool                       may pan use the 0xFF turbo byte
    controller : "paper" | "predictive"
    error_frame : "lidar" | "head"           bearing errors in the lidar frame (paper) or the head
                                             frame using the tilt estimate (the predictive
                                             controller always uses "head")
    space : D or None                        space of interest (None: every valid point)
    min_points : int >= 1                    fewer retained points -> no detection
    tilt_limits_deg : (lo, hi) [deg]         the head's tilt stops
    pan_limits_deg : (lo, hi) or None        pan stops (None: continuous 360 deg)
    tilt_margin_deg : >= 0 [deg]             keep this far from a stop
    stop_lookahead_s : > 0 [s]               horizon for the stop limit
    hold_s : >= 0 [s]                        lost-target hold time before searching
    search : "sweep" | "hold"                what to do after holding
    search_pan_speed_deg_s : > 0 [deg/s]
    search_tilt_deg : float or None [deg]    tilt to return to while searching (None: keep)
    search_timeout_s : > 0 or None [s]       stop searching after this (None: never)
    send_delay_s : >= 0 [s]                  frame end -> command written (if the driver doesn't say)
    latency_s : >= 0 [s]                     link latency (default: one Pelco-D frame at 9600 baud,
                                             7.29 ms, gimbal.head_facts.DEFAULT_HEAD.frame_time_s)
    dead_time_s, accel_deg_s2 : or None      head timing (None: the speed table's)
    timing_sigma_s : >= 0 [s]                per-command timing uncertainty for the reconstruction
    pan0_deg, tilt0_deg : [deg]              head angles at start
    lidar_offset_m : (x, y, z) [m]           lidar origin in tilt-stage coordinates
    pred_q_deg2_s3, pred_r_deg2 : > 0        predictive filter noise (see foveatrack.predictive)
    pred_deadband_deg : >= 0 [deg]           dead band of the predictive controller's corrective
                                             term (the feed-forward rate keeps the head moving, so
                                             the paper's 2 deg would park the target at the edge)
    attitude : "commands" | "gyro"           where the head's angles come from: dead reckoning of
                                             the commands sent (paper App. D.4), or the lidar's
                                             bias-corrected gyro (foveatrack.gyro_attitude; needs
                                             the lidar's IMU samples, fed with Tracker.on_imu)
    imu_rotation_deg : (roll, pitch, yaw) [deg]  the IMU's mount in the lidar frame (R = Rz Ry Rx,
                                             the result of ``foveatrack calibrate-imu``); gyro only
    gyro_noise_deg_s_rthz : > 0              gyro white noise density (BMI088: 0.014); gyro only
    gyro_bias_walk_deg_s_rts : >= 0          gyro bias random walk; gyro only
    gyro_rest_margin_s : >= 0 [s]            after a STOP, wait this long past the expected
                                             deceleration before taking the head as at rest

    A ``sky`` sub-table (``[tracker.sky]``) is not a setting of this tracker: it asks the driver for
    the multi-object tracker and its attention (:mod:`foveatrack.sky.controller`), which drives the
    head through this one; it is checked there.
    """

    rate_hz: float = 10.0
    deadband_pan_deg: float = 2.0
    deadband_tilt_deg: float = 2.0
    gain_pan_1_s: float = 2.0
    gain_tilt_1_s: float = 2.0
    max_pan_speed_deg_s: float | None = None
    max_tilt_speed_deg_s: float | None = None
    allow_turbo: bool = False
    controller: str = "paper"
    error_frame: str = "lidar"
    space: SpaceOfInterest | None = None
    min_points: int = 1
    tilt_limits_deg: tuple[float, float] = DEFAULT_HEAD.tilt_limits_deg
    pan_limits_deg: tuple[float, float] | None = None
    tilt_margin_deg: float = 3.0
    stop_lookahead_s: float = 0.3
    hold_s: float = 1.0
    search: str = "sweep"
    search_pan_speed_deg_s: float = 5.0
    search_tilt_deg: float | None = None
    search_timeout_s: float | None = 60.0
    send_delay_s: float = 0.0
    latency_s: float = DEFAULT_HEAD.frame_time_s
    dead_time_s: float | None = None
    accel_deg_s2: float | None = None
    timing_sigma_s: float = 0.002
    pan0_deg: float = 0.0
    tilt0_deg: float = 0.0
    lidar_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pred_q_deg2_s3: float = 4.0
    pred_r_deg2: float = 0.04
    pred_deadband_deg: float = 0.3
    attitude: str = "commands"
    imu_rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_noise_deg_s_rthz: float = 0.014
    gyro_bias_walk_deg_s_rts: float = 0.001
    gyro_rest_margin_s: float = 0.2

    CONTROLLERS = ("paper", "predictive")
    ATTITUDES = ("commands", "gyro")
    GYRO_KEYS = ("imu_rotation_deg", "gyro_noise_deg_s_rthz", "gyro_bias_walk_deg_s_rts", "gyro_rest_margin_s")
    ERROR_FRAMES = ("lidar", "head")
    SEARCHES = ("sweep", "hold")

    @property
    def period_s(self) -> float:
        return 1.0 / self.rate_hz

    @classmethod
    def from_mapping(cls, data: Mapping, where: str = "[tracker]") -> "TrackerConfig":
        """Validate a mapping (TOML table).  Unknown keys and bad values raise UserError naming
        ``where``, the key and what is allowed."""
        names = [f.name for f in fields(cls)]
        check_keys(data, names + ["deadband_deg", "gain_1_s", "sky"], where)
        kw: dict = {}
        f = lambda k, **a: as_float(data[k], k, where, **a)  # noqa: E731
        for k in data:
            if k in ("deadband_deg",):
                kw["deadband_pan_deg"] = kw["deadband_tilt_deg"] = f(k, lo=0)
            elif k == "gain_1_s":
                kw["gain_pan_1_s"] = kw["gain_tilt_1_s"] = f(k, lo=0, lo_open=True)
            elif k in ("deadband_pan_deg", "deadband_tilt_deg", "tilt_margin_deg", "hold_s", "send_delay_s",
                       "latency_s", "timing_sigma_s", "pred_deadband_deg", "gyro_bias_walk_deg_s_rts"):
                kw[k] = f(k, lo=0)
            elif k in ("rate_hz", "gain_pan_1_s", "gain_tilt_1_s", "stop_lookahead_s", "search_pan_speed_deg_s",
                       "pred_q_deg2_s3", "pred_r_deg2", "gyro_noise_deg_s_rthz"):
                kw[k] = f(k, lo=0, lo_open=True)
            elif k in ("max_pan_speed_deg_s", "max_tilt_speed_deg_s", "search_timeout_s", "accel_deg_s2"):
                kw[k] = as_float(data[k], k, where, lo=0, lo_open=True, allow_none=True)
            elif k == "dead_time_s":
                kw[k] = as_float(data[k], k, where, lo=0, allow_none=True)
            elif k in ("pan0_deg",):
                kw[k] = f(k, lo=-180, hi=180)
            elif k in ("tilt0_deg",):
                kw[k] = f(k, lo=-90, hi=90)
            elif k == "search_tilt_deg":
                kw[k] = as_float(data[k], k, where, lo=-90, hi=90, allow_none=True)
            elif k == "allow_turbo":
                kw[k] = as_bool(data[k], k, where)
            elif k == "controller":
                kw[k] = as_choice(data[k], k, where, cls.CONTROLLERS)
            elif k == "error_frame":
                kw[k] = as_choice(data[k], k, where, cls.ERROR_FRAMES)
            elif k == "search":
                kw[k] = as_choice(data[k], k, where, cls.SEARCHES)
            elif k == "space":
                kw[k] = None if data[k] is None else space_from_mapping(data[k], f"{where}.space")
            elif k == "sky":   # the multi-object opt-in: read by the driver (foveatrack.sky.controller)
                if not isinstance(data[k], Mapping):
                    raise UserError(f"{where}: sky must be a table of the sky tracker's keys, got {data[k]!r}")
            elif k == "min_points":
                v = data[k]
                if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                    raise UserError(f"{where}: min_points must be an integer >= 1, got {v!r}")
                kw[k] = v
            elif k in ("tilt_limits_deg", "pan_limits_deg"):
                if k == "pan_limits_deg" and data[k] is None:
                    kw[k] = None
                    continue
                lo, hi = as_vec(data[k], k, where, 2)
                lim = 90 if k == "tilt_limits_deg" else 1e6
                if not -lim <= lo < hi <= lim:
                    raise UserError(f"{where}: {k} must be [lo, hi] with lo < hi"
                                    f"{' within [-90, 90]' if lim == 90 else ''}, got {data[k]!r}")
                kw[k] = (lo, hi)
            elif k == "lidar_offset_m":
                kw[k] = as_vec(data[k], k, where, 3)
            elif k == "attitude":
                kw[k] = as_choice(data[k], k, where, cls.ATTITUDES)
            elif k == "imu_rotation_deg":
                v = as_vec(data[k], k, where, 3)
                if max(abs(x) for x in v) > 180:
                    raise UserError(f"{where}: imu_rotation_deg angles must be within +-180 deg, got {list(v)}")
                kw[k] = v
            elif k == "gyro_rest_margin_s":
                kw[k] = f(k, lo=0, hi=10)
        cfg = cls(**kw)
        lo, hi = cfg.tilt_limits_deg
        if not lo + cfg.tilt_margin_deg < hi - cfg.tilt_margin_deg:
            raise UserError(f"{where}: tilt_margin_deg {cfg.tilt_margin_deg} leaves no room inside "
                            f"tilt_limits_deg {cfg.tilt_limits_deg}")
        if not lo <= cfg.tilt0_deg <= hi:
            raise UserError(f"{where}: tilt0_deg {cfg.tilt0_deg} is outside tilt_limits_deg {cfg.tilt_limits_deg}")
        return cfg

    def effective(self) -> dict:
        """Every setting as it runs, for a recording's metadata and a person reading it (the space of
        interest by its kind and parameters; a learned background by its size only)."""
        def plain(v):
            if isinstance(v, tuple):
                return [plain(x) for x in v]
            if dataclasses.is_dataclass(v):
                d = {f.name: plain(getattr(v, f.name)) for f in fields(v) if not f.name.startswith("_")}
                return {"kind": type(v).__name__, **d}
            if isinstance(v, (set, frozenset)):
                return len(v)
            return v
        # The gyro's settings only when it runs: a recording made before they existed (attitude from
        # the commands) still rebuilds as recorded.
        skip = () if self.attitude == "gyro" else ("attitude",) + self.GYRO_KEYS
        return {f.name: plain(getattr(self, f.name)) for f in fields(self) if f.name not in skip}

    def to_mapping(self) -> dict:
        """Every setting as the ``[tracker]`` table :meth:`from_mapping` reads back to an equal
        configuration (JSON-plain: tuples as lists, D as its table): the body of configuration a
        recording keeps of the run (:class:`foveatrack.recording.run_meta.RecordingMeta`)."""
        def plain(v):
            return [plain(x) for x in v] if isinstance(v, tuple) else v
        return {f.name: space_to_mapping(self.space) if f.name == "space" and self.space is not None
                else plain(getattr(self, f.name)) for f in fields(self)}

    def with_head(self, facts, table: Mapping | None = None, where: str = "[tracker]") -> "TrackerConfig":
        """This configuration with the head's facts (:class:`gimbal.head_facts.HeadFacts`).

        One rule in every driver (simulator, replay, daemon): the stops, the start pose and the link
        timing are the head's, configured with the head (``[gimbal]`` in a scene, ``[head]`` in a
        daemon config), and always win.  A ``[tracker]`` ``table`` that sets one of them to another
        value is an error naming the key (the same value is accepted).
        """
        vals = facts.tracker_values()
        for k, v in vals.items():
            if table is not None and k in table:
                given = table[k]
                same = (tuple(float(x) for x in given) == v) if isinstance(v, tuple) else \
                    (isinstance(given, (int, float)) and abs(float(given) - v) <= 1e-9 * max(1.0, abs(v)))
                if not same:
                    raise UserError(f"{where}: {k} = {given!r} contradicts the head's {list(v) if isinstance(v, tuple) else v!r}: "
                                    "it is a fact of the head and its link, set with the head ([head] in a daemon "
                                    "config, [gimbal] in a scene); remove it from [tracker]")
        cfg = replace(self, **vals)
        lo, hi = cfg.tilt_limits_deg
        if not lo + cfg.tilt_margin_deg < hi - cfg.tilt_margin_deg or not lo <= cfg.tilt0_deg <= hi:
            raise UserError(f"{where}: the head's tilt leaves no room: tilt_limits_deg {list(cfg.tilt_limits_deg)}, "
                            f"tilt_margin_deg {cfg.tilt_margin_deg}, tilt0_deg {cfg.tilt0_deg}")
        return cfg


@dataclass(frozen=True)
class TrackOutput:
    """What the tracker decided for one frame.

    t_s : frame end time [s]
    state : TrackState
    detection : Detection or None
    command : HeadCommand
    pan_speed_deg_s, tilt_speed_deg_s : table speeds of the commanded bytes, signed [deg/s]
    error_pan_deg, error_tilt_deg : bearing errors used (None without a detection) [deg]
    head_pan_deg, head_tilt_deg, head_sigma_pan_deg, head_sigma_tilt_deg : reconstruction at
        the detection time (or frame end without a detection) [deg]
    world_xyz : (3,) or None, world_sigma_m : float or None   detection placed in the world
    stop_limited : True if a stop limit reduced a speed this frame
    """

    t_s: float
    state: TrackState
    detection: Detection | None
    command: HeadCommand
    pan_speed_deg_s: float
    tilt_speed_deg_s: float
    error_pan_deg: float | None
    error_tilt_deg: float | None
    head_pan_deg: float
    head_tilt_deg: float
    head_sigma_pan_deg: float
    head_sigma_tilt_deg: float
    world_xyz: np.ndarray | None
    world_sigma_m: float | None
    stop_limited: bool = False


_make_output = frozen_maker(TrackOutput)   # TrackOutput(...) without the frozen init's per-field cost


class Tracker:
    """Algorithms 1 and 2 at ``config.rate_hz`` with head dead reckoning.  See module docstring."""

    def __init__(self, config: TrackerConfig, speed_table: SpeedTable, *, t0_s: float = 0.0):
        self.config = config
        self.table = speed_table
        self.recon = Reconstructor(
            speed_table, pan0_deg=config.pan0_deg, tilt0_deg=config.tilt0_deg, t0_s=t0_s,
            latency_s=config.latency_s, dead_time_s=config.dead_time_s, accel_deg_s2=config.accel_deg_s2,
            tilt_limits_deg=config.tilt_limits_deg, timing_sigma_s=config.timing_sigma_s,
            lidar_offset_m=config.lidar_offset_m)
        if config.attitude == "gyro":
            self.recon = GyroAttitude(
                self.recon, imu_rotation_deg=config.imu_rotation_deg,
                noise_density_deg_s_rthz=config.gyro_noise_deg_s_rthz,
                bias_walk_deg_s_rts=config.gyro_bias_walk_deg_s_rts, rest_margin_s=config.gyro_rest_margin_s)
        self.state = TrackState.WAITING
        self.pan_filter = BearingFilter(config.pred_q_deg2_s3, config.pred_r_deg2, wrap=True)
        self.tilt_filter = BearingFilter(config.pred_q_deg2_s3, config.pred_r_deg2, wrap=False)
        self.last_detection_t_s: float | None = None
        self.last_pan_error_deg = 0.0
        self.lost_since_s: float | None = None
        self.last_command: HeadCommand = STOP
        self._head_errors = config.error_frame == "head" or config.controller == "predictive"
        # A box D (the common case) is tested by one kernel call with its bounds made once here:
        # (lo, hi, in the world frame?), or None for any other D.
        space = config.space
        self._box = None
        if isinstance(space, Box):
            self._box = box_bounds(space) + (getattr(space, "frame", "lidar") == "world",)

    def rebased(self, t0_s: float, pan_deg: float, tilt_deg: float) -> "Tracker":
        """A fresh tracker (state and filters restarted) with this one's configuration and speed table,
        whose dead reckoning starts at ``(pan_deg, tilt_deg)`` at sensor time ``t0_s`` [s]: what the
        daemon does when the lidar's clock restarts or the head was homed (its ``tracker_rebased``
        event), and what replay repeats from that event."""
        cfg = replace(self.config, pan0_deg=float(pan_deg), tilt0_deg=float(tilt_deg))
        return Tracker(cfg, self.table, t0_s=float(t0_s))

    def correct_pose(self, t_s: float, dpan_deg: float, dtilt_deg: float) -> bool:
        """Move the dead reckoning by ``(dpan_deg, dtilt_deg)`` from sensor time ``t_s`` on (the pose
        check's drift correction, :mod:`foveatrack.pose_check`; the daemon's ``pose_corrected`` event,
        which replay repeats).  False where the attitude is not dead-reckoned from the commands
        (``attitude = "gyro"``: the gyro is its own witness), and nothing is changed."""
        shift = getattr(self.recon, "shift", None)
        if shift is None:
            return False
        shift(float(t_s), float(dpan_deg), float(dtilt_deg))
        return True

    # ------------------------------------------------------------------------------------------
    def process(self, frame: Frame, send_t_s: float | None = None) -> TrackOutput:
        return self.steer(frame, self._detect(frame), send_t_s)

    def steer(self, frame: Frame, det: Detection | None, send_t_s: float | None = None,
              gains_1_s: tuple[float, float] | None = None, search: bool = True) -> TrackOutput:
        """Algorithm 2 (and the lost-target states) on a detection of ``frame`` made by the caller:
        :meth:`process`'s Algorithm 1, or the sky tracker's in the fixated track's D
        (:mod:`foveatrack.sky.controller`).  ``gains_1_s``: (pan, tilt) gains for this frame in
        place of the configured ones (the sky tracker's saccades; the paper controller only).
        ``search``: without a detection past ``hold_s`` the configured lost-target search runs
        (false: the head holds, as with ``search = "hold"``: the sky tracker's fovea with nothing to
        serve)."""
        cfg = self.config
        t_now = frame.t_end_s
        send_t = t_now + cfg.send_delay_s if send_t_s is None else send_t_s
        err_pan = err_tilt = None
        world = sigma_w = None
        if det is not None:
            hp, ht, sp, st = self.recon.angles_at(det.t_s)
            if self._head_errors:
                err_pan, err_tilt = head_errors_deg(det.xyz, ht, cfg.lidar_offset_m)
            else:   # lidar_errors_deg(det.xyz): the detection's bearing, already computed
                err_pan, err_tilt = det.az_deg, det.el_deg
            world, sigma_w = self.recon.to_world(det)
            self.last_detection_t_s = det.t_s
            self.last_pan_error_deg = err_pan
            self.lost_since_s = None
            self.state = TrackState.TRACKING
            v_pan, v_tilt = self._control(det, err_pan, err_tilt, hp, ht, send_t, gains_1_s)
        else:
            hp, ht, sp, st = self.recon.angles_at(t_now)
            v_pan, v_tilt = self._lost(t_now, send_t, ht, search)
        cmd, vp, vt, limited = self._to_command(v_pan, v_tilt, send_t)
        self.recon.on_command(send_t, cmd)
        self.last_command = cmd
        return _make_output(t_now, self.state, det, cmd, vp, vt, err_pan, err_tilt, hp, ht, sp, st,
                            world, sigma_w, limited)

    def on_imu(self, t_s, gyro_rad_s) -> None:
        """The lidar's gyro samples (time order; ``t_s`` (N,) on the frames' clock [s], ``gyro_rad_s``
        (N, 3) in the IMU frame [rad/s]), fed before the frame they precede.  Ignored unless
        ``attitude = "gyro"``: the commands' dead reckoning has no use for them."""
        if self.config.attitude == "gyro":
            self.recon.on_imu(t_s, gyro_rad_s)

    def command_sent(self, t_s: float, cmd: HeadCommand) -> None:
        """For drivers that send extra commands of their own (e.g. a stop on shutdown)."""
        self.recon.on_command(t_s, cmd)
        self.last_command = cmd

    # ------------------------------------------------------------------------------------------
    def _detect(self, frame: Frame) -> Detection | None:
        """Algorithm 1 on the frame, D tested in its own frame (the lidar's, or the world at the
        head's estimated pose at mid-frame)."""
        if self._box is not None:   # the common D, in one pass
            lo, hi, in_world = self._box
            if in_world:
                pan, tilt, _, _ = self.recon.angles_at(frame.t_mid_s)
                trig, offset = head_trig(pan, tilt), self.recon.lidar_offset_m
            else:
                trig, offset = LEVEL, _ZERO3
            det = box_detection(frame.xyz, frame.t_ns, trig, offset, lo, hi)
        else:
            space = self.config.space
            test_xyz = None
            if space is not None and getattr(space, "frame", "lidar") == "world" and frame.n_points:
                test_xyz = self.recon.lidar_to_world(frame.xyz, frame.t_mid_s)
            det = detect(frame, space, test_xyz=test_xyz)
        if det is not None and det.n_points < self.config.min_points:
            return None
        return det

    def _control(self, det, err_pan, err_tilt, hp, ht, send_t, gains_1_s=None) -> tuple[float, float]:
        cfg = self.config
        if cfg.controller == "paper":
            kp, kt = (cfg.gain_pan_1_s, cfg.gain_tilt_1_s) if gains_1_s is None else gains_1_s
            return (deadband_p(err_pan, cfg.deadband_pan_deg, kp),
                    deadband_p(err_tilt, cfg.deadband_tilt_deg, kt))
        # predictive: filter the world bearing, feed its rate forward
        self.pan_filter.update(det.t_s, hp + err_pan)
        self.tilt_filter.update(det.t_s, ht + err_tilt)
        return self._predictive_speeds(send_t, corrective=True)

    def _predictive_speeds(self, send_t: float, corrective: bool) -> tuple[float, float]:
        cfg = self.config
        t_act = send_t + self.recon.effect_delay_s
        hp_a, ht_a, _, _ = self.recon.angles_at(t_act)
        th_p, om_p, _ = self.pan_filter.predict(t_act)
        th_t, om_t, _ = self.tilt_filter.predict(t_act)
        if self.pan_filter.n_updates < 3:   # rate not yet observable: plain P
            om_p = om_t = 0.0
        v_pan, v_tilt = om_p, om_t
        if corrective:
            v_pan += deadband_p(wrap_deg(th_p - hp_a), cfg.pred_deadband_deg, cfg.gain_pan_1_s)
            v_tilt += deadband_p(th_t - ht_a, cfg.pred_deadband_deg, cfg.gain_tilt_1_s)
        return v_pan, v_tilt

    def _lost(self, t_now: float, send_t: float, tilt_est: float, search: bool = True) -> tuple[float, float]:
        cfg = self.config
        if self.last_detection_t_s is None:
            self.state = TrackState.WAITING
            return 0.0, 0.0
        since = t_now - self.last_detection_t_s
        if since < cfg.hold_s:
            self.state = TrackState.HOLDING
            if cfg.controller == "predictive" and self.pan_filter.initialised:
                return self._predictive_speeds(send_t, corrective=False)
            return 0.0, 0.0
        sweep = search and cfg.search == "sweep"      # the caller may hold the head whatever the config says
        if not sweep or (cfg.search_timeout_s is not None and since >= cfg.hold_s + cfg.search_timeout_s):
            self.state = TrackState.WAITING if sweep else TrackState.HOLDING
            if sweep:
                self.last_detection_t_s = None   # the search is over; wait for a new target
                self.pan_filter.reset()
                self.tilt_filter.reset()
            return 0.0, 0.0
        self.state = TrackState.SEARCHING
        direction = 1.0
        if self.pan_filter.initialised and self.pan_filter.n_updates >= 3 and abs(self.pan_filter.x[1]) > 0.1:
            direction = math.copysign(1.0, self.pan_filter.x[1])
        elif self.last_pan_error_deg != 0.0:
            direction = math.copysign(1.0, self.last_pan_error_deg)
        v_tilt = 0.0
        if cfg.search_tilt_deg is not None:
            v_tilt = deadband_p(cfg.search_tilt_deg - tilt_est, cfg.deadband_tilt_deg, cfg.gain_tilt_1_s)
        return direction * cfg.search_pan_speed_deg_s, v_tilt

    def _to_command(self, v_pan: float, v_tilt: float, send_t: float) -> tuple[HeadCommand, float, float, bool]:
        cfg = self.config
        t_act = send_t + self.recon.effect_delay_s
        # A zero speed needs no stop limit (limit_for_stops returns (0.0, False) without the angle):
        # the head's estimate at t_act is only worked out for a moving axis.  (A -0.0 left as it is
        # gives the same command: speed_to_axis takes either zero as stop.)
        lim_t = False
        if v_tilt != 0.0:
            tilt_a, s_tilt = self.recon.tilt_at(t_act)
            v_tilt, lim_t = limit_for_stops(v_tilt, tilt_a, s_tilt, *cfg.tilt_limits_deg, cfg.tilt_margin_deg,
                                            cfg.stop_lookahead_s)
        lim_p = False
        if cfg.pan_limits_deg is not None and v_pan != 0.0:
            pan_a, _, s_pan, _ = self.recon.angles_at(t_act)
            v_pan, lim_p = limit_for_stops(v_pan, pan_a, s_pan, *cfg.pan_limits_deg, cfg.tilt_margin_deg,
                                           cfg.stop_lookahead_s)
        pd, pb, vp = speed_to_axis(v_pan, self.table.pan, max_speed_deg_s=cfg.max_pan_speed_deg_s,
                                   allow_turbo=cfg.allow_turbo, floor=lim_p)
        td, tb, vt = speed_to_axis(v_tilt, self.table.tilt, max_speed_deg_s=cfg.max_tilt_speed_deg_s,
                                   floor=lim_t)
        return head_command(pd, pb, td, tb), vp, vt, lim_t or lim_p
