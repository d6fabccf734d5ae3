"""Trajectory reconstruction (paper Fig. 14c) with the table calibrated on a fresh unit.

A 60 s track (fig12-tracking's UAV, on the calibrated unit) is reconstructed by integrating the
table's speeds over the commands sent.  The world-position error is split per detection into

* the detection part: Algorithm 1's median of surface points placed with the TRUE head angles
  (the median lies on the near surface, and the head turns during the frame) -- present even with
  a perfect table;
* the head-angle part: the same detection placed with the reconstructed angles instead.

Errors are relative to the target's range.
"""

from dataclasses import replace

import numpy as np
import pytest

from calib_fixture import FRESH_UNIT, ROOT, fresh_unit_calibration
from foveatrack.reconstruction import rotation_matrix

pytestmark = pytest.mark.slow     # shares the ~30 s calibration; the three 60 s tracks take ~8 s


def track(table_path: str):
    from sim.loop import ClosedLoop
    from sim.scene import load_scene

    base = load_scene(ROOT / "scenes" / "fig12-tracking.toml")
    scene = replace(base, duration_s=60.0, gimbal=replace(base.gimbal, unit_seed=FRESH_UNIT, speed_table=table_path))
    rows = []

    def hook(frame, out, loop):
        if out.detection is None or out.world_xyz is None:
            return
        d = out.detection
        pan, tilt = loop.head.angles_at(np.array([d.t_s]))
        with_true_head = rotation_matrix(float(pan[0]), float(tilt[0])) @ d.xyz
        truth = loop.scene.targets[0].trajectory.position(np.array([d.t_s]))[0]
        r = np.linalg.norm(truth)
        rows.append((np.linalg.norm(out.world_xyz - truth) / r, np.linalg.norm(with_true_head - truth) / r,
                     np.linalg.norm(out.world_xyz - with_true_head) / r, r))

    log = ClosedLoop(scene, frame_hook=hook).run()
    R = np.array(rows)
    stats = lambda x: {"rms": float(np.sqrt(np.mean(x ** 2))), "p95": float(np.percentile(x, 95)),  # noqa: E731
                       "max": float(x.max())}
    drift = log["est_pan_deg"][-1] - log["head_pan_deg"][-1]
    return {"total": stats(R[:, 0]), "detection": stats(R[:, 1]), "head": stats(R[:, 2]),
            "range_m": (float(R[:, 3].min()), float(R[:, 3].max())), "detections": len(R), "pan_drift_end_deg": drift}


def test_world_error_of_a_60s_track_with_the_calibrated_table(tmp_path):
    run = fresh_unit_calibration()
    cal = tmp_path / "calibrated.json"
    run.table.save(cal)
    # the same measured speeds with the head timing as configured from the datasheet/truth model
    # (40 ms dead time, 40 / 10 deg/s^2) instead of as calibrated (see docs/tracker.md)
    t = run.table
    cfg = tmp_path / "calibrated-speeds-configured-timing.json"
    replace(t, pan=replace(t.pan, accel_deg_s2=40.0), tilt=replace(t.tilt, accel_deg_s2=10.0), dead_time_s=0.04).save(cfg)
    res = {"truth table": track("truth"), "calibrated": track(str(cal)), "calibrated speeds, configured timing": track(str(cfg))}
    print()
    for name, r in res.items():
        f = lambda s: f"rms {100 * s['rms']:.2f} p95 {100 * s['p95']:.2f} max {100 * s['max']:.2f} %"  # noqa: E731
        print(f"{name:38s} total {f(r['total'])} | detection {f(r['detection'])} | head {f(r['head'])}"
              f" | pan drift at 60 s {r['pan_drift_end_deg']:+.2f} deg; range {r['range_m'][0]:.0f}-{r['range_m'][1]:.0f} m")
    truth, calib, conf = res["truth table"], res["calibrated"], res["calibrated speeds, configured timing"]
    # the truth table integrates exactly: only the detection part remains
    assert truth["head"]["max"] < 1e-3
    # the detection part (Algorithm 1's median) alone: below 1 % of range on average, not at every frame
    assert truth["detection"]["rms"] < 0.01
    # calibrated speeds (+ configured timing): the head-angle part stays below 1 % of range over 60 s
    assert conf["head"]["max"] < 0.01 and conf["total"]["rms"] < 0.01
    # fully calibrated (speeds and timing): what holds today -- see the report / docs/tracker.md
    assert calib["total"]["rms"] < 0.025 and calib["head"]["max"] < 0.04
