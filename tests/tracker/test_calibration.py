"""Calibration (App. D.4) against the kinematic TEST DOUBLE head and synthetic room-corner clouds."""

import math

import numpy as np
import pytest

from fakes import FakeHead, corner_frame, nonlinear_speed, world_to_lidar
from foveatrack.calibration import CalibrationPlan, Calibrator, FeatureSpec, find_corner
from foveatrack.errors import UserError
from foveatrack.frames import Frame
from foveatrack.speed_table import TURBO

# a room: interior x < 5, y < 2, z < 1.5 (front wall, left wall, ceiling); corner at (5, 2, 1.5)
CORNER = np.array([5.0, 2.0, 1.5])
NORMALS = ([-1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0])
PAN0 = math.degrees(math.atan2(2.0, 5.0))
TILT0 = math.degrees(math.atan2(1.5, math.hypot(5.0, 2.0)))   # 15.6 deg: pan axis not lidar Z


def test_find_corner_on_a_static_cloud():
    rng = np.random.default_rng(0)
    head = FakeHead(lambda b: 0.0, lambda b: 0.0, pan0=PAN0, tilt0=TILT0)
    xyz, t_ns = corner_frame(head, CORNER, NORMALS, 0.0, 0.1, rng)
    truth = world_to_lidar(CORNER, PAN0, TILT0)
    c, mask = find_corner(xyz, truth + [0.2, -0.1, 0.1], FeatureSpec(tuple(truth)), np.random.default_rng(1))
    assert np.linalg.norm(c - truth) < 0.01 and mask.sum() > 0.3 * len(xyz)   # faces are cut by the 0.6 m ball
    # two parallel walls are no corner
    flat = xyz.copy()
    flat[:, 0] = 5.0
    assert find_corner(flat, truth, FeatureSpec(tuple(truth)), np.random.default_rng(1)) is None


def drive(cal, head, rng, latency_s=0.01, max_frames=20000):
    k = 0
    while not cal.done and k < max_frames:
        t0, t1 = k * 0.1, (k + 1) * 0.1
        xyz, t_ns = corner_frame(head, CORNER, NORMALS, t0, t1, rng)
        cmd = cal.step(Frame(t0, t1, xyz, t_ns))
        if cmd is not None:
            head.command(t1 + latency_s, cmd)
        k += 1
    return k


@pytest.mark.slow
def test_recovers_a_nonlinear_table_within_2_percent_on_an_unseen_unit():
    pan_true = nonlinear_speed(30.0, power=1.7, dead_bytes=3, turbo=40.0)
    tilt_true = nonlinear_speed(12.0, power=1.4, dead_bytes=2)
    head = FakeHead(pan_true, tilt_true, dead_time_s=0.06, accel_deg_s2=120.0, pan0=PAN0, tilt0=TILT0)
    approx = world_to_lidar(CORNER, PAN0, TILT0) + [0.15, -0.1, 0.05]
    plan = CalibrationPlan(pan_bytes=(1, 6, 16, 32, 63, TURBO), tilt_bytes=(1, 8, 24, 63), dwell_s=4.0,
                           settle_s=0.5, rest_s=0.4, latency_s=0.01)
    cal = Calibrator(plan, FeatureSpec(tuple(approx)), seed=5)
    rng = np.random.default_rng(42)
    frames = drive(cal, head, rng)
    assert cal.done and frames < 20000
    table = cal.result()
    rep = cal.report
    for axis, truth, bytes_ in (("pan", pan_true, plan.pan_bytes), ("tilt", tilt_true, plan.tilt_bytes)):
        ax = table.axis(axis)
        for b in bytes_:
            v, s, tv = ax.speed_deg_s(b), ax.sigma_deg_s(b), truth(b)
            print(f"{axis} byte {b:3d}: true {tv:7.3f}  measured {v:7.3f} +- {s:.3f}  "
                  f"err {100 * (v - tv) / tv if tv else float('nan'):+.2f} %")
            if tv > 20.0 and not ax.is_measured(b):
                # > 20 deg/s crosses the 15 deg excursion in < 0.75 s, mostly dead time and ramp at
                # 10 Hz frames: too few steady frames, so it must be reported as unmeasured
                assert "too few steady frames" in rep.unmeasured[axis][b]
                continue
            if tv == 0.0:
                assert abs(v) < 3 * s + 0.01             # the dead zone is measured as ~0
            else:
                assert abs(v - tv) <= max(0.02 * tv, 3 * s), (axis, b)
                assert ax.is_measured(b)
        # bytes outside the plan are reported and interpolated (not claimed measured)
        assert 10 in rep.unmeasured[axis] and not ax.is_measured(10)
    # the pan axis was found in the lidar frame: it implies the start tilt
    print("implied start tilt", rep.implied_start_tilt_deg, "true", TILT0)
    assert rep.implied_start_tilt_deg == pytest.approx(TILT0, abs=1.5)
    # head timing: effective delays -> dead time ~ 0.06 s (after the 10 ms link latency)
    assert rep.dead_time_s == pytest.approx(0.06, abs=0.04)
    # and the head was brought back near where it started
    head.advance(frames * 0.1 + 1)
    assert abs(head.ang["pan"] - PAN0) < 1.0 and abs(head.ang["tilt"] - TILT0) < 1.0
    print(f"implied start tilt {rep.implied_start_tilt_deg:.2f} (true {TILT0:.2f}), dead time "
          f"{rep.dead_time_s:.3f} s, accel {rep.accel_deg_s2}, frames {frames}")


