"""foveatrack.predictive.BearingFilter's prediction, written out in a fixed order of float operations,
is the constant-velocity model's matrix form ``F x``, ``F P F^T + Q`` (within rounding)."""

from __future__ import annotations

import math

import numpy as np

from foveatrack.predictive import BearingFilter


def test_prediction_is_the_matrix_form_within_rounding_and_symmetric():
    rng = np.random.default_rng(6)
    f = BearingFilter(q_deg2_s3=4.0, r_deg2=0.04)
    t = 0.0
    f.update(t, 10.0)
    for _ in range(300):
        t += float(rng.uniform(0.02, 0.2))
        f.update(t, 10.0 + 5.0 * t + float(rng.normal(0, 0.2)))
        dt = float(rng.uniform(-0.3, 0.5))    # also behind the last update (a late frame's time)
        x, P = f._predict_to(f.t_s + dt)
        F = np.array([[1.0, dt], [0.0, 1.0]])
        a = abs(dt)
        Q = f.q_deg2_s3 * np.array([[a**3 / 3, a**2 / 2], [a**2 / 2, a]])
        np.testing.assert_allclose(x, F @ f.x, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(P, F @ f.P @ F.T + Q, rtol=1e-13, atol=1e-15)
        assert P[0, 1] == P[1, 0]          # f.P is kept symmetric: both entries are the same sums
        assert P[0, 0] >= 0 and P[1, 1] >= 0
        theta, omega, sigma = f.predict(f.t_s + dt)
        assert (theta, omega, sigma) == (x[0], x[1], math.sqrt(P[0, 0]))
