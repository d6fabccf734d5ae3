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
6. the tracker gets the frame (points in the lidar frame) and returns a neutral command, which is
   encoded as Pelco-D and sent through the virtual UART (10 bits per byte at the scene's baud).

Everything is a function of the scene and its seed: the same scene gives the same run, to the bit.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from foveatrack.control import STOP
from foveatrack.frames import Frame
from foveatrack.reconstruction import rotation_matrix
from foveatrack.speed_table import TURBO, AxisTable, SpeedEntry, SpeedTable
from foveatrack.tracker import Tracker
from gimbal.pelco import encode_pan_tilt
from gimbal.pts303h import PTS303H, HeadParams
from sim import effects as fx
from sim.scan.kernels import RAY_OK
from sim.scan.model import ScanModel
from sim.scan.optics import SpeedNoise
from sim.scene import Scene
from sim.virtual_uart import VirtualUart
from sim.world import kernels as wk
from sim.world.trajectories import heading_rad


def truth_speed_table(head: PTS303H) -> SpeedTable:
    """The unit's true speed curve as a table: what a perfect calibration would produce."""
    def axis(name):
        bytes_ = list(range(64)) + ([TURBO] if name == "pan" else [])
        accel = head.params.pan_accel_deg_s2 if name == "pan" else head.params.tilt_accel_deg_s2
        return AxisTable(name, tuple(SpeedEntry(b, head.true_speed_deg_s(name, b), 0.0, True, note="truth")
                                     for b in bytes_), accel)
    return SpeedTable(axis("pan"), axis("tilt"), head=f"PTS-303H unit {head.unit_seed} (simulated)",
                      source="truth: the simulated unit's own curve", dead_time_s=head.params.dead_time_s)


def load_tracker_table(spec: str, head: PTS303H, where: str) -> SpeedTable:
    if spec == "truth":
        return truth_speed_table(head)
    if spec == "nominal":
        p = head.params
        return SpeedTable.nominal(p.pan_speed_max_deg_s, p.tilt_speed_max_deg_s, p.pan_turbo_deg_s)
    return SpeedTable.load(spec)


@dataclass(frozen=True)
class ExternalOutput:
    """What the loop logs for a frame driven by an external controller instead of the tracker."""

    command: object
    detection: object = None
    state: str = "external"
    head_pan_deg: float = math.nan
    head_tilt_deg: float = math.nan
    world_xyz: object = None
    world_sigma_m: float = math.nan


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
    est_pan_deg: list = field(default_factory=list)  # reconstruction
    est_tilt_deg: list = field(default_factory=list)
    command: list = field(default_factory=list)  # (pan_dir, pan_byte, tilt_dir, tilt_byte)
    target_range_m: list = field(default_factory=list)
    target_lateral_m: list = field(default_factory=list)  # y of the target (fig14a pass position)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.__dict__.items()}


class ClosedLoop:
    """One run of a scene.  ``frame_hook(frame, output, loop)`` sees every frame (recording).

    ``target_motion``: see ``__init__``.  ``head_grid_s``: the head pose is evaluated exactly on this time grid and interpolated to each
    point (see :func:`sim.world.kernels.rotate_pan_tilt_grid_kernel` for the error bound); 0 evaluates
    it exactly at every point (about 10x slower; the accuracy-vs-time study compares the two).
    """

    def __init__(self, scene: Scene, frame_hook=None, head_grid_s: float = 0.001, controller=None,
                 target_motion: str = "per_point"):
        if target_motion not in ("per_point", "per_frame"):
            raise ValueError(f"target_motion {target_motion!r}: 'per_point' or 'per_frame'")
        self.scene = scene
        self.head_grid_s = head_grid_s
        # "per_point": each point sees the target where it is at the point's own time (default);
        # "per_frame": the target is frozen at the frame's mid-time (the cheaper snapshot model the
        # accuracy-vs-time study compares against).
        self.target_motion = target_motion
        # Another driver of the head instead of the tracker (e.g. the calibration procedure):
        # controller(frame, send_t_s) -> HeadCommand or None (stop).
        self.controller = controller
        self.frame_hook = frame_hook
        seed = scene.seed
        g = scene.gimbal
        noise = None
        if scene.has("motor_speed_noise"):
            noise = SpeedNoise(sigma_frac=scene.param("speed_noise_frac"), segment_s=scene.param("speed_noise_segment_s"))
        self.scan = ScanModel(scene.optics, scene.scan_model, speed_noise=noise,
                              rng=fx.effect_rng(seed, "motor_speed_noise") if noise else None)
        params = HeadParams.for_family(g.family, **({} if scene.has("head_ripple") else {"ripple_rel": 0.0}))
        tilt0 = min(max(g.tilt0_deg, params.tilt_min_deg), params.tilt_max_deg)
        self.head = PTS303H(params, unit_seed=g.unit_seed, feedback=g.feedback, address=g.address,
                            pan0_deg=g.pan0_deg, tilt0_deg=tilt0)
        uart_fx = set()
        if scene.has("uart_bit_errors"):
            uart_fx.add("bit_errors")
        if scene.has("uart_drops"):
            uart_fx.add("drop")
        if scene.has("uart_echo"):
            uart_fx.add("echo")
        self.uart = VirtualUart(
            g.baud, uart_fx, rng=fx.effect_rng(seed, "uart") if uart_fx & {"bit_errors", "drop"} else None,
            bit_error_rate=scene.effect_params.get("uart_bit_error_rate", 0.0),
            drop_rate=scene.effect_params.get("uart_drop_rate", 0.0))
        table = load_tracker_table(g.speed_table, self.head, f"{scene.path} [gimbal] speed_table")
        cfg = replace(scene.tracker, pan0_deg=g.pan0_deg, tilt0_deg=tilt0,
                      tilt_limits_deg=(params.tilt_min_deg, params.tilt_max_deg),
                      latency_s=7 * 10 / g.baud, send_delay_s=g.send_delay_s)  # a 7-byte Pelco-D frame on the wire
        self.tracker = Tracker(cfg, table)
        self.rngs = {name: fx.effect_rng(seed, name) for name in
                     ("range_noise", "angular_noise", "return_probability", "sunlight", "dropouts")}
        self.draw_calls = {name: 0 for name in self.rngs}
        self._pending: list[tuple[float, bytes]] = []
        self._bg = scene.background_prims
        self._bg_refl = scene.background_reflectivity
        self.log = FrameLog()
        # Work counters (timing-free evidence that a scene costs only what it holds).
        self.rays_total = 0
        self.rays_cast_targets = 0
        self.rays_cast_background = 0
        self.bytes_sent = 0
        self.last_sent: tuple[float, bytes] | None = None  # (time, Pelco-D bytes) of this frame's command

    # ----------------------------------------------------------------------------------------------
    def run(self, progress=None) -> dict[str, np.ndarray]:
        period = self.tracker.config.period_s
        n_frames = int(round(self.scene.duration_s / period))
        for k in range(n_frames):
            self.step(k * period, (k + 1) * period)
            if progress is not None:
                progress(k + 1, n_frames)
        return self.log.arrays()

    def step(self, t0: float, t1: float):
        scene = self.scene
        # 1. bytes that have arrived by the end of this frame reach the head first.
        due = [(t, b) for t, b in self._pending if t < t1]
        self._pending = [(t, b) for t, b in self._pending if t >= t1]
        if due:
            self.head.receive(b"".join(b for _, b in due), [t for t, _ in due])
        # 2. the scan.
        chunk = self.scan.scan_time(t0, t1)
        n = len(chunk)
        t_s = chunk.t_ns * 1e-9
        ok = chunk.status == RAY_OK
        d_lidar = chunk.direction
        # 3. beams in the world at each point's own head pose.
        d_world = np.empty_like(d_lidar)
        if self.head_grid_s > 0:
            grid = np.arange(t0, t1 + 1.5 * self.head_grid_s, self.head_grid_s)
            pan, tilt = self.head.angles_at(grid)
            wk.rotate_pan_tilt_grid_kernel(d_lidar, t_s, t0, self.head_grid_s, np.unwrap(np.radians(pan)),
                                           np.radians(tilt), d_world)
        else:
            pan, tilt = self.head.angles_at(t_s)
            wk.rotate_pan_tilt_kernel(d_lidar, np.radians(pan), np.radians(tilt), d_world)
        # 4. ray casting: targets (culled) then background.
        rng_m = np.full(n, np.inf)
        prim = np.full(n, -1, dtype=np.int64)
        refl_of = []
        offset = 0
        target_prim_end = 0
        for spec in scene.targets:
            self._cast_target(spec, t0, t1, t_s, d_world, ok, rng_m, prim, offset)
            refl_of.append(spec.body.reflectivity)
            offset += spec.body.prims.shape[0]
        target_prim_end = offset
        self.rays_total += n
        if self._bg.shape[0]:
            self.rays_cast_background += n
            bg_prim = np.full(n, -1, dtype=np.int64)
            bg_rng = rng_m.copy()
            wk.cast_static_kernel(d_world, self._bg, bg_rng, bg_prim)
            nearer = bg_prim >= 0
            rng_m[nearer] = bg_rng[nearer]
            prim[nearer] = bg_prim[nearer] + offset
            refl_of.append(self._bg_refl)
        refl_table = np.concatenate(refl_of) if refl_of else np.zeros(0)
        hit = (prim >= 0) & ok
        idx = np.flatnonzero(hit)
        r = rng_m[idx]
        refl = refl_table[prim[idx]]
        d_pts = d_lidar[idx]
        on_target = prim[idx] < target_prim_end
        # 5. effects, each only if listed.
        keep = np.ones(idx.size, dtype=bool)
        if scene.has("return_probability"):
            self.draw_calls["return_probability"] += 1
            keep &= fx.keep_with_probability(self.rngs["return_probability"],
                                             fx.detection_probability(r, refl, scene.param("range_80pct_m")))
        if scene.has("dropouts"):
            self.draw_calls["dropouts"] += 1
            keep &= self.rngs["dropouts"].random(idx.size) >= scene.param("dropout_rate")
        if scene.has("range_noise"):
            self.draw_calls["range_noise"] += 1
            r = fx.range_noise(self.rngs["range_noise"], r, scene.param("range_noise_m"))
        if scene.has("angular_noise"):
            self.draw_calls["angular_noise"] += 1
            d_pts = fx.angular_noise(self.rngs["angular_noise"], d_pts, scene.param("angular_noise_deg"))
        xyz = d_pts * r[:, None]
        pt_ns = chunk.t_ns[idx]
        refl_byte = np.clip(np.round(refl * 100), 0, 255).astype(np.uint8)
        if scene.has("sunlight"):
            self.draw_calls["sunlight"] += 1
            xyz, pt_ns, refl_byte, keep, on_target = self._sunlight(chunk, ok, xyz, pt_ns, refl_byte, keep, on_target)
        xyz, pt_ns, refl_byte, on_target = xyz[keep], pt_ns[keep], refl_byte[keep], on_target[keep]
        order = np.argsort(pt_ns, kind="stable")
        frame = Frame(t0, t1, xyz[order], pt_ns[order], refl_byte[order])
        # 6. the tracker and the link.
        send_t = t1 + scene.gimbal.send_delay_s
        if self.controller is not None:
            cmd = self.controller(frame, send_t)
            out = ExternalOutput(STOP if cmd is None else cmd)
        else:
            out = self.tracker.process(frame, send_t_s=send_t)
        self.last_sent = None
        if scene.gimbal.frozen and self.controller is None:
            # The head is frozen (paper Fig. 13/14a): nothing is sent, and the tracker's dead reckoning
            # must know that its command never left.
            self.tracker.command_sent(send_t, STOP)
        if not scene.gimbal.frozen:
            c = out.command
            data = encode_pan_tilt(scene.gimbal.address, c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte)
            self._pending.extend(self.uart.send(data, send_t))
            self.bytes_sent += len(data)
            self.last_sent = (send_t, data)
        self._log(t0, t1, frame, int(on_target.sum()), out)
        if self.frame_hook is not None:
            self.frame_hook(frame, out, self)
        return frame, out

    # ----------------------------------------------------------------------------------------------
    def _cast_target(self, spec, t0, t1, t_s, d_world, ok, rng_m, prim, offset):
        traj = spec.trajectory
        t_mid = 0.5 * (t0 + t1)
        c = traj.position(np.array([t_mid]))[0]
        reach = spec.body.bounding_radius_m + traj.max_speed_m_s * 0.5 * (t1 - t0) * 1.01 + 1e-3
        # Beam divergence can catch a body just outside the central ray's path.
        if self.scene.has("beam_footprint"):
            reach += np.linalg.norm(c) * math.radians(max(self.scene.optics.beam_divergence_deg)) / 2
        cand = np.empty(t_s.size, dtype=np.bool_)
        wk.cone_candidates_kernel(d_world, c[0], c[1], c[2], reach, cand)
        cand &= ok
        idx = np.flatnonzero(cand)
        self.rays_cast_targets += idx.size
        if idx.size == 0:
            return
        t_pose = t_s[idx] if self.target_motion == "per_point" else np.full(idx.size, t_mid)
        pos = traj.position(t_pose)
        yaw = heading_rad(traj.velocity(t_pose))
        prims = spec.body.prims
        if not self.scene.has("beam_footprint"):
            wk.cast_moving_kernel(idx.astype(np.int64), d_world, pos, yaw, prims, offset, rng_m, prim)
            return
        # Beam footprint: sub-rays over the divergence ellipse; the return is the nearest sub-ray
        # range if at least half of the sub-rays hit (a partial hit on a thin arm may still return).
        offs = fx.footprint_offsets(self.scene.optics.beam_divergence_deg, self.scene.param("footprint_subrays"))
        d = d_world[idx]
        up = np.array([0.0, 0.0, 1.0])
        e_az = np.cross(up, d)
        e_az /= np.maximum(np.linalg.norm(e_az, axis=1, keepdims=True), 1e-12)
        e_el = np.cross(d, e_az)
        hits = np.zeros(idx.size, dtype=np.int64)
        best = np.full(idx.size, np.inf)
        best_prim = np.full(idx.size, -1, dtype=np.int64)
        local = np.arange(idx.size, dtype=np.int64)
        for a, b in offs:
            sub = d + a * e_az + b * e_el
            sub /= np.linalg.norm(sub, axis=1, keepdims=True)
            r = np.full(idx.size, np.inf)
            p = np.full(idx.size, -1, dtype=np.int64)
            wk.cast_moving_kernel(local, sub, pos, yaw, prims, offset, r, p)
            hits += p >= 0
            nearer = r < best
            best[nearer] = r[nearer]
            best_prim[nearer] = p[nearer]
        ret = hits * 2 >= len(offs)
        take = ret & (best < rng_m[idx])
        rng_m[idx[take]] = best[take]
        prim[idx[take]] = best_prim[take]

    def _sunlight(self, chunk, ok, xyz, pt_ns, refl_byte, keep, on_target):
        rng = self.rngs["sunlight"]
        n_false = rng.binomial(int(ok.sum()), self.scene.param("sunlight_rate"))
        if n_false == 0:
            return xyz, pt_ns, refl_byte, keep, on_target
        pick = rng.choice(np.flatnonzero(ok), n_false, replace=False)
        r = rng.uniform(0.5, self.scene.param("sunlight_max_range_m"), n_false)
        xyz = np.vstack([xyz, chunk.direction[pick] * r[:, None]])
        pt_ns = np.concatenate([pt_ns, chunk.t_ns[pick]])
        refl_byte = np.concatenate([refl_byte, np.full(n_false, 1, dtype=np.uint8)])
        keep = np.concatenate([keep, np.ones(n_false, dtype=bool)])
        on_target = np.concatenate([on_target, np.zeros(n_false, dtype=bool)])
        return xyz, pt_ns, refl_byte, keep, on_target

    def _log(self, t0, t1, frame, n_on_target, out):
        L = self.log
        t_mid = 0.5 * (t0 + t1)
        pan, tilt = self.head.angles_at(np.array([t_mid]))
        L.t_end_s.append(t1)
        L.points.append(frame.n_points)
        L.points_on_target.append(n_on_target)
        L.detected.append(out.detection is not None)
        L.state.append(out.state.value if hasattr(out.state, "value") else str(out.state))
        L.head_pan_deg.append(float(pan[0]))
        L.head_tilt_deg.append(float(tilt[0]))
        L.est_pan_deg.append(out.head_pan_deg)
        L.est_tilt_deg.append(out.head_tilt_deg)
        c = out.command
        L.command.append((c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte))
        if self.scene.targets:
            traj = self.scene.targets[0].trajectory
            p = traj.position(np.array([t_mid]))[0]
            R = rotation_matrix(float(pan[0]), float(tilt[0]))
            q = R.T @ p
            L.true_error_deg.append(math.degrees(math.atan2(math.hypot(q[1], q[2]), q[0])))
            L.true_az_deg.append(math.degrees(math.atan2(q[1], q[0])))
            L.true_el_deg.append(math.degrees(math.atan2(q[2], math.hypot(q[0], q[1]))))
            L.target_range_m.append(float(np.linalg.norm(p)))
            L.target_lateral_m.append(float(p[1]))
            t_det = out.detection.t_s if out.detection is not None else t_mid
            L.target_xyz.append(traj.position(np.array([t_det]))[0])
        else:
            for lst in (L.true_error_deg, L.true_az_deg, L.true_el_deg, L.target_range_m, L.target_lateral_m):
                lst.append(math.nan)
            L.target_xyz.append(np.full(3, np.nan))
        if out.world_xyz is not None:
            L.estimate_xyz.append(np.asarray(out.world_xyz, float))
            L.estimate_sigma_m.append(float(out.world_sigma_m))
        else:
            L.estimate_xyz.append(np.full(3, np.nan))
            L.estimate_sigma_m.append(math.nan)


def run_scene(scene: Scene, frame_hook=None, progress=None) -> tuple[dict[str, np.ndarray], ClosedLoop, float]:
    """Run a scene; returns the per-frame log, the loop object and the wall time [s]."""
    t = time.perf_counter()
    loop = ClosedLoop(scene, frame_hook)
    log = loop.run(progress)
    return log, loop, time.perf_counter() - t
