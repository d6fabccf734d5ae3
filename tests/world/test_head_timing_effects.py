"""The head and timing effects a scene can list (sim.effects, "Head and timing"): their scene keys, how
the closed loop applies them, and their physics with a bound.

* thermal drift: the head runs its curve times ``1 + coeff * dT``; the tracker keeps the calibrated one;
* link latency jitter: each command reaches the line later than the host's stamp by exactly its own
  stream's exponential draws;
* lidar clock drift: the sensor's time is ``t (1 + ppm 1e-6)`` to 1 ns, and the clock guard
  (foveatrack.sensor_time) reads such a clock as one stream: no clock jump, nothing dropped;
* backlash: the dead reckoning is off by half the play once the head has moved (mid-play at start);
* wind: a steady wind deflects the head by exactly its torque over the stiffness; gusts have the
  stated rms and the rates are the deflection's derivative.
"""

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from foveatrack.errors import UserError
from foveatrack.sensor_time import SensorTimeGuard
from sim import effects as fx
from sim.loop import ClosedLoop
from sim.scene import EFFECT_DEFAULTS, scene_from_mapping
from sim.virtual_uart import VirtualUart

SCENES = Path(__file__).resolve().parents[2] / "scenes"
NEW = ("head_thermal_drift", "head_dead_time_jitter", "link_latency_jitter", "lidar_clock_drift", "head_backlash",
       "head_wind")


def fig12(effects, params=None, seconds=1.0):
    data = tomllib.loads((SCENES / "fig12-tracking.toml").read_text())
    data["scene"]["effects"] = list(effects)
    data["effects"] = dict(params or {})
    return replace(scene_from_mapping(data, "fig12"), duration_s=seconds)


def test_each_new_effect_is_registered_with_its_defaults():
    for e in NEW:
        assert e in EFFECT_DEFAULTS
        sc = fig12([e])
        assert all(sc.param(k) == v for k, v in EFFECT_DEFAULTS[e].items())


@pytest.mark.parametrize("key, value, match", [
    ("lidar_clock_drift_ppm", 500.0, "lidar_clock_drift_ppm must be <= 150"),
    ("lidar_clock_drift_ppm", -151, "lidar_clock_drift_ppm must be >= -150"),
    ("head_speed_coeff_per_k", 0.009, "more than halve"),
    ("dead_time_jitter_s", -0.01, "dead_time_jitter_s must be >= 0"),
    ("head_backlash_deg", 7.0, "head_backlash_deg must be <= 5"),
    ("wind_speed_m_s", 60.0, "wind model covers"),
    ("head_stiffness_nm_per_rad", 0.0, "head_stiffness_nm_per_rad must be >= 1"),
])
def test_out_of_range_parameters_are_named(key, value, match):
    owner = next(e for e in NEW if key in EFFECT_DEFAULTS[e])
    params = {key: value}
    if key == "head_speed_coeff_per_k":
        params["head_delta_t_k"] = -60.0
    with pytest.raises(UserError, match=match):
        fig12([owner], params)


def test_negative_drift_and_cooling_are_allowed():
    sc = fig12(["lidar_clock_drift", "head_thermal_drift"], {"lidar_clock_drift_ppm": 35.0, "head_delta_t_k": -10.0})
    assert sc.param("lidar_clock_drift_ppm") == 35.0 and sc.param("head_delta_t_k") == -10.0


def test_thermal_drift_runs_the_head_hot_and_leaves_the_tracker_its_calibrated_table():
    loop = ClosedLoop(fig12(["head_thermal_drift"]))
    scale = 1.0 + EFFECT_DEFAULTS["head_thermal_drift"]["head_speed_coeff_per_k"] * 20.0
    assert loop.head.speed_scale == scale == 0.98
    table = loop.tracker.table
    for b in (5, 20, 0x3F):
        assert table.pan.speed_deg_s(b) == loop.head.calibrated_speed_deg_s("pan", b)
        assert loop.head.true_speed_deg_s("pan", b) == pytest.approx(scale * table.pan.speed_deg_s(b), rel=1e-15)


