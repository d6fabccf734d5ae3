"""The predictive controller's bearing filter (``foveatrack.predictive.BearingFilter``, a constant-velocity
Kalman filter per axis, FilterPy's white-noise-acceleration Q) at its hard inputs: repeated and
out-of-order-free but wildly uneven times, huge gaps, pan across +-180 deg.

Bounds asserted
---------------
* any update sequence (steps 0, 1e-9 s .. 1e4 s; bearings anywhere in +-1e4 deg): x and P stay finite,
  P symmetric to the bit (it is symmetrised) with eigenvalues >= -1e-9 |P| (rounding only), and
  ``predict``'s sigma is finite and >= 0;
* a target turning at a constant rate |w| <= 60 deg/s, measured without noise every 0.1 s from any
  pan (crossing +-180 deg, the innovations wrapped): after 5 s the rate is within 1e-3 deg/s and the
  wrapped bearing within 1e-3 deg of the truth (a noise-free constant-velocity target is the model's
  own case: the estimate converges to it).
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from foveatrack.detection import wrap_deg
from foveatrack.predictive import BearingFilter
from stability_util import deg_diff, examples

steps = st.sampled_from([0.0, 1e-9, 1e-6, 1e-3, 0.1, 1.0, 60.0, 1e4])


@examples(150)
@given(st.lists(st.tuples(steps, st.floats(-1e4, 1e4)), min_size=1, max_size=60), st.booleans(),
       st.floats(1e-3, 1e3), st.floats(1e-6, 10.0))
def test_any_update_sequence_keeps_the_covariance_finite_symmetric_and_psd(updates, wrap, q, r):
    f = BearingFilter(q, r, wrap=wrap)
    t = 0.0
    for dt, theta in updates:
        t += dt
        f.update(t, theta)
        assert np.all(np.isfinite(f.x)) and np.all(np.isfinite(f.P))
        assert f.P[0, 1] == f.P[1, 0]
        eig = np.linalg.eigvalsh(f.P)
        assert eig.min() >= -1e-9 * max(1.0, np.abs(f.P).max())
        th, om, sigma = f.predict(t + 0.5)
        assert math.isfinite(th) and math.isfinite(om) and math.isfinite(sigma) and sigma >= 0.0


@examples(100)
@given(st.floats(-180.0, 180.0), st.floats(-60.0, 60.0))
def test_a_constant_rate_target_is_learned_across_the_pan_wrap(theta0, w):
    f = BearingFilter(4.0, 0.04, wrap=True)
    for k in range(51):
        t = 0.1 * k
        f.update(t, wrap_deg(theta0 + w * t))   # what the tracker measures: a wrapped pan
    th, om, _ = f.predict(5.0)
    assert abs(om - w) <= 1e-3
    assert abs(deg_diff(wrap_deg(th), wrap_deg(theta0 + w * 5.0))) <= 1e-3
