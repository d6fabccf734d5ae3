"""Head-angle dead reckoning over hours (paper Appendix D.4, Fig. 14c): the drift stays inside the
uncertainty the reconstruction states, rounding does not accumulate, and rotations stay orthonormal.

Truth model for the drift test: a head whose true speed per byte differs from the table by a fixed
bias |b| <= sigma_b (the table's stated 1-sigma), piecewise-constant speeds (no dead time, no
acceleration), integrated exactly with ``math.fsum`` on unwrapped angles.  The reconstruction's
angle error is then exactly ``sum_b bias_b S_b`` (S_b = signed time at byte b), which the
reconstruction's stated variance ``sum_b (sigma_b S_b)^2`` describes.

Bounds asserted (4 h of virtual time, commands changing every 0.5-20 s, pan and tilt)
------------------------------------------------------------------------------------------
* |error| <= sum_b sigma_b |S_b| + 1e-8 deg at every check (deterministic: |bias_b| <= sigma_b);
* |error| <= 3 sigma_stated + 1e-8 deg (biases uniform in [-sigma, sigma] have std sigma/sqrt 3, so
  this is a 5.2-std bound);
* with a bias-free table the error is rounding only: <= 1e-8 deg after 4 h;
* against the PTS-303H device model (its own speed table, acceleration and dead time, no ripple):
  pan within 1e-6 deg after 2 h of random commands;
* every rotation R (at any pan up to 1e12 deg and at every check of the 4 h run) has
  |R R^T - I| <= 1e-12 and |det R - 1| <= 1e-12;
* the history limit: an instant inside ``history_s`` of the newest command is answered to the bit as
  by a reckoning that keeps everything; one before the kept commands is NaN with infinite sigma.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from foveatrack.control import HeadCommand
from foveatrack.detection import wrap_deg
from foveatrack.reconstruction import Reconstructor, rotation_matrix
from foveatrack.speed_table import AxisTable, SpeedEntry, SpeedTable
from stability_util import deg_diff, examples


def _orthonormal_error(R):
    return float(np.max(np.abs(R @ R.T - np.eye(3)))), abs(float(np.linalg.det(R)) - 1.0)


@examples(300)
@given(st.one_of(st.floats(-1e12, 1e12), st.sampled_from([180.0, -180.0, 179.99999999999997, 1e12 + 0.5])),
       st.floats(-90.0, 90.0))
def test_rotation_matrices_are_orthonormal(pan, tilt):
    R = rotation_matrix(pan, tilt)
    e_orth, e_det = _orthonormal_error(R)
    assert e_orth <= 1e-12 and e_det <= 1e-12


def _table(rng, rel_sigma):
    def axis(name, vmax):
        sp = np.sort(rng.uniform(0.05, vmax, 64))
        return AxisTable(name, tuple(SpeedEntry(b, float(sp[b]), float(rel_sigma * sp[b])) for b in range(64)))
    return SpeedTable(axis("pan", 15.0), axis("tilt", 4.0))


def _drive(seed, hours, rel_sigma, bias_scale):
    """Random command schedule; returns the per-check (error, bound, sigma) arrays for both axes and
    the worst orthonormality error."""
    rng = np.random.default_rng(seed)
    table = _table(rng, rel_sigma)
    bias = {a: rng.uniform(-1, 1, 64) * bias_scale * np.array([table.axis(a).sigma_deg_s(b) for b in range(64)])
            for a in ("pan", "tilt")}
    pan0, tilt0 = float(rng.uniform(-180, 180)), float(rng.uniform(-20, 20))
    rec = Reconstructor(table, pan0_deg=pan0, tilt0_deg=tilt0, timing_sigma_s=0.0, dead_time_s=0.0,
                        tilt_limits_deg=(-1e9, 1e9))
    truth_parts = {"pan": [pan0], "tilt": [tilt0]}
    S = {"pan": np.zeros(64), "tilt": np.zeros(64)}
    cur = {"pan": (0, 0), "tilt": (0, 0)}
    t = 0.0
    end = hours * 3600.0
    rows = []
    worst_orth = 0.0
    while t < end:
        cmd = HeadCommand(int(rng.integers(-1, 2)), 0, int(rng.integers(-1, 2)), 0)
        cmd = HeadCommand(cmd.pan_dir, int(rng.integers(0, 64)) if cmd.pan_dir else 0,
                          cmd.tilt_dir, int(rng.integers(0, 64)) if cmd.tilt_dir else 0)
        rec.on_command(t, cmd)
        cur = {"pan": cmd.axis("pan"), "tilt": cmd.axis("tilt")}
        dt = float(rng.uniform(0.5, 20.0))
        for frac in (0.5, 1.0):  # check mid-segment and at its end
            tc = t + frac * dt
            pan_r, tilt_r, s_pan, s_tilt = rec.angles_at(tc)
            for a, est, sig in (("pan", pan_r, s_pan), ("tilt", tilt_r, s_tilt)):
                d, b = cur[a]
                ax = table.axis(a)
                v = d * (ax.speed_deg_s(b) + bias[a][b]) if d else 0.0
                truth = math.fsum(truth_parts[a] + [v * frac * dt])
                Sb = S[a].copy()
                if d:
                    Sb[b] += d * frac * dt
                sig_b = np.array([ax.sigma_deg_s(k) for k in range(64)])
                bound = float(np.sum(sig_b * np.abs(Sb)))
                err = deg_diff(est, wrap_deg(truth)) if a == "pan" else est - truth
                rows.append((a == "pan", abs(err), bound, sig))
            worst_orth = max(worst_orth, *_orthonormal_error(rec.rotation_at(tc)))
        for a in ("pan", "tilt"):
            d, b = cur[a]
            if d:
                v = d * (table.axis(a).speed_deg_s(b) + bias[a][b])
                truth_parts[a].append(v * dt)
                S[a][b] += d * dt
        t += dt
    return np.array(rows), worst_orth


@examples(4)
@given(st.integers(0, 2**32 - 1))
def test_drift_over_four_hours_stays_inside_the_stated_uncertainty(seed):
    rows, worst_orth = _drive(seed, hours=4.0, rel_sigma=0.02, bias_scale=1.0)
    err, bound, sig = rows[:, 1], rows[:, 2], rows[:, 3]
    assert np.all(err <= bound + 1e-8)
    assert np.all(err <= 3.0 * sig + 1e-8)
    assert err.max() > 1.0  # the biases do act: this is not a vacuous comparison
    assert worst_orth <= 1e-12


@examples(4)
@given(st.integers(0, 2**32 - 1))
def test_bias_free_reckoning_has_no_rounding_drift(seed):
    rows, worst_orth = _drive(seed, hours=4.0, rel_sigma=0.02, bias_scale=0.0)
    assert rows[:, 1].max() <= 1e-8
    assert worst_orth <= 1e-12


@examples(3)
@given(st.integers(0, 1000), st.integers(0, 2**32 - 1))
def test_reconstruction_follows_the_device_model_for_two_hours(unit_seed, seed):
    """The PTS-303H model without ripple and the reconstruction with the unit's own table (speeds,
    per-axis acceleration, dead time): the same exact piecewise-quadratic motion, to 1e-6 deg."""
    from gimbal.pelco import encode_pan_tilt
    from gimbal.pts303h import PTS303H, HeadParams
    from sim.loop import truth_speed_table

    head = PTS303H(HeadParams(ripple_rel=0.0), unit_seed=unit_seed)
    rec = Reconstructor(truth_speed_table(head), latency_s=0.0, timing_sigma_s=0.0)
    rng = np.random.default_rng(seed)
    t, worst = 0.0, 0.0
    while t < 7200.0:
        d = int(rng.integers(-1, 2))
        b = int(rng.integers(0, 64)) if d else 0
        head.receive(encode_pan_tilt(1, d, b, 0, 0), t)
        rec.on_command(t, HeadCommand(d, b, 0, 0))
        dt = float(rng.uniform(0.3, 15.0))
        for tc in np.linspace(t + 0.01, t + dt, 4):
            truth = float(head.angles_at([tc])[0][0])
            worst = max(worst, abs(deg_diff(rec.angles_at(float(tc))[0], truth)))
        t += dt
    assert worst <= 1e-6


# ------------------------------------------------------------------------------------------------
# the history limit


@examples(20)
@given(st.integers(0, 2**32 - 1), st.floats(5.0, 60.0))
def test_history_limit_answers_unknown_never_a_confident_angle(seed, history_s):
    """Random commands for 5 history lengths: an instant inside the kept history is answered to the
    bit as by a reckoning that keeps everything; an instant before it is NaN with infinite sigma
    (802524f answered the oldest kept knot's angle with its small sigma: 127.7 deg, sigma 0,
    against 87.6 deg).  Before any trim, an instant before the start is the start pose."""
    table = SpeedTable.nominal()
    kw = dict(pan0_deg=10.0, tilt0_deg=5.0, sigma0_deg=0.1, tilt_limits_deg=(-30.0, 60.0))
    rec = Reconstructor(table, history_s=history_s, **kw)
    full = Reconstructor(table, history_s=math.inf, **kw)
    assert rec.angles_at(-1.0) == full.angles_at(-1.0) == (10.0, 5.0, 0.1, 0.1)
    rng = np.random.default_rng(seed)
    t, end = 0.0, 5.0 * history_s
    while t < end:
        dp, dt = int(rng.integers(-1, 2)), int(rng.integers(-1, 2))
        cmd = HeadCommand(dp, int(rng.integers(1, 64)) if dp else 0, dt, int(rng.integers(1, 64)) if dt else 0)
        rec.on_command(t, cmd)
        full.on_command(t, cmd)
        t_cmd = t
        t += float(rng.uniform(0.1, history_s / 4))
        for tc in rng.uniform(0.0, t, 8):
            tc = float(tc)
            got, want = rec.angles_at(tc), full.angles_at(tc)
            if tc >= t_cmd - history_s:   # inside the promised history: untouched by the trim
                assert got == want
                continue
            for k, axis in enumerate((rec.pan, rec.tilt)):
                if axis.times[0] > 0.0 and tc < axis.times[0]:   # the start was trimmed: unknown
                    assert math.isnan(got[k]) and got[k + 2] == math.inf
                else:   # older than promised but still kept: still right
                    assert got[k] == want[k] and got[k + 2] == want[k + 2]
    old = rec.angles_at(-1.0)
    assert math.isnan(old[0]) and math.isnan(old[1]) and old[2] == old[3] == math.inf
