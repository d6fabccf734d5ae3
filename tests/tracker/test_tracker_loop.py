"""Closed-loop tests of the Tracker against the kinematic TEST DOUBLE in fakes.py (not sim/)."""

import math

import numpy as np
import pytest

from fakes import FakeHead, target_frame, world_to_lidar
from foveatrack.detection import bearing_deg
from foveatrack.errors import UserError
from foveatrack.frames import Frame
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import Tracker, TrackerConfig, TrackState

TABLE = SpeedTable.nominal(pan_max_deg_s=30.0, tilt_max_deg_s=15.0, rel_sigma=0.01)  # "calibrated"


def run(cfg, target_fn, duration_s, *, present=lambda t: True, latency_s=0.00729, seed=0, pan0=0.0, tilt0=0.0):
    rng = np.random.default_rng(seed)
    head = FakeHead(TABLE.pan.speed_deg_s, TABLE.tilt.speed_deg_s, pan0=pan0, tilt0=tilt0,
                    tilt_limits=cfg.tilt_limits_deg)
    tr = Tracker(cfg, TABLE)
    rows = []
    for k in range(int(round(duration_s * cfg.rate_hz))):
        t0, t1 = k * cfg.period_s, (k + 1) * cfg.period_s
        if present(t0):
            xyz, t_ns = target_frame(head, target_fn, t0, t1, rng)
        else:
            xyz, t_ns = np.empty((0, 3)), np.empty(0, np.int64)
        out = tr.process(Frame(t0, t1, xyz, t_ns))
        head.command(t1 + latency_s, out.command)
        # truth: true bearing error of the target centre at frame end
        head.advance(t1)
        w = np.asarray(target_fn(t1))
        az, el = bearing_deg(*world_to_lidar(w, head.ang["pan"], head.ang["tilt"]))
        rows.append((t1, az, el, out, head.ang["pan"], head.ang["tilt"]))
    return rows


def orbit(omega_deg_s, r=30.0, el_deg=10.0, az0_deg=15.0):
    def f(t):
        a = math.radians(az0_deg + omega_deg_s * t)
        e = math.radians(el_deg)
        return np.array([r * math.cos(e) * math.cos(a), r * math.cos(e) * math.sin(a), r * math.sin(e)])
    return f


def test_acquires_and_holds_within_deadband_plus_lag_and_predictive_is_tighter():
    omega = 4.0
    errs = {}
    for ctrl in ("paper", "predictive"):
        cfg = TrackerConfig(controller=ctrl, tilt_limits_deg=(-30.0, 60.0))
        rows = run(cfg, orbit(omega), 30.0)
        after = [math.hypot(r[1], r[2]) for r in rows if r[0] > 8.0]
        errs[ctrl] = np.array(after)
        assert all(r[3].state == TrackState.TRACKING for r in rows)
    k, db, period = 2.0, 2.0, 0.1
    # bound: dead band + lag of the P loop at the target's rate (omega / k) + one frame of motion
    bound = db + omega / k + omega * period
    assert errs["paper"].max() < bound
    assert np.sqrt(np.mean(errs["predictive"] ** 2)) < 0.5 * np.sqrt(np.mean(errs["paper"] ** 2))
    print(f"paper rms {np.sqrt(np.mean(errs['paper'] ** 2)):.2f} max {errs['paper'].max():.2f}; "
          f"predictive rms {np.sqrt(np.mean(errs['predictive'] ** 2)):.2f} max {errs['predictive'].max():.2f}")


def test_target_behind_gets_acquired_turning_left():
    cfg = TrackerConfig()
    rows = run(cfg, lambda t: np.array([-20.0, 0.5, 0.0]), 20.0)
    assert rows[0][3].error_pan_deg > 170
    assert rows[0][3].command.pan_dir == +1        # behind, a little left: turn left at full speed
    assert rows[0][3].command.pan_byte == 63
    assert abs(rows[-1][1]) < 2.5 and rows[-1][3].state == TrackState.TRACKING


def test_lost_target_hold_then_search_then_wait():
    cfg = TrackerConfig(hold_s=1.0, search_timeout_s=3.0)
    rows = run(cfg, orbit(3.0), 12.0, present=lambda t: t < 5.0)
    states = [(round(r[0], 1), r[3].state) for r in rows]
    st = dict(states)
    assert st[5.5] == TrackState.HOLDING and rows[54][3].command.is_stop
    assert st[6.5] == TrackState.SEARCHING and rows[64][3].command.pan_dir == +1   # the way it went
    assert st[10.0] == TrackState.WAITING and rows[99][3].command.is_stop


def test_never_runs_into_the_tilt_stop_with_a_target_overhead():
    cfg = TrackerConfig(tilt_limits_deg=(-20.0, 45.0), tilt_margin_deg=3.0)
    # a target climbing straight overhead
    rows = run(cfg, lambda t: np.array([20.0 - 2.0 * t, 0.5, 5.0 + 1.0 * t]), 15.0)
    tilts = np.array([r[5] for r in rows])
    assert tilts.max() <= 45.0 - 3.0 + 0.5
    assert tilts.max() > 35.0           # it did follow the target up to near the margin
    assert any(r[3].stop_limited for r in rows)
    # the reconstructed tilt + 2 sigma never crossed the margin either
    assert max(r[3].head_tilt_deg + 2 * r[3].head_sigma_tilt_deg for r in rows) <= 42.0 + 0.5


def test_world_reconstruction_follows_the_target():
    cfg = TrackerConfig()
    f = orbit(3.0, r=40.0)
    rows = run(cfg, f, 20.0)
    errs = [np.linalg.norm(r[3].world_xyz - f(r[3].detection.t_s)) for r in rows if r[3].detection is not None]
    assert np.median(errs) < 0.3         # blob spread 0.1 m, perfect speed table


def test_config_from_mapping_errors_name_key_and_where():
    c = TrackerConfig.from_mapping({"deadband_deg": 1.5, "gain_1_s": 3, "controller": "predictive",
                                    "space": {"kind": "sector", "r_max_m": 200}}, where="s.toml [tracker]")
    assert c.deadband_pan_deg == c.deadband_tilt_deg == 1.5 and c.gain_tilt_1_s == 3.0
    with pytest.raises(UserError, match=r"s.toml \[tracker\].*unknown key.*'gain'.*allowed keys"):
        TrackerConfig.from_mapping({"gain": 2}, where="s.toml [tracker]")
    with pytest.raises(UserError, match="controller must be one of 'paper', 'predictive'"):
        TrackerConfig.from_mapping({"controller": "pid"}, where="w")
    with pytest.raises(UserError, match="rate_hz must be > 0"):
        TrackerConfig.from_mapping({"rate_hz": 0}, where="w")
    with pytest.raises(UserError, match="tilt_limits_deg"):
        TrackerConfig.from_mapping({"tilt_limits_deg": [50, 10]}, where="w")
    with pytest.raises(UserError, match=r"w.space"):
        TrackerConfig.from_mapping({"space": {"kind": "box"}}, where="w")