def test_backlash_reaches_the_head_and_the_tracker_does_not_know_it():
    loop = ClosedLoop(fig12(["head_backlash"], {"head_backlash_deg": 0.5}, seconds=3.0))
    log = loop.run()
    assert loop.head.backlash_deg == 0.5 and loop.head._pan.half_play == 0.25
    # mid-play at power-on: the first pan move loses a quarter degree against the dead reckoning
    err = log["est_pan_deg"] - log["head_pan_deg"]
    moved = np.abs(log["head_pan_deg"] - log["head_pan_deg"][0]) > 1.0
    assert moved.sum() > 20 and np.mean(np.abs(np.abs(err[moved]) - 0.25) < 1e-6) > 0.8


def _wire_times(scene, monkeypatch):
    sent = []
    real = VirtualUart.send

    def send(self, data, t_s):
        sent.append(float(t_s))
        return real(self, data, t_s)
    monkeypatch.setattr(VirtualUart, "send", send)
    loop = ClosedLoop(scene)
    loop.run()
    monkeypatch.undo()
    return np.array(sent), loop


def test_link_latency_delays_each_command_by_its_streams_draws(monkeypatch):
    scene = fig12(["link_latency_jitter"], seconds=3.0)
    wire, loop = _wire_times(scene, monkeypatch)
    host = (np.arange(1, wire.size + 1) * loop.tracker.config.period_s) + scene.gimbal.send_delay_s
    draws = fx.effect_rng(scene.seed, "link_latency_jitter").exponential(scene.param("link_latency_jitter_s"), wire.size)
    assert wire.size == 30
    assert np.allclose(wire - host, draws, rtol=0, atol=1e-12)
    assert np.all(wire >= host) and 0.2e-3 < (wire - host).mean() < 3e-3
    plain, _ = _wire_times(fig12([], seconds=3.0), monkeypatch)
    assert np.allclose(plain, host, rtol=0, atol=1e-12)


@pytest.mark.parametrize("ppm", [-20.0, 150.0, -150.0])
def test_the_lidar_clock_drifts_by_ppm_times_elapsed(ppm):
    clock = fx.LidarClock(ppm)
    t_ns = np.array([0, 10**8, 10**9, 3600 * 10**9, 86400 * 10**9], dtype=np.int64)
    drift_ns = clock.sensor_ns(t_ns) - t_ns
    assert np.all(np.abs(drift_ns - ppm * 1e-6 * t_ns) <= 0.5)
    assert abs(clock.sensor_s(3600.0) - 3600.0 * (1 + ppm * 1e-6)) < 2e-9
    # the host's offset: a minimum over packets, so it follows a fast clock and not a slow one
    for t in (1.0, 2.0, 3.0):
        clock.observe(t, clock.sensor_s(t))
    assert clock.offset_s == pytest.approx(min(0.0, -ppm * 3e-6), abs=1e-9)


def test_the_closed_loop_hands_the_tracker_sensor_time(monkeypatch):
    scene = fig12(["lidar_clock_drift"], {"lidar_clock_drift_ppm": -100.0}, seconds=2.0)
    frames = []
    loop = ClosedLoop(scene, frame_hook=lambda f, out, lp: frames.append(f))
    loop.run()
    k = 1.0 - 100e-6
    for i, f in enumerate(frames):
        t1 = (i + 1) * 0.1
        assert f.t_end_s == pytest.approx(t1 * k, abs=1e-9)
        assert f.t_ns.size and f.t_ns.min() >= round(f.t_start_s * 1e9) - 1 and f.t_ns.max() <= round(t1 * k * 1e9)
    # a slow clock: the host's offset stays at its first value, the commands still go out on time
    assert loop.clock.offset_s == 0.0
    wire, _ = _wire_times(scene, monkeypatch)
    assert np.allclose(wire, np.arange(1, 21) * 0.1 + scene.gimbal.send_delay_s, rtol=0, atol=1e-12)


