"""The closed loop in virtual time (DESIGN.md "How data flows"; paper Appendix D, Fig. 12-14).

Per frame ``[t0, t1)`` (100 ms at the tracker's 10 Hz):

1. command bytes that reached the head by now are delivered at their arrival times;
2. the scan model gives each point's time, channel and beam direction in the lidar frame;
3. the head's true pose *at each point's time* turns the beams into the world (the head moves
   during a frame and the cloud shows it);
4. rays are cast against the scene's targets (each at the point's own time) and background; a
   target is only traced for rays inside its bounding cone for this frame, so a one-UAV scene
   never traces the whole cloud;
5. the effects the scene lists act on the returns;
   (with ``[imu]``: the lidar's gyro samples up to the frame's end, from the head's true motion,
   go to the tracker first, :mod:`sim.head_imu`);
6. the tracker gets the frame (points in the lidar frame) and returns a neutral command, which is
   encoded as Pelco-D and sent through the virtual UART (10 bits per byte at the scene's baud).

Everything is a function of the scene and its seed: the same scene gives the same run, to the bit.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from foveatrack.control import STOP
from foveatrack.errors import UserError
from foveatrack.fixed_order import rows_T_times
from foveatrack.frame_step import FrameStep, NoHead
from foveatrack.frames import Frame
from foveatrack.gate import CommandGate, Limits
from foveatrack.reconstruction import rotation_rows
from foveatrack.speed_table import TURBO, AxisTable, SpeedEntry, SpeedTable
from foveatrack.startup_heap import freeze_startup_heap
from foveatrack.tracker import Tracker
from gimbal.head_facts import HeadFacts
from gimbal.pelco import encode_pan_tilt, wrap_pan_deg
from gimbal.pts303h import PTS303H, HeadParams
from sim import effects as fx
from sim.ahead import Ahead, ScanAhead
from sim.head_imu import HeadGyro
from sim.scene import Scene
from sim.sensor import SceneSensor, scene_scan_model
from sim.virtual_uart import VirtualUart
from sim.world import kernels as wk


def truth_speed_table(head: PTS303H, calibrated: bool = False) -> SpeedTable:
    """The unit's true speed curve as a table: what a perfect calibration would produce now, or with
    ``calibrated`` at the temperature the unit was calibrated at (without the thermal drift)."""
    speed = head.calibrated_speed_deg_s if calibrated else head.true_speed_deg_s

    def axis(name):
        bytes_ = list(range(64)) + ([TURBO] if name == "pan" else [])
        accel = head.params.pan_accel_deg_s2 if name == "pan" else head.params.tilt_accel_deg_s2
        return AxisTable(name, tuple(SpeedEntry(b, speed(name, b), 0.0, True, note="truth")
                                     for b in bytes_), accel)
    return SpeedTable(axis("pan"), axis("tilt"), head=f"PTS-303H unit {head.unit_seed} (simulated)",
                      source="truth: the simulated unit's own curve", dead_time_s=head.params.dead_time_s)


def load_tracker_table(spec: str, head: PTS303H, where: str) -> SpeedTable:
    if spec == "truth":   # calibrated before the run: a thermal drift since is not in it
        return truth_speed_table(head, calibrated=True)
    if spec == "nominal":
        p = head.params
        return SpeedTable.nominal(p.pan_speed_max_deg_s, p.tilt_speed_max_deg_s, p.pan_turbo_deg_s)
    try:
        return SpeedTable.load(spec)
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None


@dataclass
class FrameLog:
    """Per-frame record of a run (arrays are built by :meth:`ClosedLoop.run`)."""

    t_end_s: list = field(default_factory=list)
    points: list = field(default_factory=list)
    points_on_target: list = field(default_factory=list)
    detected: list = field(default_factory=list)
    state: list = field(default_factory=list)
    true_error_deg: list = field(default_factory=list)  # target off the lidar axis at frame mid
    true_az_deg: list = field(default_factory=list)
    true_el_deg: list = field(default_factory=list)
    target_xyz: list = field(default_factory=list)  # world, at the detection time (or frame mid)
    estimate_xyz: list = field(default_factory=list)  # tracker's world estimate (NaN if none)
    estimate_sigma_m: list = field(default_factory=list)
    head_pan_deg: list = field(default_factory=list)  # true, at frame mid
    head_tilt_deg: list = field(default_factory=list)
    est_pan_deg: list = field(default_factory=list)  # dead reckoning, at frame mid like the truth
    est_tilt_deg: list = field(default_factory=list)
    command: list = field(default_factory=list)  # (pan_dir, pan_byte, tilt_dir, tilt_byte)
    target_range_m: list = field(default_factory=list)
    target_lateral_m: list = field(default_factory=list)  # y of the target (fig14a pass position)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.__dict__.items()}


class _UartSink:
    """The simulator's command sink: Pelco-D bytes into the virtual UART (baud timing, link effects:
    a dropped byte is unknown to the sender, so every write "reached the head")."""

    def __init__(self, loop: "ClosedLoop"):
        self.loop = loop
        self.encoded: dict[tuple, bytes] = {}   # Pelco-D bytes per (pan_dir, pan_byte, tilt_dir, tilt_byte)
        self.spent_s = 0.0                      # wall time of the last send (the loop's "link" stage)

    def send(self, c, send_t_s: float, source: str) -> bool:
        c0 = time.perf_counter()
        loop = self.loop
        key = (c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte)
        data = self.encoded.get(key)
        if data is None:     # a run uses a few dozen distinct commands: encode each once
            data = self.encoded[key] = encode_pan_tilt(loop.scene.gimbal.address, *key)
        # the controller's time is the lidar's clock; the line runs on true time, later by the
        # host and link latency the host never sees
        wire_t_s = send_t_s if loop.clock is None else loop.clock.sensor_to_host(send_t_s)
        if loop.link_jitter_rng is not None:
            wire_t_s += fx.link_latency_draw(loop.link_jitter_rng, loop.scene.param("link_latency_jitter_s"))
        loop._pending.extend(loop.uart.send(data, wire_t_s))
        loop.bytes_sent += len(data)
        if "echo" in loop.uart.effects:
            # RS-485 echo: the host hears its own bytes.  The tracker reads no replies (the head
            # reports nothing), so here they are only counted; a reply parser must skip them.
            loop.echo_bytes += sum(len(b) for _, b in loop.uart.pop_echo())
        loop.last_sent = (send_t_s, data)
        self.spent_s = time.perf_counter() - c0
        return True


_NO_STRAYS = np.zeros((0, 3))      # a frame's stray returns where the scene lists none
_NO_STRAYS.flags.writeable = False
_NAN3 = np.full(3, np.nan)          # copied into the log where a frame has no position
_NAN3.flags.writeable = False

STAGES = ("head model: commands arrive", "scan", "beams into the world (head pose)", "ray casting + effects",
          "tracker", "link (Pelco-D, UART)", "log and recording")


class ClosedLoop:
    """One run of a scene.  ``frame_hook(frame, output, loop)`` sees every frame (recording).

    ``head_grid_s``: how each point gets the head's pose at its own time.  None (default): exactly,
    from the head's constant-acceleration pieces (:func:`sim.world.kernels.rotate_head_pieces_kernel`;
    when the scene lists the head's speed ripple, as for 0); 0: exactly, the head model asked about
    every point (the slow reference); > 0: interpolated from a grid of that step (see
    :func:`sim.world.kernels.rotate_pan_tilt_grid_kernel` for the error bound; the accuracy-vs-time
    study measures it).
    ``target_motion``: see :class:`sim.sensor.SceneSensor`.
    """

    _TRIG_NODE_S = 0.001   # trigonometry once per ms in the exact route (1.7e-3 rad steps at 100 deg/s)

    def __new__(cls, *args, **kwargs):
        # the imports out of the collector's walks (foveatrack.startup_heap), before this loop exists:
        # a frozen loop would hold its own cycles, and all it keeps, until the process ends
        freeze_startup_heap()
        return super().__new__(cls)

    def __init__(self, scene: Scene, frame_hook=None, head_grid_s: float | None = None, controller=None,
                 target_motion: str = "per_point"):
        self.scene = scene
        self.head_grid_s = head_grid_s
        self.sensor = SceneSensor(scene, target_motion)
        # What drives the head (foveatrack.controller.Controller): the tracker, or another controller
        # (the calibration procedure) in its place; the command gate and the link are the same.
        self.external_controller = controller
        self.frame_hook = frame_hook
        seed = scene.seed
        g = scene.gimbal
        self.scan = scene_scan_model(scene)
        self._scan_ahead: ScanAhead | None = None     # only while run() drives the frames
        self.worked_ahead = False                     # run(ahead=True) was used
        params = HeadParams.for_family(g.family, **({} if scene.has("head_ripple") else {"ripple_rel": 0.0}))
        tilt0 = min(max(g.tilt0_deg, params.tilt_min_deg), params.tilt_max_deg)
        head_fx = {}
        if scene.has("head_thermal_drift"):
            head_fx["speed_scale"] = fx.thermal_speed_scale(scene.param("head_speed_coeff_per_k"),
                                                            scene.param("head_delta_t_k"))
        if scene.has("head_dead_time_jitter"):
            head_fx["dead_time_jitter_s"] = scene.param("dead_time_jitter_s")
            head_fx["dead_time_rng"] = fx.effect_rng(seed, "head_dead_time_jitter")
        if scene.has("head_backlash"):
            head_fx["backlash_deg"] = scene.param("head_backlash_deg")
        if scene.has("head_wind"):
            head_fx["deflection"] = fx.WindOnHead(scene.param("wind_speed_m_s"), scene.param("wind_turbulence"),
                                                  scene.param("head_stiffness_nm_per_rad"),
                                                  fx.effect_rng(seed, "head_wind"))
        self.head = PTS303H(params, unit_seed=g.unit_seed, feedback=g.feedback, address=g.address,
                            pan0_deg=g.pan0_deg, tilt0_deg=tilt0, **head_fx)
        # the lidar's free-running clock (the tracker's time), and the host's latency to the line
        self.clock = fx.LidarClock(scene.param("lidar_clock_drift_ppm")) if scene.has("lidar_clock_drift") else None
        self.link_jitter_rng = fx.effect_rng(seed, "link_latency_jitter") if scene.has("link_latency_jitter") else None
        uart_fx = set()
        if scene.has("uart_bit_errors"):
            uart_fx.add("bit_errors")
        if scene.has("uart_drops"):
            uart_fx.add("drop")
        if scene.has("uart_echo"):
            uart_fx.add("echo")
        # each random link effect draws from its own stream, keyed by its scene name
        self.uart = VirtualUart(
            g.baud, uart_fx, rngs={e: fx.effect_rng(seed, name) for e, name in
                                   (("bit_errors", "uart_bit_errors"), ("drop", "uart_drops")) if e in uart_fx},
            bit_error_rate=scene.effect_params.get("uart_bit_error_rate", 0.0),
            drop_rate=scene.effect_params.get("uart_drop_rate", 0.0))
        table = load_tracker_table(g.speed_table, self.head, f"{scene.path} [gimbal] speed_table")
        # The head's facts (its stops, start pose, Pelco-D at the scene's baud, the loop's send delay)
        # win over [tracker] by the one rule every driver applies (TrackerConfig.with_head); the
        # recording keeps the configuration that results (sim.recorder.recording_meta).
        gate = {} if scene.gate is None else dict(
            max_pan_byte=scene.gate.max_pan_byte, max_tilt_byte=scene.gate.max_tilt_byte,
            allow_turbo=scene.gate.allow_turbo, tilt_margin_deg=scene.gate.tilt_margin_deg)
        self.head_facts = HeadFacts((params.tilt_min_deg, params.tilt_max_deg), g.pan0_deg, tilt0, "D", g.baud,
                                    g.send_delay_s, **gate)
        self.tracker = Tracker(scene.tracker.with_head(self.head_facts, scene.tracker_table, f"{scene.path} [tracker]"),
                               table)
        # [tracker.sky]: every object tracked, the fovea shared by saccades (foveatrack.sky.controller),
        # the head driven through the tracker above; its output per frame in sky_log
        self.sky = None
        self.sky_log: list = []
        if controller is None and "sky" in scene.tracker_table:
            from foveatrack.sky.controller import SkyController
            from sim.summary import half_fov_deg
            self.sky = SkyController.from_table(self.tracker, scene.tracker_table["sky"],
                                                f"{scene.path} [tracker.sky]", half_fov_deg(scene))
        # The lidar's gyro on the head, only when the scene has [imu] (its own random stream).
        if self.tracker.config.attitude == "gyro" and scene.imu is None:
            raise UserError(f"{scene.path} [tracker]: attitude = \"gyro\" needs an [imu] table "
                            "(the lidar's IMU on the head, whose gyro it integrates)")
        self.gyro = HeadGyro(scene.imu, seed, tilt0) if scene.imu is not None else None
        # The daemon's gate (limits, stale frames): pass-through unless the scene has a [gate] table.
        self.gate = CommandGate(None if scene.gate is None else Limits.of(self.head_facts))
        self.link = _UartSink(self)
        self.frame_step = FrameStep(controller if controller is not None else (self.sky or self.tracker), self.gate,
                                    NoHead() if g.frozen else self.link)
        self.last_command = STOP          # this frame's command as sent (after the gate)
        self.last_limited: list[str] = []  # why the gate changed it (empty: unchanged)
        self._pending: list[tuple[float, bytes]] = []
        self.log = FrameLog()
        # Multi-object scenes (Scene.multi_object): every object's truth per frame (sim.objects_truth), a
        # list of ObjectTruth per frame built when read (TruthLog); kept apart from the log, whose
        # arrays the regression and determinism digests cover.
        from sim.objects_truth import TruthLog

        self.objects_log = TruthLog(scene)
        self._last_objects: tuple[int, list] | None = None   # (frame count, its truth) of the last read
        self._strays_seen = 0
        self.bytes_sent = 0
        self.echo_bytes = 0
        self.last_sent: tuple[float, bytes] | None = None  # (time, Pelco-D bytes) of this frame's command
        self.imu_fed: tuple[np.ndarray, np.ndarray] | None = None   # (t_s, gyro) fed before this frame
        # Wall time per stage of :meth:`step` [s], summed over every step but the first (what a scene's
        # fidelity costs, reported by ``simulate --json``); the first step alone in ``first_step_s``: it
        # loads the numba kernels from their cache, or compiles them (about a minute) on a first run.
        self.stage_s: dict[str, float] = dict.fromkeys(STAGES, 0.0)
        self.steps_timed = 0
        self.first_step_s: float | None = None

    @property
    def controller(self):     # what drives the head: the tracker, or the controller given in its place
        return self.frame_step.controller

    @controller.setter
    def controller(self, c) -> None:
        self.frame_step.controller = c

    @property
    def last_objects(self) -> list | None:
        """The last frame's truth of every object (multi-object scenes; None before a frame): the last
        entry of :attr:`objects_log`, built once a frame when read (a recording reads it)."""
        n = len(self.objects_log)
        if n == 0:
            return None
        if self._last_objects is None or self._last_objects[0] != n:
            self._last_objects = (n, self.objects_log[n - 1])
        return self._last_objects[1]

    # Effect streams and work counters live in the sensor; these keep the loop's own view of them.
    @property
    def rngs(self):
        return self.sensor.rngs

    @property
    def draw_calls(self):
        return self.sensor.draw_calls

    @property
    def rays_total(self):
        return self.sensor.rays_total

    @property
    def rays_cast_targets(self):
        return self.sensor.rays_cast_targets

    @property
    def rays_cast_background(self):
        return self.sensor.rays_cast_background

    # ----------------------------------------------------------------------------------------------
    def run(self, progress=None, ahead: bool = False) -> dict[str, np.ndarray]:
        """Run the scene's frames; returns the per-frame log.

        ``ahead``: trace the scan of the coming frames and draw the effects' random values on a
        second thread while this one works (:mod:`sim.ahead`; same bits).  Worth it for one run on a
        machine with a free core (``simulate`` turns it on); not for many runs side by side (studies
        keep it off).
        """
        period = self.tracker.config.period_s
        n_frames = int(round(self.scene.duration_s / period))
        if self.sky is not None:
            # its kernels run first when its warm-up ends, ~10 frames in: compiled (or loaded) now, on
            # a throwaway controller, once per process (a fresh install's frame 11 waited ~8 s)
            from foveatrack.sky.controller import SkyController
            from foveatrack.sky.warm import compile_sky_kernels

            compile_sky_kernels(lambda: SkyController(self.tracker.rebased(0.0, 0.0, 0.0), self.sky.sky.cfg,
                                                      self.sky.attention.cfg), self.tracker.config.rate_hz)
        worker = None
        try:
            if ahead:       # inside the try: a Ctrl-C during the set-up still ends the worker
                self.worked_ahead = True
                worker = Ahead()
                self._scan_ahead = ScanAhead(self.scan, period, worker)
                self.sensor.draw_ahead(worker)
            for k in range(n_frames):
                self.step(k * period, (k + 1) * period)
                if progress is not None:
                    progress(k + 1, n_frames)
        finally:
            self._scan_ahead = None
            if worker is not None:
                worker.close()      # the streams drawn ahead go on synchronously if step() is called again
        return self.log.arrays()

    def step(self, t0: float, t1: float):
        scene = self.scene
        clock = time.perf_counter
        T = self.stage_s
        c0 = clock()
        # 1. bytes that have arrived by the end of this frame reach the head first.
        due = [(t, b) for t, b in self._pending if t < t1]
        self._pending = [(t, b) for t, b in self._pending if t >= t1]
        if due:
            self.head.receive(b"".join(b for _, b in due), [t for t, _ in due])
        c1 = clock()
        # 2. the scan.
        chunk = (self._scan_ahead or self.scan).scan_time(t0, t1)
        c2 = clock()
        d_lidar = chunk.direction
        # 3. beams in the world at each point's own head pose.
        d_world = np.empty_like(d_lidar)
        t_mid = 0.5 * (t0 + t1)
        # Grids run from t0 to exactly t1 (the step shrinks to divide the frame): the head is never
        # asked about a time past t1, which a command sent at t1 could still affect.
        pieces = self.head.pose_segments(t0, t1) if self.head_grid_s is None else None
        if pieces is not None:
            n_steps = max(1, math.ceil((t1 - t0) / self._TRIG_NODE_S - 1e-9))
            wk.rotate_head_pieces_kernel(d_lidar, chunk.t_ns, t0, (t1 - t0) / n_steps, n_steps + 1, pieces[0],
                                         pieces[1], d_world)
            pan = [wk.piece_angle_deg_kernel(pieces[0], t_mid)]    # the log's truth at mid-frame
            tilt = [wk.piece_angle_deg_kernel(pieces[1], t_mid)]
        elif self.head_grid_s:
            # The frame's mid-time rides along (the log's truth).  Pan unwrapped: continuous between nodes.
            n_steps = max(1, math.ceil((t1 - t0) / self.head_grid_s - 1e-9))
            step = (t1 - t0) / n_steps
            times = np.append(t0 + step * np.arange(n_steps + 1), t_mid)
            t_s = chunk.t_ns * 1e-9
            pan, tilt = self.head.angles_at(times, wrap_pan=False)
            rad = np.radians(np.stack([pan[:-1], tilt[:-1]]))
            wk.rotate_pan_tilt_grid_kernel(d_lidar, t_s, t0, step, rad[0], rad[1], d_world)
        else:
            pan, tilt = self.head.angles_at(np.append(chunk.t_ns * 1e-9, t_mid), wrap_pan=False)
            wk.rotate_pan_tilt_kernel(d_lidar, np.radians(pan[:-1]), np.radians(tilt[:-1]), d_world)
        mid_pose_deg = (float(wrap_pan_deg(pan[-1])), float(tilt[-1]))   # the log's truth
        c3 = clock()
        # 4-5. ray casting and the effects the scene lists.
        xyz, pt_ns, refl_byte, on_target = self.sensor.returns(chunk, d_world, t0, t1)
        lidar_clock = self.clock
        if lidar_clock is None:
            frame = Frame(t0, t1, xyz, pt_ns, refl_byte)
        else:   # the lidar stamps its points by its own clock; the host's offset follows the packets
            frame = Frame(lidar_clock.sensor_s(t0), lidar_clock.sensor_s(t1), xyz, lidar_clock.sensor_ns(pt_ns),
                          refl_byte)
            lidar_clock.observe(t1, lidar_clock.sensor_s(t1))
        if scene.multi_object:     # kept for the truth, built when read (sim.objects_truth.TruthLog)
            strays = self.sensor.last_strays_m if scene.has("stray_returns") else _NO_STRAYS
            self.objects_log.append(t_mid, self.sensor.last_object_rays, strays, self._strays_seen,
                                    self.sensor.last_mid_xyz_m, self.sensor.last_mid_velocity)
            self._strays_seen += len(strays)
        c4 = clock()
        # 6. the one step (foveatrack.frame_step): the gyro's samples, the controller, the gate, the link.
        self.imu_fed = None
        imu = None
        if self.gyro is not None:
            t_imu, gyro = self.gyro.samples_until(self.head, t1)
            if lidar_clock is not None:    # the lidar's IMU is stamped by the same clock
                t_imu = np.asarray(t_imu) * (1.0 + lidar_clock.drift_ppm * 1e-6)
            if hasattr(self.controller, "on_imu"):
                imu = [(t_imu, gyro)]
                self.imu_fed = (t_imu, gyro)    # recorded with the frame (sim.recorder)
        send_t = t1 + scene.gimbal.send_delay_s
        self.last_sent = None
        self.link.spent_s = 0.0
        stale_s = None if scene.gate is None else scene.gate.stale_frame_s
        # The frozen head (paper Fig. 13/14a) gets nothing: its sink fails every write, so the
        # controller (the tracker's dead reckoning) is told its command never left.
        stale = stale_s is not None and send_t - t1 > stale_s
        send_t_tracker = send_t if lidar_clock is None else lidar_clock.host_to_sensor(send_t)
        rec = self.frame_step(frame, send_t_tracker, imu=imu, stale=stale)
        out = rec.output
        self.last_limited = list(rec.limited)
        if not scene.gimbal.frozen:
            self.last_command = rec.command
        c5 = clock() - self.link.spent_s      # the link's time is its own stage
        c6 = clock()
        self._log(t0, t1, frame, int(np.count_nonzero(on_target)), out, mid_pose_deg)
        if self.sky is not None:
            self.sky_log.append(out)
        if self.frame_hook is not None:
            self.frame_hook(frame, out, self)
        c7 = clock()
        if self.first_step_s is None:
            self.first_step_s = c7 - c0
        else:
            for name, a, b in zip(STAGES, (c0, c1, c2, c3, c4, c5, c6), (c1, c2, c3, c4, c5, c6, c7)):
                T[name] += b - a
            self.steps_timed += 1
        return frame, out

    # ----------------------------------------------------------------------------------------------
    def _log(self, t0, t1, frame, n_on_target, out, mid_pose_deg):
        """Append a frame; ``mid_pose_deg``: the head's true (pan, tilt) at mid-frame (from step 3)."""
        L = self.log
        t_mid = 0.5 * (t0 + t1)
        pan, tilt = mid_pose_deg
        L.t_end_s.append(t1)
        L.points.append(frame.n_points)
        L.points_on_target.append(n_on_target)
        L.detected.append(out.detection is not None)
        L.state.append(out.state.value if hasattr(out.state, "value") else str(out.state))
        L.head_pan_deg.append(pan)
        L.head_tilt_deg.append(tilt)
        # The tracker's dead reckoning at the same instant as the truth above (frame mid).
        if self.external_controller is None:
            t_est = t_mid if self.clock is None else self.clock.sensor_s(t_mid)   # the tracker's clock
            est_pan, est_tilt = self.tracker.recon.angles_at(t_est)[:2]
        else:
            est_pan, est_tilt = math.nan, math.nan
        L.est_pan_deg.append(est_pan)
        L.est_tilt_deg.append(est_tilt)
        c = out.command if self.scene.gimbal.frozen else self.last_command   # as sent, after the gate
        L.command.append((c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte))
        if self.scene.targets:
            traj = self.scene.targets[0].trajectory
            p = self.sensor.last_mid_xyz_m[0]   # its position at t_mid, as this frame's cull evaluated it
            x, y, z = p
            # R.T @ p in a fixed order (BLAS's differs per CPU), on the rotation's rows as floats
            q0, q1, q2 = rows_T_times(rotation_rows(pan, tilt), x, y, z)
            L.true_error_deg.append(math.degrees(math.atan2(math.hypot(q1, q2), q0)))
            L.true_az_deg.append(math.degrees(math.atan2(q1, q0)))
            L.true_el_deg.append(math.degrees(math.atan2(q2, math.hypot(q0, q1))))
            L.target_range_m.append(math.sqrt(x * x + y * y + z * z))    # fixed_order.norm3
            L.target_lateral_m.append(float(y))
            if out.detection is None:   # at t_mid: the position the cull evaluated (the path's own call's bits)
                L.target_xyz.append(np.array(p))
            else:
                L.target_xyz.append(traj.position(np.array([out.detection.t_s]))[0])
        else:
            for lst in (L.true_error_deg, L.true_az_deg, L.true_el_deg, L.target_range_m, L.target_lateral_m):
                lst.append(math.nan)
            L.target_xyz.append(_NAN3.copy())
        if out.world_xyz is not None:
            L.estimate_xyz.append(np.asarray(out.world_xyz, float))
            L.estimate_sigma_m.append(float(out.world_sigma_m))
        else:
            L.estimate_xyz.append(_NAN3.copy())
            L.estimate_sigma_m.append(math.nan)


def run_scene(scene: Scene, frame_hook=None, progress=None,
              ahead: bool = False) -> tuple[dict[str, np.ndarray], ClosedLoop, float]:
    """Run a scene; returns the per-frame log, the loop object and the wall time [s]."""
    t = time.perf_counter()
    loop = ClosedLoop(scene, frame_hook)
    log = loop.run(progress, ahead=ahead)
    return log, loop, time.perf_counter() - t