def test_missing_feature_is_a_clear_failure():
    head = FakeHead(lambda b: 1.0, lambda b: 1.0)
    cal = Calibrator(CalibrationPlan(pan_bytes=(10,), tilt_bytes=(10,)), FeatureSpec((0.0, 30.0, 0.0)))
    k = 0
    rng = np.random.default_rng(0)
    while not cal.done and k < 200:
        xyz, t_ns = corner_frame(head, CORNER, NORMALS, k * 0.1, (k + 1) * 0.1, rng)
        cal.step(Frame(k * 0.1, (k + 1) * 0.1, xyz, t_ns))
        k += 1
    assert cal.done
    with pytest.raises(UserError, match="corner was not found"):
        cal.result()
    with pytest.raises(UserError, match="bytes"):
        CalibrationPlan(tilt_bytes=(TURBO,))


def _arc_leg(direction, rate_deg_s, t_cmd, n, rng, q0, noise_m=(0.005, 0.004, 0.005)):
    """A steady tilt leg's corner samples: ``q0`` turned about lidar Y at ``direction * rate`` from
    ``t_cmd + 0.5`` s, 20 Hz, with about the corner noise seen on the live rig (per coordinate, m)."""
    from foveatrack.calibration.corner import _rotate_about
    from foveatrack.calibration.plan import LegRecord

    t = t_cmd + 0.5 + 0.05 * np.arange(n)
    ang = np.radians(direction * rate_deg_s * (t - t_cmd))
    q = _rotate_about(np.repeat(q0[None], n, axis=0), np.array([0.0, 1.0, 0.0]), ang)
    q += rng.normal(0, 1, (n, 3)) * noise_m
    return LegRecord("tilt", 63, direction, t_cmd, t_stop_s=t[-1], ref_q=q0.copy(), samples=list(zip(t, q)))


def test_a_wrong_corner_neither_turns_the_tilt_axis_nor_biases_the_speed():
    # Seen on the live rig and in simulation: one corner among ~90 found 0.19 m off (RANSAC took a
    # wrong plane; this offset is a live run's) made the tilt legs' scatter look like a curved arc:
    # the estimated tilt axis turned 22 deg from lidar Y, the tilt speed came out 2-4 % high.  Here,
    # without the outlier rejection, the axis turns 17 deg and the speed reads 1 % higher.
    from foveatrack.calibration import PriorAxisCalibrator

    q0 = np.array([5.9, 0.8, 0.84])
    v_true = 2.0773
    out = []
    for wrong in (False, True):
        rng = np.random.default_rng(1)
        cal = PriorAxisCalibrator(CalibrationPlan(pan_bytes=(40,), tilt_bytes=(63,)), FeatureSpec(tuple(q0)))
        cal.legs = [_arc_leg(+1, v_true, 0.0, 45, rng, q0), _arc_leg(-1, v_true, 4.0, 45, rng, q0)]
        if wrong:
            t, q = cal.legs[0].samples[33]
            cal.legs[0].samples[33] = (t, q + [-0.079, -0.162, -0.055])
        table, report = cal._estimate()
        out.append((np.asarray(report.axis_lidar["tilt"]), table.tilt.speed_deg_s(63), table.tilt.sigma_deg_s(63)))
    (axis0, v0, s0), (axis1, v1, s1) = out
    assert abs(v0 - v_true) <= 3 * s0 and s0 < 0.01 * v_true, (v0, s0)      # the clean legs: sigma 0.6 %
    assert math.degrees(math.acos(min(1.0, abs(axis1[1])))) < 1.0, axis1
    assert abs(v1 - v0) <= 0.25 * s0 and abs(s1 - s0) <= 0.25 * s0, (v1, s1, v0, s0)   # as if it were not there


