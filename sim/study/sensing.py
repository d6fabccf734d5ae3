"""Axis 3 -- sensing time: the accumulation window (25-400 ms) against detection, bearing and latency.

The tracker accumulates one frame per window (``TrackerConfig.rate_hz = 1 / window``) and runs
Algorithm 1 on it.  A longer window gathers more points on a small far target (paper Fig. 6: the
cloud fills in with accumulation time) but the bearing is older when the command leaves, and the
head (and target) move during the window.  Measured per window, in the closed loop, for:

* ``near``: ``fig12-tracking`` as shipped (a 0.35 m quadrotor at ~12 m entering 11 deg off-centre,
  paper Fig. 12);
* ``far``: ``far-target-range-limit`` (a 0.8 m UAV on a 140 m circle, near the 159 m range limit at
  30 % reflectivity), with the head pointed at the target's start so that the window, not the
  acquisition, is measured;
* ``mid``: the same scene scaled by 0.4 (circle radius 56 m about (0, 0, 0.8) m at 2 m/s: the same
  bearings and bearing rate), head pointed at the start likewise.  At 140 m the beam footprint
  (0.28 deg = 0.68 m) is nearly as wide as the body and few returns pass the half-of-the-sub-rays
  rule; 56 m shows how a window trades points for latency on a target with more points.

Definitions (per run; means over seeds in the report):

* detection probability = frames with a detection / frames whose true target direction (at the
  frame's mid-time) is inside the scanner's FoV;
* bearing error of a detection = angle between the detection's median point (lidar frame) and
  the true target centre in the lidar frame at the detection's timestamp, using the head's true
  pose at that time (so it contains the smear of head and target motion inside the window);
* control latency = time the command's last byte reaches the head - detection timestamp
  (send time + 7 bytes x 10 bits / baud - median point time): the age of the bearing when the
  head can act on it (the head's own dead time comes on top and does not depend on the window).

Plus coverage of the FoV against accumulation time (paper Fig. 6e; Appendix C voxel definition,
:func:`sim.scan.coverage.voxel_coverage`) for the Mid-40 and the Horizon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from foveatrack.metrics import angle_between_deg
from foveatrack.reconstruction import rotation_matrix
from gimbal.pelco import frame_time_s
from sim.study.common import Timer, load_study_scene, run_loop, seeds_for, strip_private, with_window
from sim.study.stats import interval

TARGETS = {"near": "fig12", "mid": "far", "far": "far"}


def target_scene(target: str):
    """The scene of a sensing target (see module docstring), at its shipped duration."""
    from sim.scene import TargetSpec
    from sim.world.trajectories import Circle

    scene = load_study_scene(TARGETS[target])
    if target == "near":
        return scene
    if target == "mid":
        tr = scene.targets[0].trajectory
        scale = 0.4
        scene = replace(scene, targets=(TargetSpec(scene.targets[0].body, Circle(
            tuple(float(c) * scale for c in tr.centre_m), tr.radius_m * scale, tr.speed_m_s * scale, tr.start_deg)),))
    p = scene.targets[0].trajectory.position(np.array([0.0]))[0]
    pan0 = math.degrees(math.atan2(p[1], p[0]))
    tilt0 = math.degrees(math.atan2(p[2], math.hypot(p[0], p[1])))
    return replace(scene, gimbal=replace(scene.gimbal, pan0_deg=pan0, tilt0_deg=tilt0))


class BearingProbe:
    """Frame hook recording, per frame, truth-in-FoV, detection, bearing error and latency."""

    def __init__(self, scene, half_fov_deg: float):
        self.scene = scene
        self.half_fov_deg = half_fov_deg
        self.in_fov: list[bool] = []
        self.detected: list[bool] = []
        self.bearing_err_deg: list[float] = []
        self.latency_s: list[float] = []
        self.points: list[int] = []
        self.wire_s = frame_time_s("D", scene.gimbal.baud)

    def true_lidar_xyz(self, loop, t_s: float) -> np.ndarray:
        """The target centre in the lidar frame at ``t_s`` (true head pose; lidar at the head origin)."""
        p = self.scene.targets[0].trajectory.position(np.array([t_s]))[0]
        pan, tilt = loop.head.angles_at(np.array([t_s]))
        return rotation_matrix(float(pan[0]), float(tilt[0])).T @ p

    def __call__(self, frame, out, loop):
        q = self.true_lidar_xyz(loop, frame.t_mid_s)
        off = math.degrees(math.atan2(math.hypot(q[1], q[2]), q[0]))
        self.in_fov.append(off < self.half_fov_deg)
        det = out.detection
        self.detected.append(det is not None)
        if det is None:
            return
        self.points.append(det.n_points)
        q_det = self.true_lidar_xyz(loop, det.t_s)
        self.bearing_err_deg.append(float(angle_between_deg(det.xyz, q_det)[0]))
        # the command leaves send_delay_s after the frame ends (ClosedLoop.step), even when the
        # head is frozen and nothing is sent
        self.latency_s.append(frame.t_end_s + self.scene.gimbal.send_delay_s + self.wire_s - det.t_s)

    def summary(self) -> dict:
        in_fov = np.array(self.in_fov, bool)
        det = np.array(self.detected, bool)
        be = np.array(self.bearing_err_deg)
        return {
            "frames": int(in_fov.size), "frames_in_fov": int(in_fov.sum()),
            "detections": int(det.sum()), "detections_in_fov": int((det & in_fov).sum()),
            "p_detect": float((det & in_fov).sum() / in_fov.sum()) if in_fov.any() else None,
            "bearing_rms_deg": float(np.sqrt(np.mean(be ** 2))) if be.size else None,
            "bearing_p95_deg": float(np.percentile(be, 95)) if be.size else None,
            "latency_mean_s": float(np.mean(self.latency_s)) if self.latency_s else None,
            "latency_max_s": float(np.max(self.latency_s)) if self.latency_s else None,
            "points_per_detection": float(np.mean(self.points)) if self.points else None,
        }


@dataclass(frozen=True)
class SensingTask:
    target: str        # "near" | "far"
    window_ms: float
    seed: int
    scene: object

    axis = "sensing"

    @property
    def cost_hint(self) -> float:
        return self.scene.duration_s * 0.1

    def run(self) -> dict:
        from sim.scan.fov import field_of_view_deg

        h, v = field_of_view_deg(self.scene.optics, model=self.scene.scan_model, samples=100_000)
        probe = BearingProbe(self.scene, 0.5 * min(h, v))
        m = strip_private(run_loop(self.scene, frame_hook=probe))
        m.update(probe.summary())
        return m


@dataclass(frozen=True)
class CoverageTask:
    optics_name: str
    duration_s: float
    reference_rays: int
    windows_ms: tuple = ()

    axis = "coverage"

    @property
    def cost_hint(self) -> float:
        return 2.0 + 5.0 * self.duration_s

    def run(self) -> dict:
        from sim.scan.coverage import voxel_coverage, voxel_grid
        from sim.scan.model import ScanModel
        from sim.scan.presets import PRESETS

        optics = PRESETS[self.optics_name]
        grid = voxel_grid(optics, reference_rays=self.reference_rays)
        with Timer() as t:
            curve = voxel_coverage(ScanModel(optics), self.duration_s, grid)
        # exactly at each window: a run of that length ends on it (the curve's samples need not)
        at = {str(int(w)): float(voxel_coverage(ScanModel(optics), w / 1000, grid).coverage[-1])
              for w in self.windows_ms}
        return {"optics": self.optics_name, "cells": curve.cells, "times_s": curve.times_s.tolist(),
                "coverage": curve.coverage.tolist(), "t50_s": curve.t50_s, "t90_s": curve.t90_s,
                "cpu_s": t.cpu_s, "at_windows": at}


def tasks(size) -> list:
    out = []
    for target in TARGETS:
        base = replace(target_scene(target), duration_s=size.sensing_duration_s[target])
        for seed in seeds_for(base.seed, size.sensing_seeds):
            for w in size.windows_ms:
                out.append(SensingTask(target, float(w), seed, with_window(replace(base, seed=seed), w)))
    for name in ("mid40", "horizon"):
        out.append(CoverageTask(name, size.coverage_s, size.coverage_rays, tuple(size.windows_ms)))
    return out


KEYS = ("p_detect", "bearing_rms_deg", "bearing_p95_deg", "latency_mean_s", "error_rms_all_deg",
        "error_rms_acq_deg", "points_per_detection", "cpu_per_virtual_s")


def collect(results, windows_ms) -> dict:
    rows = {}
    for target in TARGETS:
        tr = []
        for w in windows_ms:
            runs = [r for t, r in results if getattr(t, "axis", "") == "sensing" and t.target == target
                    and t.window_ms == float(w)]
            if not runs:
                continue
            row = {"window_ms": float(w), "seeds": len(runs),
                   "detections": int(sum(r["detections_in_fov"] for r in runs)),
                   "frames_in_fov": int(sum(r["frames_in_fov"] for r in runs)), "ci": {}}
            for k in KEYS:
                iv = interval([r.get(k) for r in runs])
                row[k] = None if iv is None else iv["mean"]
                row["ci"][k] = iv
            tr.append(row)
        scene = next((t.scene for t, _ in results if getattr(t, "axis", "") == "sensing" and t.target == target), None)
        rows[target] = {"scene": scene.name if scene else None, "rows": tr,
                        "duration_s": scene.duration_s if scene else None}
    cov = {}
    for t, r in results:
        if getattr(t, "axis", "") == "coverage":
            cov[t.optics_name] = r
    return {"targets": rows, "coverage": cov}


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = control latency [ms], error = tracking error rms over *all* frames [deg]) per target,
    each with its interval over seeds; detection probability kept.

    The end metric, not the bearing error: the bearing is measured on detected frames only, so a
    window that rarely detects (a far target at 25 ms) would look accurate by selection.
    """
    pts = []
    for target, res in axis_result["targets"].items():
        for r in res["rows"]:
            lat, e = r["ci"].get("latency_mean_s"), r["ci"].get("error_rms_all_deg")
            if lat is None or e is None:
                continue
            pts.append({"group": f"{target} ({res['scene']})", "label": f"{r['window_ms']:g} ms",
                        "cost": 1000 * lat["mean"], "cost_lo": 1000 * lat["lo"], "cost_hi": 1000 * lat["hi"],
                        "error": e["mean"], "error_lo": e["lo"], "error_hi": e["hi"],
                        "p_detect": r["p_detect"], "p_detect_ci": r["ci"].get("p_detect"), "offered": True})
    return pts
