"""The command gate's tilt stops during a calibration count from the start tilt the corner data show.

The calibration driver tells the gate the head's tilt as the start tilt plus the corner's turn about
the tilt axis.  The start tilt was always the config's ``tilt0_deg``: a wrong one moved the stops by
its error, even after the pan legs had shown it wrong (their chi-square test, which only warned at
the end).  Now, once the pan legs are over and contradict it, the gate counts from the start tilt
they imply, or, where their scatter cannot tell it (degenerate), refuses tilt (the tilt is unknown).

Simulated rig (sim.calibration_run's loop: the PTS-303H model behind the scene's [gate], with the
head's stops at -30 and 60 deg and the gate's 2 deg margin), one pan and one tilt byte:

* the calibration room, head at tilt 6.5 deg, told 40: the gate's estimate was 33.5 deg high;
* a tall room whose corner is 55 deg up, head at 48 deg, told 20: the tilt leg drove the head into
  its stop at 60 while the gate believed 32, and the run wrote a table.
"""

from dataclasses import replace

import numpy as np

from calib_fixture import ROOT
from foveatrack.errors import UserError

TALL_ROOM = """
[scene]
name = "tall-room"
description = "a room corner 55 deg up: the head starts 12 deg below its tilt stop"
duration_s = 120.0
seed = 7
effects = ["range_noise"]

[lidar]
preset = "mid40"

[gimbal]
unit_seed = 101
pan0_deg = 38.7
tilt0_deg = 48.0
speed_table = "nominal"

[tracker]
rate_hz = 20.0

[gate]

[[background]]
type = "room"
size_m = [4.0, 4.0, 6.0]
centre_m = [0.5, 0.0, 1.5]
reflectivity = 0.6
"""


def _calibrate(scene, told_tilt0_deg, dwell_s):
    """run_calibration's loop, recording per frame the head's true tilt and the gate's estimate:
    ``(calibrator, rows (t, true, estimate, sigma), the UserError or None)``."""
    from foveatrack.calibration import FeatureSpec, PriorAxisCalibrator
    from foveatrack.calibration.drive import CalibrationDriver
    from sim.calibration_run import default_plan, room_corner_in_view
    from sim.loop import ClosedLoop

    plan = default_plan(scene, start_tilt_deg=told_tilt0_deg, pan_bytes=(40,), tilt_bytes=(63,), dwell_s=dwell_s)
    cal = PriorAxisCalibrator(plan, FeatureSpec(tuple(float(v) for v in room_corner_in_view(scene)), radius_m=1.0))
    driver = CalibrationDriver(cal)
    loop = ClosedLoop(scene, controller=driver)
    period = loop.tracker.config.period_s
    rows, error = [], None
    try:
        for k in range(int(scene.duration_s / period)):
            _, out = loop.step(k * period, (k + 1) * period)
            _, tilt = loop.head.angles_at(np.array([(k + 1) * period]))
            rows.append(((k + 1) * period, float(tilt[0]), out.head_tilt_deg, out.head_sigma_tilt_deg))
            driver.refuse_limited(loop.last_limited, out)
            if driver.finished:
                break
    except UserError as e:
        error = e
    return cal, np.array(rows), error


def test_a_start_tilt_the_pan_legs_contradict_is_not_what_the_gate_counts_from():
    from sim.scene import GateSpec, load_scene

    scene = load_scene(ROOT / "scenes" / "calibration-room.toml")
    scene = replace(scene, gate=GateSpec())
    assert scene.gimbal.tilt0_deg == 6.5
    cal, rows, error = _calibrate(scene, 40.0, 3.0)
    assert error is None and cal.done and cal.failure is None
    assert any("start tilt disagrees" in w for w in cal.report.warnings), cal.report.warnings
    # from the first tilt leg on, the gate's estimate is the head's tilt (within 3 sigma)
    t_tilt = next(g.t_cmd_s for g in cal.legs if g.axis == "tilt")
    t, true, est, sigma = rows[rows[:, 0] >= t_tilt].T
    worst = np.argmax(np.abs(est - true) / sigma)
    assert np.all(np.abs(est - true) <= 3 * sigma), (true[worst], est[worst], sigma[worst])
    start, start_sigma, from_data = cal.start_tilt_deg()
    assert from_data and abs(start - 6.5) <= 3 * start_sigma, (start, start_sigma)


def test_a_head_near_its_stop_told_a_low_start_tilt_is_not_driven_into_it(tmp_path):
    from sim.scene import load_scene

    path = tmp_path / "tall-room.toml"
    path.write_text(TALL_ROOM)
    scene = load_scene(path)
    cal, rows, error = _calibrate(scene, 20.0, 8.0)
    print(f"\nhead's true tilt at most {rows[:, 1].max():.1f} deg; {error}")
    assert error is not None, "the tilt leg ran"
    assert "contradict tilt0_deg 20" in str(error) and "no table was written" in str(error), str(error)
    # the refusal of a start tilt the legs cannot tell gives its own advice, not the limits' (which told
    # the user to take a smaller max_excursion_deg right after the larger one this case needs)
    if "too short to tell the start tilt" in str(error):
        assert "smaller max_excursion_deg" not in str(error) and "past its limits" not in str(error), str(error)
    assert rows[:, 1].max() < 60.0 - 2.0, rows[:, 1].max()      # never past the gate's line
    assert not any(g.axis == "tilt" and g.t_stop_s is not None for g in cal.legs)


def test_a_right_start_tilt_is_the_one_the_gate_counts_from():
    from sim.scene import GateSpec, load_scene

    scene = replace(load_scene(ROOT / "scenes" / "calibration-room.toml"), gate=GateSpec())
    cal, rows, error = _calibrate(scene, 6.5, 3.0)
    assert error is None and cal.report.warnings == ()
    assert cal.start_tilt_deg() == (6.5, 0.5, False)
