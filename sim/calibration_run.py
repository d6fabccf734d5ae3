"""The speed-table calibration (paper Appendix D.4) run against the simulated head.

:class:`foveatrack.calibration.Calibrator` is a driver-agnostic state machine; here it drives the
closed loop's PTS-303H model through the virtual UART, by way of ``ClosedLoop(controller=...)``
(the tracker is bypassed: the calibration decides every command).  The driver adapter is
:class:`foveatrack.calibration.drive.CalibrationDriver`, the same one the live calibration on a real
lidar + head uses (:func:`foveatrack.calibration.live.calibrate_live`).

The room corner the calibration tracks is found from the scene's geometry
(:func:`room_corner_in_view`): on real hardware the user gives its approximate position instead.

Command timing: the Calibrator stamps a command with its frame's end; the loop writes it
``send_delay_s`` later and a Pelco-D frame takes :func:`gimbal.pelco.frame_time_s` on the wire.  Both are given
to the plan as ``latency_s``, so the dead time written into the table is the head's own (the
reconstruction adds the link latency itself, see :mod:`foveatrack.reconstruction`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from foveatrack.calibration import CalibrationPlan, CalibrationReport, FeatureSpec
from foveatrack.errors import UserError
from foveatrack.reconstruction import rotation_matrix
from foveatrack.speed_table import SpeedTable, axis_bytes
from gimbal.pelco import frame_time_s
from sim.scene import Scene


def link_latency_s(scene: Scene) -> float:
    """Frame end -> command bytes at the head: the loop's send delay plus a 7-byte Pelco-D frame."""
    return scene.gimbal.send_delay_s + frame_time_s("D", scene.gimbal.baud)


def room_corner_in_view(scene: Scene, margin_deg: float = 4.0) -> np.ndarray:
    """The inside corner of the scene's background nearest the optical axis at the start, in the
    lidar frame [m].

    Candidates: every triple of rectangles with mutually perpendicular normals whose planes meet in
    a point lying on all three rectangles (within 1 cm) with the head centre on the inner side of
    each (an *inside* corner, as seen from the lidar).  The one with the smallest off-axis angle
    inside the half-FoV minus ``margin_deg`` is returned.  UserError if there is none.
    """
    from sim.world.kernels import RECT
    from sim.scan.fov import field_of_view_deg

    prims = scene.background_prims
    rects = [p for p in prims if int(p[0]) == RECT]
    planes = []
    for p in rects:
        c, n, u = p[1:4], p[7:10], p[10:13]
        n = n / np.linalg.norm(n)
        v = np.cross(n, u)
        planes.append((c, n, u, v, p[4], p[5]))
    R = rotation_matrix(scene.gimbal.pan0_deg, scene.gimbal.tilt0_deg)
    h, vv = field_of_view_deg(scene.optics, model=scene.scan_model, samples=50_000)
    half = 0.5 * min(h, vv) - margin_deg
    best, best_ang = None, math.inf
    n_pl = len(planes)
    for i in range(n_pl):
        for j in range(i + 1, n_pl):
            for k in range(j + 1, n_pl):
                tri = (planes[i], planes[j], planes[k])
                N = np.array([t[1] for t in tri])
                if np.max(np.abs((N @ N.T)[np.triu_indices(3, 1)])) > 1e-6:
                    continue
                D = np.array([t[1] @ t[0] for t in tri])
                x = np.linalg.solve(N, D)
                ok = True
                for c, n, u, v, hu, hv in tri:
                    d = x - c
                    if abs(d @ u) > hu + 0.01 or abs(d @ v) > hv + 0.01 or (n @ (-c)) <= 0:
                        ok = False
                        break
                if not ok:
                    continue
                q = R.T @ x                       # world -> lidar (head centre = lidar origin)
                ang = math.degrees(math.atan2(math.hypot(q[1], q[2]), q[0]))
                if ang < half and ang < best_ang:
                    best, best_ang = q, ang
    if best is None:
        raise UserError(f"{scene.path}: no inside room corner within {half:.1f} deg of the optical axis "
                        f"at pan0 {scene.gimbal.pan0_deg} deg, tilt0 {scene.gimbal.tilt0_deg} deg; "
                        "the calibration needs a [[background]] room (or walls) with a corner in view")
    return best


def default_plan(scene: Scene, **overrides) -> CalibrationPlan:
    """The calibration plan for a scene: default bytes and timing, the start tilt as the pan-axis prior
    and the link latency (so the table's dead time is the head's own)."""
    kw = dict(start_tilt_deg=scene.gimbal.tilt0_deg, latency_s=link_latency_s(scene))
    kw.update(overrides)
    return CalibrationPlan(**kw)


