"""The head's opt-in effects in the device model (sim.effects, "Head and timing"): the thermal drift of
the speed curve and the jitter of the dead time.  Bounds: the drift scales every speed by exactly the
stated factor; each dead time lies within ``dead_time_s +- jitter / 2`` and the spread covers it."""

import numpy as np
import pytest

from gimbal.errors import GimbalError
from gimbal.pelco import encode_pan_tilt
from gimbal.pts303h import PTS303H, HeadParams

NO_RIPPLE = HeadParams(ripple_rel=0.0)


@pytest.mark.parametrize("coeff_per_k, delta_t_k", [(-0.001, 20.0), (0.002, -15.0)])
def test_thermal_drift_scales_the_speed_curve_by_the_coefficient_per_kelvin(coeff_per_k, delta_t_k):
    scale = 1.0 + coeff_per_k * delta_t_k
    cold = PTS303H(NO_RIPPLE, unit_seed=3)
    hot = PTS303H(NO_RIPPLE, unit_seed=3, speed_scale=scale)
    for axis in ("pan", "tilt"):
        ref = cold.speed_table(axis)
        assert np.array_equal(hot.speed_table(axis), ref * scale)
        for b in (0, 10, 0x3F, 0xFF):
            assert hot.calibrated_speed_deg_s(axis, b) == cold.true_speed_deg_s(axis, b)   # the curve kept
    # the motion: 2 s at pan byte 0x20, tilt 0x30; the steady speeds and the distance covered follow
    for h in (cold, hot):
        h.receive(encode_pan_tilt(1, 1, 0x20, 1, 0x30), 0.0)
    t = np.array([3.0, 4.0])
    (pc, tc), (ph, th) = cold.angles_at(t, wrap_pan=False), hot.angles_at(t, wrap_pan=False)
    for c, h in ((pc, ph), (tc, th)):
        assert (h[1] - h[0]) == pytest.approx(scale * (c[1] - c[0]), rel=1e-12)


def test_no_thermal_drift_is_the_same_head_to_the_bit():
    a, b = PTS303H(unit_seed=5), PTS303H(unit_seed=5, speed_scale=1.0)
    for h in (a, b):
        h.receive(encode_pan_tilt(1, -1, 0x2A, 1, 0x11), 0.1)
    t = np.linspace(0, 3, 301)
    assert all(np.array_equal(x, y) for x, y in zip(a.angles_at(t), b.angles_at(t)))


def _start_delays(head, n, period_s=0.5):  # at rest again after 0.3 s
    """Send ``n`` pan commands from rest; return each one's delay from its last byte to motion."""
    accel = head.params.pan_accel_deg_s2
    delays = []
    for k in range(n):
        t = k * period_s
        head.receive(encode_pan_tilt(1, 1, 0x3F, 0, 0), t)           # arrives at t
        probe = t + 0.08                                               # still accelerating then
        v = float(head.rates_at(probe)[0])
        delays.append(probe - v / accel)                               # v = a (probe - t_effect)
        head.receive(encode_pan_tilt(1, 0, 0, 0, 0), t + 0.1)          # stop (at rest before the next)
    return np.array(delays) - period_s * np.arange(n)


def test_dead_time_jitter_stays_within_its_width_and_spreads_over_it():
    p = NO_RIPPLE
    jitter = 0.02
    head = PTS303H(p, dead_time_jitter_s=jitter, dead_time_rng=np.random.default_rng(11))
    d = _start_delays(head, 200)
    assert d.min() >= p.dead_time_s - jitter / 2 - 1e-9
    assert d.max() <= p.dead_time_s + jitter / 2 + 1e-9
    assert d.max() - d.min() > 0.9 * jitter                              # uniform over the width
    assert abs(d.mean() - p.dead_time_s) < 4 * jitter / np.sqrt(12 * 200)  # centred: the mean unchanged
    steady = _start_delays(PTS303H(p), 5)
    assert np.allclose(steady, p.dead_time_s, atol=1e-9)


