"""Axis 4 -- calibration time: dwell per speed byte against speed-table and reconstruction error.

The shape of paper Fig. 11(b) (calibration error vs accumulation time at each pose), for the head
instead of the IMU: the speed table is calibrated by tracking a room corner (paper Appendix D.4,
:class:`foveatrack.calibration.PriorAxisCalibrator`, the estimator ``foveatrack calibrate`` uses) in a simulated room, with the head driven through the
virtual UART by the calibrator (``ClosedLoop(controller=...)``), for several dwell times per leg
and two byte plans.  Then the table it produced drives the tracker's dead reckoning in
``fig12-tracking`` on the *same* head unit.

* calibration time = virtual seconds the procedure took (what it costs on the real head);
* speed-table error = relative error of the table against the unit's true curve
  (:func:`sim.loop.truth_speed_table`), rms over the bytes the plan measured (true speed > 0), and
  over all bytes 1-63 of both axes (bytes between the plan's knots are interpolated by the table);
* reconstruction error = angle between the reconstructed and the true optical axis (dead
  reckoning with the table vs the head's true pose) at every frame end of the fig12 run, and the
  world position error of the detections (``reconstruction_error_m``).

Reference points: ``nominal`` (no calibration: the linear nominal table, time 0) and ``truth`` (the
unit's own curve: an infinitely long calibration).

The study's room (the head pointed at one corner) is its own, so the axis is self-contained; the
procedure and its driver are the product's (``CalibrationDriver``).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, replace

import numpy as np

from foveatrack.calibration import DEFAULT_BYTES, CalibrationPlan, FeatureSpec, PriorAxisCalibrator
from foveatrack.calibration.drive import CalibrationDriver
from foveatrack.metrics import angle_between_deg
from foveatrack.reconstruction import rotation_matrix
from foveatrack.speed_table import TURBO
from sim.study.common import Timer, load_study_scene, run_loop, seeds_for, strip_private
from sim.study.stats import interval

PLANS = {
    "tiny": ((8, 32), (32, 63)),
    "sparse": ((2, 4, 8, 16, 32, 63), (4, 16, 32, 63)),
    "dense": (DEFAULT_BYTES + (TURBO,), DEFAULT_BYTES),
}
ROOM_SIZE_M = (10.0, 4.0, 3.0)        # centred on the head: walls at x = +-5, y = +-2, z = +-1.5
CORNER_M = (5.0, 2.0, 1.5)            # the front-left-ceiling corner
MAX_CAL_S = 3000.0                    # virtual-time guard against a procedure that never ends


def room_scene(unit_seed: int, seed: int):
    """A room with the head pointed at one corner (the calibration's feature), Mid-40, range noise
    and motor speed noise as in the tracking scenes."""
    from sim.scene import scene_from_mapping

    pan0 = math.degrees(math.atan2(CORNER_M[1], CORNER_M[0]))
    tilt0 = math.degrees(math.atan2(CORNER_M[2], math.hypot(CORNER_M[0], CORNER_M[1])))
    data = {
        "scene": {"name": "calibration-room", "duration_s": MAX_CAL_S, "seed": seed,
                  "effects": ["range_noise", "motor_speed_noise"]},
        "lidar": {"preset": "mid40"},
        "gimbal": {"unit_seed": unit_seed, "pan0_deg": pan0, "tilt0_deg": tilt0},
        "background": [{"type": "room", "size_m": list(ROOM_SIZE_M), "centre_m": [0.0, 0.0, 0.0],
                        "reflectivity": 0.5}],
    }
    return scene_from_mapping(data, "study calibration room"), pan0, tilt0


def calibrate(plan: CalibrationPlan, unit_seed: int, seed: int):
    """Run the procedure in the simulated room; (table, calibrator, loop, virtual seconds)."""
    from sim.loop import ClosedLoop

    scene, pan0, tilt0 = room_scene(unit_seed, seed)
    corner_lidar = rotation_matrix(pan0, tilt0).T @ np.asarray(CORNER_M)
    # The estimator `foveatrack calibrate` uses (mounting priors on the rotation axes).
    cal = PriorAxisCalibrator(plan, FeatureSpec(tuple(float(v) for v in corner_lidar)), seed=seed,
                              head=f"PTS-303H unit {unit_seed} (simulated)", date="virtual time (simulation)")
    loop = ClosedLoop(scene, controller=CalibrationDriver(cal))
    period = loop.tracker.config.period_s
    k = 0
    while not cal.done and (k + 1) * period <= MAX_CAL_S:
        loop.step(k * period, (k + 1) * period)
        k += 1
    table = cal.result() if cal.done else None
    return table, cal, loop, k * period


def table_errors(table, truth, plan_bytes: dict, moving_frac: float = 0.1) -> dict:
    """Errors of ``table`` against ``truth`` over bytes 1-63 of both axes.

    Relative errors [%] only over the bytes whose true speed is at least ``moving_frac`` of the
    axis's top speed (below that a relative error measures the edge of the dead zone, not the
    table); absolute errors [deg/s] over every byte.  Bytes between the plan's knots are
    interpolated by the table; bytes it cannot place (NaN) are counted in ``unknown_bytes``.
    """
    measured, every, unknown = [], [], 0
    absolute = {"pan": [], "tilt": []}
    for axis in ("pan", "tilt"):
        ta, tt = table.axis(axis), truth.axis(axis)
        top = tt.speed_deg_s(63)
        for b in range(1, 64):
            tv, v = tt.speed_deg_s(b), ta.speed_deg_s(b)
            if not math.isfinite(v):
                unknown += 1
                continue
            absolute[axis].append(v - tv)
            if tv >= moving_frac * top:
                rel = 100.0 * (v - tv) / tv
                every.append(rel)
                if b in plan_bytes[axis]:
                    measured.append(rel)
    r = lambda x: float(np.sqrt(np.mean(np.square(x)))) if len(x) else None  # noqa: E731
    return {"table_err_measured_pct": r(measured), "table_err_all_pct": r(every),
            "table_err_max_pct": float(np.max(np.abs(every))) if every else None,
            "table_abs_pan_deg_s": r(absolute["pan"]), "table_abs_tilt_deg_s": r(absolute["tilt"]),
            "unknown_bytes": unknown}


class PointingProbe:
    """Frame hook: angle between the reconstructed and the true optical axis at each frame end."""

    def __init__(self):
        self.t_s: list[float] = []
        self.err_deg: list[float] = []

    def __call__(self, frame, out, loop):
        t = frame.t_end_s
        hp, ht, _, _ = loop.tracker.recon.angles_at(t)
        pan, tilt = loop.head.angles_at(np.array([t]))
        a = rotation_matrix(hp, ht)[:, 0]
        b = rotation_matrix(float(pan[0]), float(tilt[0]))[:, 0]
        self.t_s.append(t)
        self.err_deg.append(float(angle_between_deg(a, b)[0]))


def tracking_check(table_spec: str, check_s: float, seed: int) -> dict:
    """fig12-tracking with the tracker's table = ``table_spec`` ('truth' | 'nominal' | a JSON path)."""
    scene = load_study_scene("fig12")
    scene = replace(scene, duration_s=check_s, seed=seed, gimbal=replace(scene.gimbal, speed_table=table_spec))
    probe = PointingProbe()
    m = strip_private(run_loop(scene, frame_hook=probe))
    e = np.array(probe.err_deg)
    m.update(pointing_rms_deg=float(np.sqrt(np.mean(e ** 2))), pointing_max_deg=float(e.max()),
             pointing_t_s=[round(x, 3) for x in probe.t_s], pointing_err_deg=[float(x) for x in e])
    return m


