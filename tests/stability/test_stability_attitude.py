"""The gyro attitude source over long random motion and at its history limit (``foveatrack.gyro_attitude``:
Savage's strapdown update, second-order rotation vector with coning term; the lidar's IMU on the tilt
stage).

Conventions: pan positive = LEFT (CCW from above), tilt positive = UP; body rates in the lidar frame.

Bounds asserted
---------------
* random piecewise-constant pan and tilt rates (|rate| <= 30 / 10 deg/s, changes every 0.05-3 s, for
  60 s at 200 Hz), a noise- and bias-free gyro: the attitude's pan and tilt stay within
  ``sum |jump of body rate| dt / 2 + 1e-3 deg`` of the truth: a rate step between two samples is
  spread over one sample step by the trapezoid (half a step of the jump, at most), and the smooth
  parts' third-order truncation stays below 1e-3 deg over 60 s (measured: 1.9e-5 deg after 10 s of
  the faster test in ``tests/tracker``);
* the history limit: once samples older than ``history_s`` are dropped, an instant before the kept
  ones is NaN with infinite sigma (not the oldest kept angle with its small sigma); inside the kept
  samples the answers are those of a source that keeps everything, to the bit.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from foveatrack.control import HeadCommand
from foveatrack.gyro_attitude import GyroAttitude
from foveatrack.reconstruction import Reconstructor
from foveatrack.speed_table import SpeedTable
from sim.head_imu import lidar_body_rate_rad_s
from stability_util import deg_diff, examples

RATE_HZ = 200.0


def _motion(seed: int, duration_s: float):
    """Sample times, true pan / tilt [deg] and the lidar's body rate [rad/s] of random piecewise-
    constant head rates (tilt kept within +-80 deg by reflecting its rate)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration_s * RATE_HZ) + 1) / RATE_HZ
    pan_rate, tilt_rate = np.empty_like(t), np.empty_like(t)
    t_change, i = 0.0, 0
    while i < t.size:
        t_next = t_change + rng.uniform(0.05, 3.0)
        j = np.searchsorted(t, t_next)
        pan_rate[i:j], tilt_rate[i:j] = rng.uniform(-30.0, 30.0), rng.uniform(-10.0, 10.0)
        t_change, i = t_next, j
    # exact angles of the piecewise-constant rates at the samples (the rates hold from each sample on)
    dt = np.diff(t, prepend=0.0)
    pan = np.cumsum(np.concatenate([[0.0], pan_rate[:-1]]) * dt)
    tilt = np.empty_like(t)
    tilt[0] = 0.0
    for k in range(1, t.size):   # reflect at +-80 so the tilt never reaches the pole
        nxt = tilt[k - 1] + tilt_rate[k - 1] * dt[k]
        if abs(nxt) > 80.0:
            tilt_rate[k - 1:] *= -1.0
            nxt = tilt[k - 1] + tilt_rate[k - 1] * dt[k]
        tilt[k] = nxt
    return t, pan, tilt, pan_rate, tilt_rate


@examples(4)
@given(st.integers(0, 2**32 - 1))
def test_gyro_attitude_follows_random_rates_within_the_step_bound(seed):
    t, pan, tilt, pan_rate, tilt_rate = _motion(seed, 60.0)
    # the gyro samples the rate in force at each sample time; the head's rates are piecewise constant
    # over the sample steps, and the true angles move linearly between samples
    w = lidar_body_rate_rad_s(pan_rate, tilt, tilt_rate)
    rec = Reconstructor(SpeedTable.nominal(), tilt_limits_deg=(-90.0, 90.0), accel_deg_s2=40.0)
    g = GyroAttitude(rec, history_s=120.0)
    g.on_command(0.0, HeadCommand(1, 20, 0, 0))   # moving from t = 0: no rest, no bias update
    g.on_imu(t, w)
    est = np.array([g.angles_at(float(x))[:2] for x in t])
    err = np.array([max(abs(deg_diff(e[0], p)), abs(e[1] - ti)) for e, p, ti in zip(est, pan, tilt)])
    jumps = np.degrees(np.linalg.norm(np.diff(w, axis=0), axis=1))
    bound = np.cumsum(np.concatenate([[0.0], jumps])) * (0.5 / RATE_HZ) + 1e-3
    assert np.all(err <= bound)
    assert np.all(np.isfinite(est))


@examples(6)
@given(st.integers(0, 2**32 - 1), st.floats(1.0, 10.0))
def test_gyro_history_limit_answers_unknown(seed, history_s):
    rng = np.random.default_rng(seed)
    t = np.arange(int(4 * history_s * RATE_HZ)) / RATE_HZ
    w = lidar_body_rate_rad_s(np.full_like(t, rng.uniform(-20, 20)), np.zeros_like(t),
                              np.full_like(t, rng.uniform(-2, 2)))
    sources = []
    for h in (history_s, 1e9):
        rec = Reconstructor(SpeedTable.nominal(), tilt_limits_deg=(-90.0, 90.0), accel_deg_s2=40.0)
        g = GyroAttitude(rec, history_s=h)
        g.on_command(0.0, HeadCommand(1, 20, 0, 0))
        sources.append(g)
    short, full = sources
    n_first = int(0.5 * history_s * RATE_HZ)
    for g in sources:   # before any trim, an instant before the first sample is the start pose
        g.on_imu(t[:n_first], w[:n_first])
    assert short.angles_at(-1.0) == full.angles_at(-1.0)
    for g in sources:
        g.on_imu(t[n_first:], w[n_first:])
    t_kept = short._t[0]
    assert t_kept > 0.0   # it did drop samples
    for tc in rng.uniform(0.0, t[-1], 50):
        got = short.angles_at(float(tc))
        if tc >= t_kept:
            assert got == full.angles_at(float(tc))
        else:
            assert math.isnan(got[0]) and math.isnan(got[1]) and got[2] == got[3] == math.inf
    assert t[-1] - t_kept <= 1.5 * history_s + 1.0 / RATE_HZ