@dataclass
class CalibrationRun:
    """A finished calibration in the simulator."""

    table: SpeedTable
    report: CalibrationReport
    truth: SpeedTable            # the simulated unit's true curve (sim.loop.truth_speed_table)
    comparison: list             # rows from compare_with_truth
    frames: int
    virtual_s: float
    wall_s: float
    head_end_deg: tuple          # true (pan, tilt) at the end
    head_start_deg: tuple


def compare_with_truth(table: SpeedTable, truth: SpeedTable, rel_tol: float = 0.02, n_sigma: float = 3.0
                       ) -> list[dict]:
    """Per measured entry: measured, sigma, true speed, error [%], and ``ok`` =
    ``|v - v_true| <= max(rel_tol * v_true, n_sigma * sigma)`` (for a true speed of 0:
    ``|v| <= n_sigma * sigma + 0.01``).  Unmeasured entries are not listed (see
    ``SpeedTable.unmeasured``)."""
    rows = []
    for axis in ("pan", "tilt"):
        ax, tr = table.axis(axis), truth.axis(axis)
        for b in axis_bytes(axis):
            if not ax.is_measured(b):
                continue
            v, s, tv = ax.speed_deg_s(b), ax.sigma_deg_s(b), tr.speed_deg_s(b)
            err = v - tv
            if tv > 0:
                ok = abs(err) <= max(rel_tol * tv, n_sigma * s)
            else:
                ok = abs(v) <= n_sigma * s + 0.01
            rows.append({"axis": axis, "byte": b, "measured_deg_s": v, "sigma_deg_s": s, "true_deg_s": tv,
                         "error_pct": 100.0 * err / tv if tv > 0 else None,
                         "error_sigmas": err / s if s > 0 else None, "ok": bool(ok)})
    return rows


def run_calibration(scene: Scene, plan: CalibrationPlan | None = None, feature: FeatureSpec | None = None, *,
                    unit_seed: int | None = None, seed: int = 0, date: str | None = None,
                    start_tilt_sigma_deg: float = 0.5, progress=None) -> CalibrationRun:
    """Calibrate the scene's simulated head: the Calibrator drives ``ClosedLoop(controller=...)`` until
    it is done, or the scene's ``duration_s`` (the virtual-time budget) runs out (UserError).

    unit_seed : overrides ``[gimbal] unit_seed`` (another simulated unit).
    feature : default: the corner from :func:`room_corner_in_view` with a 1 m search radius.
    start_tilt_sigma_deg : how well the start tilt is known (see ``PriorAxisCalibrator``).
    seed : the Calibrator's RANSAC seed.  ``progress(t_s, budget_s)`` is called every frame.
    """
    from foveatrack.calibration import PriorAxisCalibrator
    from foveatrack.calibration.drive import CalibrationDriver
    from sim.loop import ClosedLoop, truth_speed_table

    if unit_seed is not None:
        scene = replace(scene, gimbal=replace(scene.gimbal, unit_seed=unit_seed))
    if scene.gimbal.frozen:
        raise UserError(f"{scene.path}: [gimbal] frozen = true; a frozen head cannot be calibrated")
    plan = plan or default_plan(scene)
    feature = feature or FeatureSpec(tuple(float(v) for v in room_corner_in_view(scene)), radius_m=1.0)
    cal = PriorAxisCalibrator(plan, feature, seed=seed, date=date, start_tilt_sigma_deg=start_tilt_sigma_deg,
                     head=f"{scene.gimbal.family.upper()} unit {scene.gimbal.unit_seed} (simulated, {scene.name})")
    driver = CalibrationDriver(cal)
    loop = ClosedLoop(scene, controller=driver)
    period = loop.tracker.config.period_s
    n_max = int(round(scene.duration_s / period))
    t_wall = time.perf_counter()
    k = 0
    while not driver.finished and k < n_max:
        _, out = loop.step(k * period, (k + 1) * period)
        driver.refuse_limited(loop.last_limited, out)    # the scene's [gate] changed a command: an error
        k += 1
        if progress is not None:
            progress(k * period, scene.duration_s)
    wall = time.perf_counter() - t_wall
    if not driver.finished:
        raise UserError(f"{scene.path}: the calibration did not finish within duration_s = {scene.duration_s} s "
                        f"of virtual time ({len(cal.legs)} legs done); raise [scene] duration_s or shorten the plan")
    table = cal.result()
    truth = truth_speed_table(loop.head)
    t_end = k * period
    for j in range(k, k + 10):            # 1 s more: the final stop is delivered and the head is at rest
        loop.step(j * period, (j + 1) * period)
    pan, tilt = loop.head.angles_at(np.array([(k + 10) * period]))
    return CalibrationRun(table, cal.report, truth, compare_with_truth(table, truth), k, t_end, wall,
                          (float(pan[0]), float(tilt[0])), (scene.gimbal.pan0_deg, scene.gimbal.tilt0_deg))
