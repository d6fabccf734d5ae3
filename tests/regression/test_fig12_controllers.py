"""fig12-tracking with the paper's controller (Algorithm 2) and the predictive one, side by side.

Scene: a 0.35 m quadrotor at 12 m crossing at 0.5 m/s (and 0.03 m/s up), head PTS-303H (pan
<= ~15 deg/s, accel 40 deg/s^2; tilt <= 2 deg/s, 10 deg/s^2; dead time 40 ms; gimbal/pts303h.py
HeadParams), 10 Hz frames, dead band 2 deg, gain 2 /s.

Bound for the paper controller, per axis, once both axes have reached their dead band
(acquisition + T_settle; T_settle = 1.5 s covers tilt's approach from the 4.3 deg start
elevation at 2 deg/s):

.. math:: |e| \\le e_{db} + \\omega\\,(T_f + T_d + T_{link} + T_{dead} + \\omega/a) + \\delta

* ``e_db`` = 2 deg: the head does not move until the error reaches it;
* the lag: the target keeps moving at its bearing rate ``omega`` while the crossing is seen (up to
  one frame, ``T_f`` = 0.1 s), reported (detection time = median point time, up to
  ``T_d`` = 0.05 s before the frame end), sent (2 ms + 7.3 ms for 7 bytes at 9600 baud), acted on
  (``T_dead`` = 40 ms) and until the head has ramped up to the target's rate (``omega / a``);
  pan: omega <= 0.5 / 12 rad/s = 2.39 deg/s -> 0.63 deg; tilt: omega <= 0.15 deg/s -> 0.04 deg;
* ``delta`` = 0.84 deg: Algorithm 1's median of surface points vs the body centre the truth uses
  (at most the 0.175 m half-span at 12 m).

Pan <= 3.47 deg, tilt <= 2.88 deg, the off-axis angle <= hypot = 4.51 deg.  (The commanded speed
``k e`` >= 4 deg/s always exceeds the target's rate, so the error does not grow past this.)

Predictive controller (constant-velocity filter on the bearing, rate fed forward, its own 0.3 deg
dead band on the corrective term): per axis ``0.3 + delta`` = 1.14 deg, off-axis <= 1.61 deg, once
the filter has converged (same T_settle).
"""

import math

import numpy as np


T_SETTLE_S = 1.5
DELTA = math.degrees(math.atan2(0.175, 12.0))
LAG = {"pan": 2.39 * (0.1 + 0.05 + 0.0093 + 0.04 + 2.39 / 40.0), "tilt": 0.15 * (0.1 + 0.05 + 0.0093 + 0.04 + 0.15 / 10.0)}
BOUND = {
    "paper": {"pan": 2.0 + LAG["pan"] + DELTA, "tilt": 2.0 + LAG["tilt"] + DELTA},
    "predictive": {"pan": 0.3 + DELTA, "tilt": 0.3 + DELTA},
}


def _run(scene_name):
    from sim.loop import ClosedLoop
    from sim.scene import load_scene
    from sim.summary import summarize

    from cases import ROOT

    scene = load_scene(ROOT / "scenes" / f"{scene_name}.toml")
    log = ClosedLoop(scene).run()
    return scene, log, summarize(scene, log, 1.0)


def test_paper_and_predictive_controllers_on_fig12():
    rows = {}
    for controller, scene_name in (("paper", "fig12-tracking"), ("predictive", "fig12-predictive")):
        scene, log, m = _run(scene_name)
        assert scene.tracker.controller == controller
        assert m["acquisition_s"] is not None
        t = log["t_end_s"]
        after = t >= t[0] + m["acquisition_s"] + T_SETTLE_S
        az, el, err = (np.abs(log[k][after]) for k in ("true_az_deg", "true_el_deg", "true_error_deg"))
        rows[controller] = (m, az.max(), el.max(), err)
    print("\ncontroller  acq [s]  rms    p95    max  (after acquisition, summarize)  | after +1.5 s: |pan| max  |tilt| max  max   bound")
    for c, (m, az, el, err) in rows.items():
        e = m["tracking_error_deg"]
        b = BOUND[c]
        print(f"{c:10s}  {m['acquisition_s']:6.1f}  {e['rms']:.2f}   {e['p95']:.2f}   {e['max']:.2f}"
              f"                                  | {az:.2f} (<= {b['pan']:.2f})  {el:.2f} (<= {b['tilt']:.2f})"
              f"  {err.max():.2f} (<= {math.hypot(b['pan'], b['tilt']):.2f})")
    for c, (m, az, el, err) in rows.items():
        b = BOUND[c]
        assert az <= b["pan"] and el <= b["tilt"], c
        assert err.max() <= math.hypot(b["pan"], b["tilt"]), c
    # the predictive controller holds the target nearer the fovea than Algorithm 2 does
    assert rows["predictive"][0]["tracking_error_deg"]["rms"] < 0.5 * rows["paper"][0]["tracking_error_deg"]["rms"]
