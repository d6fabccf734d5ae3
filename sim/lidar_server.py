"""The scene's lidar in real time on UDP (``foveatrack lidar serve SCENE.toml``).

A :class:`SceneSource` turns a scene into the ``source(t0_ns, t1_ns)`` that
:class:`sim.virtual_lidar.VirtualLivox` streams: for the slots of ``[t0_ns, t1_ns)`` it runs the
scene's scan model (:class:`sim.scan.model.ScanModel` with ``scene.optics``), turns the beams into the
world at the head pose of each point's own time (:func:`sim.world.kernels.rotate_pan_tilt_kernel`),
casts them against the targets (culled by :func:`~sim.world.kernels.bodies_candidates_kernel`, each
target at the point's own time, :func:`~sim.world.kernels.cast_moving_kernel`) and the background
(:func:`~sim.world.kernels.cast_static_kernel`), and applies the effects the scene lists -- the
same steps 2-5 as :meth:`sim.loop.ClosedLoop.step` (DESIGN.md "How data flows").  Stream time 0 is
scene time 0, and by default (``clock="sampling"``) that is when a host first starts sampling, not when
the serve starts: a daemon that connects late (a cold start's compiles, a loaded machine) still sees
the scene from its beginning.  ``clock="start"`` starts it with the serve (as before 2026-12).  Past
the scene's ``duration_s`` the stream goes on (the trajectories past their end: straight, circle and
figure-eight flights keep flying, waypoint and manual ones hover where they end), and ``status`` is
told so once.  The random streams are the scene's (:func:`sim.effects.effect_rng`), so two serves
of one scene with the same batches give the same points; the batches follow the wall clock, so a
served run is not bit-identical to the closed-loop simulator (which is what replay is for).

Head pose ("follows the virtual head's pose if the scene's gimbal is served too")
---------------------------------------------------------------------------------
``foveatrack gimbal serve --truth FILE`` writes the head's true state as JSON lines every
``--truth-period-s`` (20 ms).  :class:`TruthTail` follows that file: it reads the complete new lines
at every source call, maps head time to the lidar's stream time through ``time.monotonic`` (the
head's ``t_s`` = monotonic − its clock zero, printed by ``gimbal serve``; the lidar's stream time 0 is
the monotonic time its clock started, :attr:`sim.virtual_lidar.VirtualLivox.clock_zero_mono`; without ``--head-clock-zero``
it is estimated as the smallest ``read time − newest t_s`` seen, which is late by at most the
file's write-to-read delay), and interpolates pan (unwrapped) and tilt between lines.

Latency that implies: the source is called for points up to "now" (every 10 ms batch), so the
newest truth line is up to one truth period (20 ms) plus the batch period (10 ms) old.  Past the
newest line the pose is extrapolated with the line's own speeds (at most ``extrapolate_s`` = 0.1 s,
then held), so the pose error is ``|accel| × lag² / 2`` while the head ramps (40 deg/s² × 30 ms² / 2
≈ 0.02 deg for the PTS-303 pan) and ~0 at constant speed; a head that was killed holds its last pose.
A restarted head (file truncated, ``t_s`` starting again) is detected and followed afresh.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

from sim.livox_units import UNITS as PRESET_UNITS, unit_for_preset  # the Livox unit each preset serves as
from sim.sensor import SceneSensor, scene_scan_model
from sim.world import kernels as wk


#: How long the served IMU trails the points when the scene has an ``[imu]`` (:mod:`sim.head_imu`):
#: its finite differences need the head's pose 5 ms after each sample, and the truth file is up to a
#: period (20 ms) + a batch (10 ms) old.  This is the least lag: on a loaded machine the truth can be
#: later still, and the IMU then waits until the truth covers its samples (``imu_ready_ns``), rather
#: than differentiating a held or extrapolated pose (up to ``sim.virtual_lidar.IMU_MAX_WAIT_S``).
IMU_LAG_S = 0.25


class TruthTail:
    """The head pose from a ``gimbal serve --truth`` JSON-lines file that is still being written.

    path : the truth file (it may not exist yet: the pose is then the fallback)
    clock_zero : float or None, ``time.monotonic()`` at head time 0 (printed by ``gimbal serve``);
        None = estimate it (see module docstring)
    fallback : (pan_deg, tilt_deg) before any line has been read
    extrapolate_s : float >= 0 [s], how far past the newest line the pose is extrapolated
    keep_s : float > 0 [s], how much history is kept for interpolation
    """

    def __init__(self, path: str, clock_zero: float | None = None, fallback=(0.0, 0.0),
                 extrapolate_s: float = 0.1, keep_s: float = 3.0):
        self.path = path
        self.fixed_zero = clock_zero
        self.zero = clock_zero
        self.fallback = (float(fallback[0]), float(fallback[1]))
        self.extrapolate_s = extrapolate_s
        self.keep_s = keep_s
        self._fh = None
        self._ino = None
        self._pos = 0
        self._partial = b""
        self.rows = np.zeros((0, 5))  # t_s, pan_deg (unwrapped), tilt_deg, pan_speed, tilt_speed
        self.restarts = 0
        self.lines = 0
        self._denied_said = False

    def _reset(self) -> None:
        self.rows = np.zeros((0, 5))
        self._partial = b""
        self._pos = 0
        self.zero = self.fixed_zero

    def poll(self, now_mono: float) -> None:
        """Read the complete lines written since the last call (``now_mono``: time of this read)."""
        try:
            st = os.stat(self.path)
        except OSError:
            return
        if self._fh is None or st.st_ino != self._ino or st.st_size < self._pos:
            if self._fh is not None:
                self._fh.close()
                self.restarts += 1
                pan, tilt = self.pose_at_head_time(np.array([math.inf]))
                self.fallback = (float(pan[0]), float(tilt[0]))  # a dead head holds its last pose
            try:
                self._fh = open(self.path, "rb")
            except OSError as exc:
                self._fh = None
                if isinstance(exc, PermissionError) and not self._denied_said:
                    # a truth file another user wrote (its umask 077): said, not served past in silence
                    self._denied_said = True
                    print(f"lidar serve: WARNING: --head-truth {self.path}: cannot read it ({exc.strerror}); the "
                          "head stays at the scene's pan0/tilt0 until this user may read it", file=sys.stderr,
                          flush=True)
                return
            self._ino = st.st_ino
            self._reset()
        self._fh.seek(self._pos)
        data = self._fh.read()
        self._pos += len(data)
        if not data:
            return
        buf = self._partial + data
        *lines, self._partial = buf.split(b"\n")
        new = []
        for line in lines:
            try:
                r = json.loads(line)
                new.append((float(r["t_s"]), float(r["pan_deg"]), float(r["tilt_deg"]),
                            float(r.get("pan_speed_deg_s", 0.0)), float(r.get("tilt_speed_deg_s", 0.0))))
            except (ValueError, KeyError, TypeError):
                continue
        if not new:
            return
        arr = np.array(new)
        if self.rows.shape[0] and arr[0, 0] < self.rows[-1, 0] - 1e-9:   # t_s went back: a new head
            self.restarts += 1
            self._reset()
        self.lines += len(new)
        # unwrap pan continuing from the previous rows
        prev = self.rows[-1, 1] if self.rows.shape[0] else None
        pan = np.degrees(np.unwrap(np.radians(arr[:, 1])))
        if prev is not None:
            pan += 360.0 * np.round((prev - pan[0]) / 360.0)
        arr[:, 1] = pan
        self.rows = np.vstack([self.rows, arr])
        self.rows = self.rows[self.rows[:, 0] >= self.rows[-1, 0] - self.keep_s]
        if self.fixed_zero is None:
            est = now_mono - float(arr[-1, 0])
            self.zero = est if self.zero is None else min(self.zero, est)

    def pose_at_head_time(self, t_head_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(pan_deg wrapped to (-180, 180], tilt_deg) at head times ``t_head_s``."""
        t = np.asarray(t_head_s, float)
        R = self.rows
        if R.shape[0] == 0:
            return np.full(t.shape, self.fallback[0]), np.full(t.shape, self.fallback[1])
        pan = np.interp(t, R[:, 0], R[:, 1])
        tilt = np.interp(t, R[:, 0], R[:, 2])
        late = t > R[-1, 0]
        if late.any():
            dt = np.clip(t[late] - R[-1, 0], 0.0, self.extrapolate_s)
            pan[late] = R[-1, 1] + R[-1, 3] * dt
            tilt[late] = R[-1, 2] + R[-1, 4] * dt
        pan = (pan + 180.0) % 360.0 - 180.0
        pan[pan == -180.0] = 180.0
        return pan, tilt

    def pose_at_mono(self, mono: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.zero is None:
            return self.pose_at_head_time(np.full(np.shape(mono), -math.inf))
        return self.pose_at_head_time(np.asarray(mono) - self.zero)

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def warm_up_kernels(scene) -> None:
    """Compile (or load from numba's cache) every kernel of the scene's stream before going real
    time: on a fresh install the first chunk would otherwise take seconds.  A throwaway source, so
    the served one's random streams start untouched; and the target casts too, which 2 ms of stream
    may not reach (the first ray on the UAV then stalled the stream ~2 s, sent on in a burst)."""
    warm = SceneSource(scene)
    warm(0, 2_000_000)
    warm.sensor.warm_up(warm.scan.scan(0, 16))


class SceneSource:
    """The returns of a scene's lidar for stream-time intervals (``VirtualLivox`` source).

    scene : sim.scene.Scene
    pose : callable(t_s array) -> (pan_deg array, tilt_deg array), the head pose at point times;
        None = the scene's fixed start pose ``[gimbal] pan0_deg, tilt0_deg``
    """

    def __init__(self, scene, pose=None):
        self.scene = scene
        self.scan = scene_scan_model(scene)
        self.rate_hz = float(scene.optics.point_rate_hz)
        g = scene.gimbal
        self.pose = pose or (lambda t: (np.full(np.shape(t), g.pan0_deg), np.full(np.shape(t), g.tilt0_deg)))
        self.sensor = SceneSensor(scene)
        self.points_on_target = 0
        self.points_out = 0

    def __call__(self, t0_ns: int, t1_ns: int):
        k0 = int(math.ceil(t0_ns * self.rate_hz / 1e9 - 1e-6))
        k1 = int(math.ceil(t1_ns * self.rate_hz / 1e9 - 1e-6))
        chunk = self.scan.scan(max(k0, 0), max(0, k1 - max(k0, 0)))
        t_s = chunk.t_ns * 1e-9
        pan, tilt = self.pose(t_s)
        return self.returns(chunk, np.asarray(pan, float), np.asarray(tilt, float))

    def set_rain_fog_suppression(self, on: bool) -> None:
        """The unit's rain/fog suppression switched by the host (SDK lidar command 0x03): the
        scene's droplet returns (effect ``weather``) are dropped while it is on."""
        self.sensor.rain_fog_suppression = bool(on)

    def returns(self, chunk, pan_deg: np.ndarray, tilt_deg: np.ndarray):
        """Steps 3-5 of the closed loop for one scan chunk at the given per-point head pose
        (the ray casting and effects are :class:`sim.sensor.SceneSensor`'s, shared with the loop).

        Returns (xyz (n,3) [m] lidar frame, reflectivity (n,) u8, t_ns (n,) int64), time-ordered.
        """
        n = len(chunk)
        d_world = np.empty_like(chunk.direction)
        wk.rotate_pan_tilt_kernel(chunk.direction, np.radians(pan_deg), np.radians(tilt_deg), d_world)
        t0 = float(chunk.t_ns[0]) * 1e-9 if n else 0.0
        t1 = float(chunk.t_ns[-1]) * 1e-9 + 1e-9 if n else 0.0
        xyz, t_ns, refl_byte, on_target = self.sensor.returns(chunk, d_world, t0, t1)
        self.points_on_target += int(on_target.sum())
        self.points_out += int(t_ns.size)
        return xyz, refl_byte, t_ns


class _FollowingSource:
    """SceneSource whose pose comes from a :class:`TruthTail`, mapped from stream time to monotonic."""

    def __init__(self, scene, tail: TruthTail, time_scale: float):
        self.tail = tail
        self.time_scale = time_scale
        self.lidar = None  # the VirtualLivox streaming this (set by serve_scene): its clock is stream time's
        self.inner = SceneSource(scene, pose=self._pose)

    @property
    def mono0(self) -> float | None:
        """``time.monotonic()`` at stream time 0 (None until the lidar's clock starts)."""
        return None if self.lidar is None else self.lidar.clock_zero_mono

    def known_until_ns(self, ahead_s: float) -> float:
        """Stream time [ns] up to which the pose is interpolated from truth lines, not extrapolated,
        with ``ahead_s`` of it to spare (the served IMU's differences look that far ahead)."""
        R = self.tail.rows
        if R.shape[0] == 0 or self.tail.zero is None or self.mono0 is None:
            return -math.inf
        return ((R[-1, 0] + self.tail.zero - self.mono0) * self.time_scale - ahead_s) * 1e9

    def set_rain_fog_suppression(self, on: bool) -> None:
        self.inner.set_rain_fog_suppression(on)

    def _pose(self, t_s):
        mono0 = self.mono0 if self.mono0 is not None else 0.0
        return self.tail.pose_at_mono(mono0 + np.asarray(t_s) / self.time_scale)

    def __call__(self, t0_ns, t1_ns):
        self.tail.poll(time.monotonic())
        return self.inner(t0_ns, t1_ns)


class _SceneEnd:
    """The source, saying once (``status``) when the stream first passes the scene's ``duration_s``."""

    def __init__(self, source, duration_s: float, status):
        self.source = source
        self.duration_s = duration_s
        self.end_ns = duration_s * 1e9
        self.status = status
        self.passed = False

    def set_rain_fog_suppression(self, on: bool) -> None:
        self.source.set_rain_fog_suppression(on)

    def __call__(self, t0_ns, t1_ns):
        if not self.passed and t1_ns > self.end_ns:
            self.passed = True
            if self.status is not None:
                self.status(f"scene time {max(t0_ns * 1e-9, self.duration_s):.1f} s: past the scene's duration_s "
                            f"= {self.duration_s:g} s; serving on, the targets past their trajectories' end "
                            "(straight, circle and figure-eight flights fly on, waypoint and manual ones hover "
                            "where they end); restart the serve to see the scene again from its start")
        return self.source(t0_ns, t1_ns)


def serve_scene(scene, *, bind_ip="127.0.0.1", cmd_port=65000, broadcast_addr=("127.0.0.1", 55000),
                time_scale=1.0, loss_rate=0.0, seed=0, packet_type=None, head_truth=None,
                head_clock_zero=None, duration_s=None, ready=None, control_log=None, clock="sampling",
                status=None) -> dict:
    """Serve ``scene``'s lidar until SIGINT/SIGTERM or ``duration_s`` (wall seconds); returns the counters.

    ``ready(lidar)`` is called once the sockets are bound (the CLI prints ``READY ip port``).
    ``clock``: scene time 0 at the first start-sampling command ("sampling") or at the start ("start").
    ``status(line)``, if given, gets a line at every sampling start (the scene time it starts at) and
    one when the stream first passes the scene's ``duration_s``.
    """
    from foveatrack.errors import UserError
    from foveatrack.livox import protocol as P
    from sim.virtual_lidar import VirtualLivox, run_virtual_lidar

    unit = unit_for_preset(scene.optics.name)
    if packet_type is not None and unit.mode_of_data_type(packet_type) is None:
        types = sorted(set(t for t in unit.data_types.values() if t in P.POINT_DATA_TYPES))
        raise UserError(f"--packet-type {packet_type}: a {unit.model} sends data types {types}")
    if head_truth is not None and time_scale != 1.0:
        raise UserError("--head-truth follows a head served in real time; use --time-scale 1")
    tail = None
    if head_truth is not None:
        tail = TruthTail(head_truth, head_clock_zero, fallback=(scene.gimbal.pan0_deg, scene.gimbal.tilt0_deg))
        source = _FollowingSource(scene, tail, time_scale)
    else:
        source = SceneSource(scene)

    warm_up_kernels(scene)
    scene_s = float(scene.duration_s)
    clock_started = []

    def _sampling_start(t_ns: int, host) -> None:
        first = not clock_started
        clock_started.append(t_ns)
        if status is None:
            return
        t = t_ns * 1e-9
        where = (f"past the scene's end (duration_s = {scene_s:g} s)" if t >= scene_s
                 else f"of the scene's {scene_s:g} s")
        note = "; the scene's clock starts now" if first and clock == "sampling" else ""
        status(f"host {host[0]}:{host[1]} started sampling at scene time {t:.2f} s, {where}{note}")

    imu_kw = {}
    if scene.imu is not None and unit.has_imu:
        # the scene's IMU on the head, moving with the pose the points are cast at
        from sim.effects import effect_rng
        from sim.head_imu import HeadImu

        pose = source._pose if tail is not None else source.pose
        imu = HeadImu(pose, scene.imu.T_lidar_imu, scene.imu.noise, effect_rng(scene.seed, "imu"))
        imu_kw = {"imu_source": imu, "imu_lag_s": IMU_LAG_S}
        if tail is not None:
            imu_kw["imu_ready_ns"] = lambda: source.known_until_ns(imu.h_s)

    def _ready(lidar: VirtualLivox):
        if tail is not None:
            source.lidar = lidar  # the head's time is mapped through the lidar's clock zero
        if ready is not None:
            ready(lidar)

    counters = run_virtual_lidar(
        _SceneEnd(source, scene_s, status), duration_s=duration_s, ready=_ready, bind_ip=bind_ip,
        cmd_port=cmd_port, broadcast_addr=broadcast_addr, point_rate_hz=float(scene.optics.point_rate_hz),
        packet_type=packet_type, unit=unit, time_scale=time_scale, loss_rate=loss_rate, seed=seed,
        control_log=control_log, clock=clock, on_sampling_start=_sampling_start, **imu_kw)
    inner = source.inner if tail is not None else source
    counters["points_on_target"] = inner.points_on_target
    if tail is not None:
        counters["head_truth_lines"] = tail.lines
        counters["head_restarts"] = tail.restarts
        tail.close()
    return counters


__all__ = ["SceneSource", "TruthTail", "serve_scene", "PRESET_UNITS"]