def test_dead_time_jitter_draws_one_uniform_per_frame_from_its_own_stream():
    rng = np.random.default_rng(4)
    head = PTS303H(NO_RIPPLE, dead_time_jitter_s=0.02, dead_time_rng=rng)
    d = _start_delays(head, 20)
    u = np.random.default_rng(4).random(40)[::2]     # a start and a stop per command
    assert np.allclose(d, NO_RIPPLE.dead_time_s + 0.02 * (u - 0.5), atol=1e-9)


def test_bad_effect_arguments_are_refused():
    with pytest.raises(GimbalError, match="speed_scale"):
        PTS303H(speed_scale=0.0)
    with pytest.raises(GimbalError, match="dead_time_rng"):
        PTS303H(dead_time_jitter_s=0.01)


@pytest.mark.parametrize("ripple", [0.0, 0.02])
@pytest.mark.parametrize("play_deg", [0.2, 1.0])
def test_a_reversal_loses_exactly_the_backlash_before_the_output_moves(play_deg, ripple):
    """The same unit and commands with and without the play: the output lags the motor by half the
    play while driven (mid-play at power-on), stands still on a reversal until the motor has turned
    the whole play back, then leads by half the play.  Bound 1e-9 deg."""
    p = HeadParams(ripple_rel=ripple)
    motor, geared = PTS303H(p, unit_seed=2), PTS303H(p, unit_seed=2, backlash_deg=play_deg)
    again = PTS303H(p, unit_seed=2, backlash_deg=play_deg)      # for the speeds (asking advances a head)
    for h in (motor, geared, again):
        h.receive(encode_pan_tilt(1, 1, 0x20, 1, 0x20), 0.0)     # left and up for 1.5 s
        h.receive(encode_pan_tilt(1, -1, 0x20, -1, 0x20), 1.5)   # then reverse both
    assert geared.pose_segments(0.0, 0.1) is None
    assert (motor.pose_segments(0.0, 0.1) is None) == (ripple > 0)
    t = np.linspace(0.0, 4.0, 40_001)
    m_pan, m_tilt = motor.angles_at(t, wrap_pan=False)
    g_pan, g_tilt = geared.angles_at(t, wrap_pan=False)
    rates = again.rates_at(t)
    h = play_deg / 2
    eps = 1e-4   # samples this close (in motor angle) to a switch are not classified
    for m, g, v in ((m_pan, g_pan, rates[0]), (m_tilt, g_tilt, rates[1])):
        k_peak = int(np.argmax(m))
        peak = m[k_peak]                       # within 1e-6 deg of the true turning point
        before, back = np.arange(t.size) < k_peak, np.arange(t.size) > k_peak
        first = before & (m - m[0] < h - eps)
        assert first.sum() > 10 and np.allclose(g[first], m[0], atol=1e-9, rtol=0)   # half the play: still
        fwd = before & (m - m[0] > h + eps)
        assert fwd.sum() > 100 and np.allclose(g[fwd], m[fwd] - h, atol=1e-9, rtol=0)
        held = back & (m > peak - play_deg + eps)
        assert held.sum() > 10 and np.ptp(g[held]) < 1e-12                  # the output stands still
        assert abs(g[held][0] - (peak - h)) < 1e-6
        after = back & (m < peak - play_deg - eps)                            # the play lost, it follows
        assert after.sum() > 100 and np.allclose(g[after], m[after] + h, atol=1e-9, rtol=0)
        assert np.all(v[held] == 0.0) and np.all(v[first] == 0.0) and np.all(v[fwd] > 0) and np.all(v[after] < 0)


def test_no_backlash_is_the_same_head_to_the_bit():
    a, b = PTS303H(NO_RIPPLE, unit_seed=8), PTS303H(NO_RIPPLE, unit_seed=8, backlash_deg=0.0)
    for h in (a, b):
        h.receive(encode_pan_tilt(1, 1, 0x3F, -1, 0x3F), 0.0)
        h.receive(encode_pan_tilt(1, -1, 0x10, 1, 0x3F), 0.7)
    t = np.linspace(0, 2, 201)
    assert all(np.array_equal(x, y) for x, y in zip(a.angles_at(t), b.angles_at(t)))
    assert all(np.array_equal(x, y) for x, y in zip(a.pose_segments(0, 2), b.pose_segments(0, 2)))