@dataclass(frozen=True)
class CalibrationTask:
    plan: str            # a key of PLANS, or "nominal" / "truth" (no calibration run)
    dwell_s: float
    seed: int
    unit_seed: int
    check_s: float
    tilt_prior: bool = True   # tell the calibrator the start tilt (CalibrationPlan.start_tilt_deg)

    axis = "calibration"

    @property
    def cost_hint(self) -> float:
        if self.plan in ("nominal", "truth"):
            return 0.1 * self.check_s
        n = sum(len(b) for b in PLANS[self.plan])
        return 0.1 * self.check_s + 0.12 * n * 2 * (min(self.dwell_s, 4.0) + 0.6)

    def run(self) -> dict:
        from sim.loop import truth_speed_table

        if self.plan in ("nominal", "truth"):
            m = tracking_check(self.plan, self.check_s, self.seed)
            m.update(cal_virtual_s=0.0 if self.plan == "nominal" else math.inf, cal_cpu_s=0.0)
            if self.plan == "nominal":
                from sim.loop import ClosedLoop, load_tracker_table

                scene, _, _ = room_scene(self.unit_seed, self.seed)
                head = ClosedLoop(scene).head
                m.update(table_errors(load_tracker_table("nominal", head, ""), truth_speed_table(head),
                                      {"pan": (), "tilt": ()}))
            return m
        pan_b, tilt_b = PLANS[self.plan]
        _, _, tilt0 = room_scene(self.unit_seed, self.seed)
        plan = CalibrationPlan(pan_bytes=pan_b, tilt_bytes=tilt_b, dwell_s=self.dwell_s,
                               settle_s=min(0.5, self.dwell_s / 2), rest_s=0.5,
                               start_tilt_deg=tilt0 if self.tilt_prior else 0.0)
        with Timer() as t:
            table, cal, loop, cal_s = calibrate(plan, self.unit_seed, self.seed)
        out = {"cal_virtual_s": cal_s, "cal_cpu_s": t.cpu_s, "cal_frames": cal.frames,
               "implied_start_tilt_deg": cal.report.implied_start_tilt_deg if cal.report else None,
               "cal_frames_with_feature": cal.frames_with_feature, "cal_done": cal.done}
        if table is None:
            out["failure"] = cal.failure or f"not done after {MAX_CAL_S} s"
            return out
        truth = truth_speed_table(loop.head)
        out.update(table_errors(table, truth, {"pan": pan_b, "tilt": tilt_b}))
        out.update(table_dead_time_s=table.dead_time_s, table_accel_deg_s2=table.accel_deg_s2,
                   true_dead_time_s=truth.dead_time_s, true_accel_pan_deg_s2=truth.pan.accel_deg_s2,
                   true_accel_tilt_deg_s2=truth.tilt.accel_deg_s2)
        out.update(self._check(table))
        # Diagnostic: the measured speeds with the head's true timing (dead time, per-axis
        # acceleration), to separate what the speed entries cost from what the timing costs.
        timed = replace(table, dead_time_s=truth.dead_time_s, accel_deg_s2=truth.accel_deg_s2,
                        pan=replace(table.pan, accel_deg_s2=truth.pan.accel_deg_s2),
                        tilt=replace(table.tilt, accel_deg_s2=truth.tilt.accel_deg_s2))
        out["pointing_rms_true_timing_deg"] = self._check(timed)["pointing_rms_deg"]
        return out

    def _check(self, table) -> dict:
        fd, path = tempfile.mkstemp(suffix=".json", prefix="study-table-")
        os.close(fd)
        try:
            table.save(path)
            return tracking_check(path, self.check_s, self.seed)
        finally:
            os.unlink(path)