def _calibrate_with(monkeypatch, tamper):
    """A pan and a tilt byte (4 and 2 deg/s) calibrated on 20 Hz frames, with ``tamper(cal, found)``
    in the corner finder's place (it gets the real result and returns what the procedure sees)."""
    import foveatrack.calibration.procedure as procedure

    head = FakeHead(lambda b: 4.0, lambda b: 2.0, dead_time_s=0.04, accel_deg_s2=40.0, pan0=PAN0, tilt0=TILT0)
    plan = CalibrationPlan(pan_bytes=(16,), tilt_bytes=(16,), dwell_s=2.0, latency_s=0.01)
    cal = Calibrator(plan, FeatureSpec(tuple(world_to_lidar(CORNER, PAN0, TILT0))), seed=2)
    real_find = procedure.find_corner
    monkeypatch.setattr(procedure, "find_corner", lambda *a: tamper(cal, real_find(*a)))
    rng = np.random.default_rng(7)
    k = 0
    while not cal.done and k < 1000:
        t0, t1 = k * 0.05, (k + 1) * 0.05
        xyz, t_ns = corner_frame(head, CORNER, NORMALS, t0, t1, rng)
        cmd = cal.step(Frame(t0, t1, xyz, t_ns))
        if cmd is not None:
            head.command(t1 + 0.01, cmd)
        k += 1
    assert cal.done
    out = next(leg for leg in cal.legs if leg.axis == "pan" and leg.direction > 0)
    return cal, out, plan


def _pan_out_leg(cal):
    leg = cal._leg
    return leg if cal._phase == "move" and leg.axis == "pan" and leg.direction > 0 else None


def test_one_wrong_corner_neither_ends_a_leg_nor_loses_the_corner(monkeypatch):
    # A wrong corner 0.25 m along the motion read as ~50 deg/s from the last two samples: the
    # excursion check's coasting distance ended the leg at once (or the next frames, de-rotated at
    # that rate, lost the corner three times running); the live test lost its pan entry that way.
    injected = []

    def tamper(cal, found):
        leg = _pan_out_leg(cal)
        if found is not None and not injected and leg is not None and len(leg.samples) == 20:
            step = leg.samples[-1][1] - leg.samples[-2][1]
            injected.append(True)
            return found[0] + 0.25 * step / np.linalg.norm(step), found[1]
        return found

    cal, out, plan = _calibrate_with(monkeypatch, tamper)
    assert injected
    assert out.t_stop_s - out.t_cmd_s >= plan.dwell_s - 0.05     # the leg ran its dwell
    v = cal.result().pan.speed_deg_s(16)
    assert abs(v - 4.0) <= 0.01 * 4.0, v


def test_a_corner_unseen_for_three_frames_as_a_leg_starts_does_not_end_it(monkeypatch):
    # The Mid-40's pattern now and then leaves one of the corner's planes thin for three 50 ms frames
    # running; right after the command (dead time, ramp) that ended the leg as "lost" after 0.2 s and
    # the byte came out unmeasured.
    first = []

    def hide_first_three(cal, found):
        if _pan_out_leg(cal) is None:
            return found
        first[:] = first or [cal.frames]
        return None if cal.frames - first[0] < 3 else found

    cal, out, plan = _calibrate_with(monkeypatch, hide_first_three)
    assert first and out.samples[0][0] - out.t_cmd_s > 0.15      # the first three frames saw nothing
    assert out.t_stop_s - out.t_cmd_s >= plan.dwell_s - 0.05
    v = cal.result().pan.speed_deg_s(16)
    assert abs(v - 4.0) <= 0.01 * 4.0, v


def test_a_corner_lost_for_three_frames_once_the_leg_has_settled_ends_it(monkeypatch):
    # the safety the loss rule is for: a feature gone from view stops the head's leg
    first = []

    def hide_from_one_second(cal, found):
        leg = _pan_out_leg(cal)
        if leg is None or not leg.samples or leg.samples[-1][0] - leg.t_cmd_s < 1.0:
            return found
        first[:] = first or [cal.frames]
        return None

    cal, out, plan = _calibrate_with(monkeypatch, hide_from_one_second)
    assert first and 1.0 < out.t_stop_s - out.t_cmd_s <= 1.0 + 4 * 0.05 + 1e-9
