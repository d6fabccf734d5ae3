"""The PTS-303H model: unit curves, exact dynamics, stops, feedback modes, presets, quirks."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad

from gimbal import pelco as P
from gimbal.errors import GimbalError
from gimbal.pts303h import HEAD_FAMILIES, PTS303H, HeadParams

PARAMS = HeadParams()


def script_head(**kw):
    """A head driven through speed changes, a reversal, a tilt stop hit and a stop."""
    h = PTS303H(tilt0_deg=kw.pop("tilt0_deg", 58.0), **kw)
    cmds = [
        (0.10, P.encode_pan_tilt(1, 1, 0x3F, 1, 0x3F)),
        (0.73, P.encode_pan_tilt(1, 1, 0x18, 1, 0x30)),
        (1.31, P.encode_pan_tilt(1, -1, P.PAN_TURBO, 1, 0x3F)),
        (2.20, P.encode_pan_tilt(1, 1, 0x08, -1, 0x3F)),
        (2.90, P.encode_stop(1)),
    ]
    return h, cmds


def run_script(step_s, t_end=4.0, grid=None):
    h, cmds = script_head()
    t = 0.0
    out = []
    grid = np.linspace(0.0, t_end, 401) if grid is None else grid
    gi = 0
    for tc, frame in cmds + [(t_end + 1, None)]:
        while t + step_s <= tc and t + step_s <= t_end:
            t += step_s
            h.advance_to(t)
            while gi < len(grid) and grid[gi] <= t:
                out.append(h.state_at(grid[gi]))
                gi += 1
        if frame is not None:
            h.receive(frame, tc)
    while gi < len(grid):
        out.append(h.state_at(grid[gi]))
        gi += 1
    return np.array([[s.pan_deg, s.tilt_deg, s.pan_speed_deg_s, s.tilt_speed_deg_s] for s in out])


# speed curve --------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2, 7])
def test_speed_curve_is_monotone_with_dead_zone_and_separate_turbo(seed):
    h = PTS303H(unit_seed=seed)
    for axis in ("pan", "tilt"):
        v = np.array([h.true_speed_deg_s(axis, b) for b in range(64)])
        assert v[0] == 0.0 and v[1] == 0.0  # dead zone at low bytes (b0 >= 1)
        live = v > 0
        first = int(np.argmax(live))
        assert live[first:].all() and np.all(np.diff(v[first:]) > 0)  # strictly increasing
        assert 0.5 * h.params.pan_speed_max_deg_s < h.true_speed_deg_s("pan", 0x3F) < 1.5 * 15
        assert h.true_speed_deg_s(axis, 0x50) == v[63]  # 0x40-0xFE act as 0x3F
        # nonlinear: the curve is not a straight line through the live bytes
        x = np.arange(first, 64)
        fit = np.polyval(np.polyfit(x, v[first:], 1), x)
        assert np.max(np.abs(fit - v[first:])) > 0.02 * v[63]
    assert h.true_speed_deg_s("pan", 0xFF) > 1.04 * h.true_speed_deg_s("pan", 0x3F)
    assert h.true_speed_deg_s("tilt", 0xFF) == h.true_speed_deg_s("tilt", 0x3F)  # no tilt turbo


def test_two_units_differ_and_one_seed_is_reproducible():
    a, b, a2 = PTS303H(unit_seed=0), PTS303H(unit_seed=1), PTS303H(unit_seed=0)
    assert not np.allclose(a.speed_table("pan"), b.speed_table("pan"), rtol=0.02)
    assert np.array_equal(a.speed_table("pan"), a2.speed_table("pan"))
    assert np.array_equal(a.speed_table("tilt"), a2.speed_table("tilt"))


# exactness ----------------------------------------------------------------------------------
def test_step_size_never_changes_the_result():
    ref = run_script(1.0)  # coarse: one advance per second
    for step in (0.001, 0.0137, 0.1):
        assert np.max(np.abs(run_script(step) - ref)) < 1e-9


def test_closed_form_angle_equals_the_integral_of_the_speed():
    h, cmds = script_head(params=replace(PARAMS, history_s=100.0))
    for t, f in cmds:
        h.receive(f, t)
    t_grid = np.linspace(0.0, 4.0, 41)
    pan, tilt = h.angles_at(t_grid)
    # numerically integrate the true speed (ripple included) and compare: two routes agree
    vp = lambda t: float(h.rates_at(np.array([t]))[0][0])  # noqa: E731
    vt = lambda t: float(h.rates_at(np.array([t]))[1][0])  # noqa: E731
    breaks = list(np.linspace(0, 4, 81))
    for k in range(1, len(t_grid)):
        pts = [b for b in breaks if t_grid[k - 1] < b < t_grid[k]]
        dp = quad(vp, t_grid[k - 1], t_grid[k], points=pts or None, limit=200, epsabs=1e-11)[0]
        dt = quad(vt, t_grid[k - 1], t_grid[k], points=pts or None, limit=200, epsabs=1e-11)[0]
        assert abs(P.wrap_pan_deg(pan[k] - pan[k - 1] - dp)) < 1e-7
        assert abs(tilt[k] - tilt[k - 1] - dt) < 1e-7


def test_vectorised_angles_match_state_at_and_accept_any_shape():
    h, cmds = script_head()
    for t, f in cmds[:3]:
        h.receive(f, t)
    t = np.linspace(1.2, 1.9, 12).reshape(3, 4)
    pan, tilt = h.angles_at(t)
    assert pan.shape == tilt.shape == (3, 4)
    for (i, j), tt in np.ndenumerate(t):
        s = h.state_at(tt)
        assert pan[i, j] == pytest.approx(s.pan_deg, abs=1e-12)
        assert tilt[i, j] == pytest.approx(s.tilt_deg, abs=1e-12)


@pytest.mark.parametrize("ripple", [0.0, PARAMS.ripple_rel])
def test_position_only_path_equals_the_full_evaluation_and_unwrapped_pan_is_continuous(ripple):
    # angles_at takes the position-only path (no speed, no ripple terms when there is no ripple);
    # it must give the very bits of the full evaluation, and wrap_pan=False must not jump at 180.
    h = PTS303H(replace(PARAMS, ripple_rel=ripple, history_s=100.0), unit_seed=3, pan0_deg=170.0)
    h.receive(P.encode_pan_tilt(1, 1, 0x3F, 1, 0x20), 0.5)
    h.receive(P.encode_pan_tilt(1, 0, 0, -1, 0x10), 2.5)
    t = np.linspace(0.0, 4.0, 401)
    full_pan, _ = h._pan.eval(t)
    full_tilt, _ = h._tilt.eval(t)
    pan_c, tilt = h.angles_at(t, wrap_pan=False)
    assert np.array_equal(pan_c, full_pan) and np.array_equal(tilt, full_tilt)
    pan_w, _ = h.angles_at(t)
    assert pan_c.max() > 180.0 and pan_w.max() <= 180.0          # it crossed the wrap ...
    assert np.max(np.abs(np.diff(pan_c))) < 1.0                    # ... continuously when unwrapped
    assert np.allclose(P.wrap_pan_deg(pan_w - pan_c), 0.0, atol=1e-9)


# dynamics from the parameters ---------------------------------------------------------------
def test_dead_time_then_acceleration_limit_then_commanded_speed():
    p = replace(PARAMS, ripple_rel=0.0)
    h = PTS303H(p, unit_seed=3)
    h.receive(P.encode_pan_tilt(1, 1, 0x30, -1, 0x30), 1.0)
    te = 1.0 + p.dead_time_s
    vp, vt = h.rates_at(np.array([te - 1e-6, te + 0.05, te + 0.1]))
    assert vp[0] == 0 and vt[0] == 0
    assert (vp[2] - vp[1]) / 0.05 == pytest.approx(p.pan_accel_deg_s2, rel=1e-9)
    assert (vt[2] - vt[1]) / 0.05 == pytest.approx(-p.tilt_accel_deg_s2, rel=1e-9)
    v_end = h.rates_at(np.array([5.0]))
    assert v_end[0][0] == pytest.approx(h.true_speed_deg_s("pan", 0x30), rel=1e-12)
    assert v_end[1][0] == pytest.approx(-h.true_speed_deg_s("tilt", 0x30), rel=1e-12)


def test_ripple_averages_out_over_its_period():
    h = PTS303H(unit_seed=4)
    h.receive(P.encode_pan_tilt(1, 1, 0x20, 0, 0), 0.0)
    f_pan = h.ripple_freq_hz[0]
    n = 5 / f_pan
    t0 = 3.0
    pan0, _ = h.angles_at(np.array([t0]))
    pan1, _ = h.angles_at(np.array([t0 + n]))
    assert (pan1[0] - pan0[0]) / n == pytest.approx(h.true_speed_deg_s("pan", 0x20), rel=1e-9)
    v = h.rates_at(np.linspace(t0, t0 + n, 500))[0]
    assert v.max() > h.true_speed_deg_s("pan", 0x20) * (1 + 0.5 * PARAMS.ripple_rel)


def test_pan_wraps_and_tilt_stops_hold():
    h = PTS303H(tilt0_deg=59.0)
    h.receive(P.encode_pan_tilt(1, 1, P.PAN_TURBO, 1, 0x3F), 0.0)
    t = np.linspace(0, 30, 3001)
    pan, tilt = h.angles_at(t)
    assert np.all(pan > -180) and np.all(pan <= 180)
    assert np.any(np.diff(pan) < -300)  # it went round
    assert tilt.max() == PARAMS.tilt_max_deg  # exactly at the stop, never beyond
    hold = t > 2.0
    assert np.all(tilt[hold] == PARAMS.tilt_max_deg)
    assert np.all(h.rates_at(t[hold])[1] == 0.0)
    # commanded away from the stop it leaves it
    h.receive(P.encode_pan_tilt(1, 0, 0, -1, 0x3F), 31.0)
    assert h.state_at(33.0).tilt_deg < PARAMS.tilt_max_deg - 1.0


def test_lower_stop_holds_too_and_a_stop_command_releases_the_push():
    h = PTS303H(tilt0_deg=-29.5)
    h.receive(P.encode_pan_tilt(1, 0, 0, -1, 0x3F), 0.0)
    assert h.state_at(2.0).tilt_deg == PARAMS.tilt_min_deg
    assert not h.at_rest(2.0)  # motor pushing into the stop
    h.receive(P.encode_stop(1), 2.0)
    assert h.at_rest(2.5) and h.state_at(2.5).tilt_deg == PARAMS.tilt_min_deg


def test_a_reversal_while_braking_into_a_stop_is_honoured():
    """Driven down at full speed from 0.2 deg above the lower stop and reversed at times spanning
    the stop hit: the head never passes the stop, rests on it for no sampled instant (the stop
    absorbs the speed and the reversed command moves it away at once), and ends at least where
    turning round at the latest (v / accel after the reversal takes effect) would leave it.
    802524f dropped the reversal once the braking reached the stop: the head stayed at -30 deg."""
    p = HeadParams(ripple_rel=0.0)
    stop = p.tilt_min_deg
    hits = 0
    for t_rev in np.arange(0.0, 0.301, 0.01):
        h = PTS303H(p, tilt0_deg=stop + 0.2)
        v = h.true_speed_deg_s("tilt", 0x3F)
        h.receive(P.encode_pan_tilt(1, 0, 0, -1, 0x3F), 0.0)
        h.receive(P.encode_pan_tilt(1, 0, 0, 1, 0x3F), float(t_rev))
        t = np.linspace(0.0, 3.0, 3001)
        tilt = h.angles_at(t)[1]
        assert tilt.min() >= stop
        hits += tilt.min() == stop
        assert np.all(tilt[t > t_rev + p.dead_time_s + 1e-3] > stop)
        ramp_s = v / p.tilt_accel_deg_s2
        t_up = 3.0 - (t_rev + p.dead_time_s + ramp_s)   # time since the latest turn-round
        assert tilt[-1] >= stop + 0.5 * v * ramp_s + v * (t_up - ramp_s) - 1e-9
    assert hits >= 10   # the sweep does reach the stop


def test_history_is_bounded_and_causality_is_enforced():
    h = PTS303H()
    h.receive(P.encode_pan_tilt(1, 1, 0x20, 0, 0), 0.0)
    for k in range(1, 60):
        h.receive(P.encode_pan_tilt(1, 1, 0x20 + (k % 5), 0, 0), 0.1 * k)
        h.advance_to(0.1 * k + 0.05)
    assert len(h._pan.segs) < 60
    h.angles_at(np.array([h.t_now_s - 0.99 * PARAMS.history_s]))  # inside the history: fine
    with pytest.raises(ValueError, match="history"):
        h.angles_at(np.array([0.0, h.t_now_s]))
    h.advance_to(10.0)
    with pytest.raises(ValueError, match="asked about"):
        h.receive(P.encode_stop(1), 9.0)


def test_other_addresses_and_camera_functions_are_ignored():
    h = PTS303H(address=3)
    h.receive(P.encode_pan_tilt(2, 1, 0x3F, 0, 0), 0.0)
    h.receive(bytes(P.PelcoCommand("D", 3, 0, 0x20 | P.PAN_LEFT, 0x3F, 0).to_bytes()), 0.1)
    assert h.state_at(2.0).pan_deg == 0.0
    h.receive(P.encode_pan_tilt(4, 1, 0x3F, 0, 0, "P"), 2.0)
    h.receive(P.encode_pan_tilt(3, 1, 0x3F, 0, 0, "P"), 2.1)  # P is adaptive: obeyed
    assert h.state_at(4.0).pan_deg > 1.0


# feedback -----------------------------------------------------------------------------------
def _reply(h, proto, t, which="pan"):
    enc = P.encode_query_pan if which == "pan" else P.encode_query_tilt
    out = h.receive(enc(1, proto), t)
    assert all(ts > t for ts, _ in out)
    return [P.decode(b) for _, b in out]


def test_feedback_none_never_answers():
    h = PTS303H()
    assert _reply(h, "D", 1.0) == [] and _reply(h, "P", 1.1, "tilt") == []


@pytest.mark.parametrize("proto", ["D", "P"])
def test_feedback_always_answers_truth_in_the_envelope_it_was_asked_in(proto):
    h = PTS303H(feedback="always", pan0_deg=-33.33, tilt0_deg=12.5)
    h.receive(P.encode_pan_tilt(1, 1, 0x30, 1, 0x30), 0.0)
    (r,) = _reply(h, proto, 2.0)
    assert r.protocol == proto and r.kind == "pan_reply" and r.address == 1
    assert P.word_to_pan_deg(r.word) == pytest.approx(h.state_at(2.0).pan_deg, abs=0.006)
    (r,) = _reply(h, proto, 2.01, "tilt")
    assert r.kind == "tilt_reply"
    tilt = P.word_to_tilt_deg(r.word, PARAMS.tilt_zero)
    assert tilt == pytest.approx(h.state_at(2.01).tilt_deg, abs=0.006)


def test_feedback_at_rest_is_right_at_rest_and_never_right_while_moving():
    h = PTS303H(feedback="at-rest", pan0_deg=10.0, tilt0_deg=-5.0)
    (r,) = _reply(h, "D", 0.5)
    assert P.word_to_pan_deg(r.word) == pytest.approx(10.0, abs=0.006)
    h.receive(P.encode_pan_tilt(1, -1, 0x38, 1, 0x38), 1.0)
    t = 1.0 + PARAMS.dead_time_s + 0.001
    for k in range(200):
        tq = t + 0.02 * k
        for which in ("pan", "tilt"):
            (r,) = _reply(h, "D" if k % 2 else "P", tq, which)
            assert r.kind == f"{which}_reply"
            if P.word_is_angle(r.word):
                s = h.state_at(tq)
                got = (P.word_to_pan_deg(r.word) if which == "pan"
                       else P.word_to_tilt_deg(r.word, PARAMS.tilt_zero))
                truth = s.pan_deg if which == "pan" else s.tilt_deg
                assert abs(P.wrap_pan_deg(got - truth)) > PARAMS.garbage_margin_deg
    h.receive(P.encode_stop(1), 6.0)
    (r,) = _reply(h, "D", 8.0)
    assert P.word_to_pan_deg(r.word) == pytest.approx(h.state_at(8.0).pan_deg, abs=0.006)
    (r,) = _reply(h, "D", 8.1, "tilt")
    assert P.word_to_tilt_deg(r.word, "zenith") == pytest.approx(h.state_at(8.1).tilt_deg,
                                                                 abs=0.006)


# presets and absolute sets -----------------------------------------------------------------
def test_presets_set_go_to_and_clear():
    h = PTS303H(pan0_deg=170.0, tilt0_deg=5.0)
    h.receive(P.encode_set_preset(1, 4), 0.0)
    h.receive(P.encode_pan_tilt(1, 1, 0x3F, -1, 0x3F), 0.1)  # crosses +180 -> wraps
    h.receive(P.encode_goto_preset(1, 4), 3.0)
    s = h.state_at(30.0)
    assert s.pan_deg == pytest.approx(170.0, abs=1e-9) and s.tilt_deg == pytest.approx(5.0, abs=1e-9)
    assert h.at_rest(30.0)
    h.receive(P.encode_clear_preset(1, 4), 31.0)
    h.receive(P.encode_pan_tilt(1, 1, 0x3F, 0, 0), 31.1)
    h.receive(P.encode_goto_preset(1, 4), 32.0)  # cleared: ignored, keeps moving
    assert h.state_at(34.0).pan_speed_deg_s > 1.0


def test_absolute_set_needs_a_quiet_line():
    h = PTS303H()
    set_pan = P.encode_set_pan(1, -45.0)
    h.receive(P.encode_stop(1), 1.0)
    h.receive(set_pan, 1.0 + 0.01)  # right behind another frame: ignored (quirk)
    assert h.state_at(10.0).pan_deg == 0.0
    h.receive(set_pan, 11.0)  # after a quiet line: obeyed, shortest way round
    assert h.state_at(30.0).pan_deg == pytest.approx(-45.0, abs=1e-9)
    h.receive(P.encode_set_tilt(1, 80.0, tilt_zero="zenith"), 31.0)  # beyond the stop: clamped
    assert h.state_at(80.0).tilt_deg == pytest.approx(PARAMS.tilt_max_deg, abs=1e-9)
    quirkless = PTS303H(replace(PARAMS, abs_set_quiet_s=0.0))
    quirkless.receive(P.encode_stop(1) + set_pan, 1.0)
    assert quirkless.state_at(20.0).pan_deg == pytest.approx(-45.0, abs=1e-9)


def test_parameter_errors_are_user_errors():
    with pytest.raises(GimbalError, match="feedback"):
        PTS303H(feedback="sometimes")
    with pytest.raises(GimbalError, match="stops"):
        PTS303H(tilt0_deg=89.0)
    with pytest.raises(GimbalError, match="pan_turbo"):
        HeadParams(pan_turbo_deg_s=1.0)
    with pytest.raises(GimbalError, match="known"):
        HeadParams.for_family("pts-999")
    assert HeadParams.for_family("heavy-worm").tilt_speed_max_deg_s == 15.0
    assert set(HEAD_FAMILIES) >= {"pts-303", "heavy-worm"}


def test_times_in_any_order_give_the_same_angles_with_ripple():
    h = PTS303H(replace(PARAMS, history_s=100.0), unit_seed=3)
    h.receive(P.encode_pan_tilt(1, 1, 0x3F, 1, 0x20), 0.5)
    h.receive(P.encode_pan_tilt(1, 0, 0, -1, 0x10), 2.5)
    t = np.linspace(0.0, 4.0, 401)
    pan, tilt = h.angles_at(t)
    pan_r, tilt_r = h.angles_at(t[::-1])
    assert np.array_equal(pan_r[::-1], pan) and np.array_equal(tilt_r[::-1], tilt)
    assert np.array_equal(pan, P.wrap_pan_deg(h._pan.eval(t)[0]))   # ripple included
