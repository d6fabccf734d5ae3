"""A straight pass's positions from the numba kernel are its numpy expression's, to the bit, for any
number and split of the times (the closed loop asks for 1 and for a few hundred per frame)."""

import numpy as np
import pytest

from sim.world import trajectories as tr


@pytest.mark.parametrize("start, velocity", [((12.0, 2.4, 0.9), (0.0, -0.5, 0.03)),
                                             ((10, 2, 1), (0, -3, 0.5)),              # ints, as a TOML may give
                                             ((-3.7e3, 1e-9, 0.0), (123.456, -7.0e-4, -0.0))])
def test_kernel_positions_are_the_numpy_expression(start, velocity):
    s = tr.Straight(start, velocity)
    rng = np.random.default_rng(4)
    t = np.concatenate([[0.0, -0.0, 1e-300, 15.05], rng.uniform(-100.0, 3600.0, 10_001)])
    want = s.position_twin(t)
    got = s.position(t)
    assert got.shape == want.shape == (t.size, 3) and got.dtype == np.float64
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
    # in pieces (a chunk's start changes nothing), one time, a Python scalar, a list
    parts = np.concatenate([s.position(t[a:b]) for a, b in ((0, 1), (1, 9), (9, 4000), (4000, t.size))])
    assert np.array_equal(parts.view(np.int64), want.view(np.int64))
    assert np.array_equal(s.position(float(t[3])), want[3:4])
    assert np.array_equal(s.position([t[3], t[4]]), want[3:5])
    assert np.array_equal(s.velocity(t[:5]), np.broadcast_to(np.asarray(velocity, float), (5, 3)))