UNIT_SEED = 3   # fig12-tracking's head unit: the table is checked on the unit it was measured on


def tasks(size) -> list[CalibrationTask]:
    fig12 = load_study_scene("fig12")
    assert fig12.gimbal.unit_seed == UNIT_SEED
    out = []
    for seed in seeds_for(fig12.seed, size.cal_seeds):
        for plan in size.cal_plans:
            for dwell in size.dwells_s:
                out.append(CalibrationTask(plan, float(dwell), seed, UNIT_SEED, size.cal_check_s))
        for ref in ("nominal", "truth"):
            out.append(CalibrationTask(ref, 0.0, seed, UNIT_SEED, size.cal_check_s))
        if size.name == "full":
            # the calibrator's fallback pan axis without the start-tilt prior (see the report)
            out.append(CalibrationTask(size.cal_plans[0], size.dwells_s[-2], seed, UNIT_SEED, size.cal_check_s,
                                       tilt_prior=False))
    return out


KEYS = ("cal_virtual_s", "cal_cpu_s", "table_err_measured_pct", "table_err_all_pct", "table_err_max_pct",
        "table_abs_pan_deg_s", "table_abs_tilt_deg_s", "implied_start_tilt_deg", "table_dead_time_s",
        "table_accel_deg_s2", "true_dead_time_s", "true_accel_pan_deg_s2", "true_accel_tilt_deg_s2",
        "pointing_rms_true_timing_deg",
        "pointing_rms_deg", "pointing_max_deg", "recon_rms_m", "error_rms_all_deg")


def collect(results) -> dict:
    groups: dict = {}
    for t, r in results:
        groups.setdefault((t.plan, t.dwell_s, t.tilt_prior), []).append((t, r))
    rows = []
    for (plan, dwell, prior), runs in groups.items():
        ok = [r for _, r in runs if "failure" not in r]
        row = {"plan": plan, "dwell_s": dwell, "tilt_prior": prior, "runs": len(runs), "failed": len(runs) - len(ok),
               "bytes": None if plan not in PLANS else [len(b) for b in PLANS[plan]]}
        row["ci"] = {}
        for k in KEYS:
            iv = interval([r.get(k) for r in ok])
            row[k] = None if iv is None else iv["mean"]
            row["ci"][k] = iv
        first = next((r for r in ok if "pointing_err_deg" in r), None)
        if first is not None:
            row["pointing_t_s"] = first["pointing_t_s"]
            row["pointing_err_deg"] = first["pointing_err_deg"]
        rows.append(row)
    order = {"nominal": 0, "tiny": 1, "sparse": 2, "dense": 3, "truth": 4}
    rows.sort(key=lambda r: (order.get(r["plan"], 9), not r["tilt_prior"], r["dwell_s"]))
    return {"rows": rows, "unit_seed": UNIT_SEED, "room_m": ROOM_SIZE_M, "corner_m": CORNER_M}


def pareto_points(axis_result: dict) -> list[dict]:
    """(cost = calibration time [virtual s], error = speed-table rms error over all bytes [%])."""
    pts = []
    for r in axis_result["rows"]:
        if r["plan"] == "truth" or not r["tilt_prior"] or r["table_err_all_pct"] is None or r["cal_virtual_s"] is None:
            continue
        label = "no calibration (nominal table)" if r["plan"] == "nominal" else f"{r['plan']} plan, dwell {r['dwell_s']:g} s"
        e = r["ci"].get("table_err_all_pct") or {}
        pts.append({"group": "speed table", "label": label, "cost": r["cal_virtual_s"], "error": r["table_err_all_pct"],
                    "error_lo": e.get("lo"), "error_hi": e.get("hi"),
                    "pointing_rms_deg": r["pointing_rms_deg"], "offered": True})
    return pts