@pytest.mark.parametrize("ppm", [-150.0, -20.0, 20.0, 150.0])
def test_the_clock_guard_reads_a_drifting_clock_as_one_stream(ppm):
    """60 s of 1 ms packets stamped by a clock off by ``ppm``, read 10 packets at a time as they
    arrive (host time = true time): every point accepted, no clock jump, nothing early or stale."""
    clock = fx.LidarClock(ppm)
    guard = SensorTimeGuard()
    rate, per_read = 100_000, 1000
    accepted = pushed = 0
    for k in range(6000):
        t_true_ns = 10**9 + (k * per_read + np.arange(per_read, dtype=np.int64)) * (10**9 // rate)
        t = clock.sensor_ns(t_true_ns)
        xyz = np.tile([10.0, 0.0, 0.0], (per_read, 1))
        out = guard.push(xyz, t, np.zeros(per_read, np.uint8), host_s=float(t_true_ns[-1]) * 1e-9)
        accepted += sum(len(a) for a in out)
        pushed += per_read
    accepted += sum(len(a) for a in guard.flush())
    assert accepted == pushed
    c = guard.counters
    assert c["clock_jumps"] == 0 and c["bad_time_points"] == 0 and c["duplicate_points"] == 0


def test_steady_wind_deflects_the_head_by_its_torque_over_the_stiffness():
    """No gusts: the deflection is 0.5 rho Cd A L U^2 / k, pan right and tilt down by half; the
    geared motion is unchanged underneath (the same head without wind, plus the constant)."""
    u, k = 10.0, 100.0
    wind = fx.WindOnHead(u, 0.0, k, np.random.default_rng(0))
    torque_nm = 0.5 * 1.225 * (1.2 * 0.02) * 0.05 * u * u
    t = np.linspace(0, 10, 11)
    (pan, tilt), (vp, vt) = wind.angles_deg(t), wind.rates_deg_s(t)
    assert np.allclose(pan, -np.degrees(torque_nm / k), rtol=1e-12) and np.allclose(tilt, pan / 2, rtol=1e-12)
    assert np.all(vp == 0) and np.all(vt == 0)
    assert 0.03 < -pan[0] < 0.05                          # 0.06 N m on 100 N m/rad: 0.034 deg
    from gimbal.pelco import encode_pan_tilt
    from gimbal.pts303h import PTS303H
    calm, windy = PTS303H(unit_seed=1), PTS303H(unit_seed=1, deflection=wind)
    for h in (calm, windy):
        h.receive(encode_pan_tilt(1, 1, 0x30, 1, 0x30), 0.0)
    t = np.linspace(0, 3, 31)
    (pc, tc), (pw, tw) = calm.angles_at(t, wrap_pan=False), windy.angles_at(t, wrap_pan=False)
    assert np.allclose(pw - pc, pan[0], atol=1e-12) and np.allclose(tw - tc, tilt[0], atol=1e-12)
    assert windy.pose_segments(3.0, 3.1) is None


def test_gusts_have_the_stated_rms_and_their_rates_are_the_derivative():
    wind = fx.WindOnHead(8.0, 0.2, 100.0, fx.effect_rng(12, "head_wind"))
    t = np.arange(0.0, 3000.0, 0.05)
    v = wind.speed(t)
    assert v.mean() == pytest.approx(8.0, abs=0.1)
    assert np.std(v) / 8.0 == pytest.approx(0.2, rel=0.15)           # 16 sinusoids: unit variance by construction
    h = 1e-5
    tt = np.array([1.0, 7.3, 123.4])
    num = (wind.angles_deg_exact(tt + h)[0] - wind.angles_deg_exact(tt - h)[0]) / (2 * h)
    assert np.allclose(wind.rates_deg_s(tt)[0], num, rtol=1e-5, atol=1e-9)
    assert np.allclose(wind.rates_deg_s(tt)[1], num / 2, rtol=1e-5, atol=1e-9)
    # the angles interpolate the gusts between 1 ms nodes: within the stated bound of the exact sum,
    # and the same at a time however it is asked (a frame's span, scattered times, one time)
    for u, stated in ((8.0, 3e-7), (40.0, 1e-5)):
        w = fx.WindOnHead(u, 0.2, 100.0, fx.effect_rng(3, "head_wind"))
        assert w.interpolation_bound_deg() < stated
        frame = np.sort(np.random.default_rng(1).uniform(17.0, 17.1, 10_000))
        assert np.max(np.abs(w.angles_deg(frame)[0] - w.angles_deg_exact(frame)[0])) <= w.interpolation_bound_deg()
        scattered = np.concatenate([frame[:50], [1e4, 3.3]])
        assert np.array_equal(w.angles_deg(scattered)[0][:50], w.angles_deg(frame)[0][:50])
        assert w.angles_deg(frame[7:8])[0][0] == w.angles_deg(frame)[0][7]
    # the phases are the effect's own stream, drawn once
    again = fx.WindOnHead(8.0, 0.2, 100.0, fx.effect_rng(12, "head_wind"))
    assert np.array_equal(again.phase, wind.phase)
    assert np.array_equal(wind.phase, fx.effect_rng(12, "head_wind").uniform(0, 2 * np.pi, 16))
