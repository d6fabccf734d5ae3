"""The trajectory kernels give their numpy twins' bits: a straight pass's positions for any number
and split of the times (the closed loop asks for 1 and for a few hundred per frame), and the
heading's hover mask."""

import numpy as np
import pytest

from sim.world import trajectories as tr
from world_twins import heading_twin, straight_position_twin


def _bits(a):
    return np.ascontiguousarray(a).view(np.int64)


@pytest.mark.parametrize("start, velocity", [((12.0, 2.4, 0.9), (0.0, -0.5, 0.03)),
                                             ((10, 2, 1), (0, -3, 0.5)),              # ints, as a TOML may give
                                             ((-3.7e3, 1e-9, 0.0), (123.456, -7.0e-4, -0.0))])
def test_kernel_positions_are_the_numpy_expression(start, velocity):
    s = tr.Straight(start, velocity)
    rng = np.random.default_rng(4)
    t = np.concatenate([[0.0, -0.0, 1e-300, 15.05], rng.uniform(-100.0, 3600.0, 10_001)])
    want = straight_position_twin(start, velocity, t)
    got = s.position(t)
    assert got.shape == want.shape == (t.size, 3) and got.dtype == np.float64
    assert np.array_equal(_bits(got), _bits(want))
    # in pieces (a chunk's start changes nothing), one time, a Python scalar, a list
    parts = np.concatenate([s.position(t[a:b]) for a, b in ((0, 1), (1, 9), (9, 4000), (4000, t.size))])
    assert np.array_equal(_bits(parts), _bits(want))
    assert np.array_equal(s.position(float(t[3])), want[3:4])
    assert np.array_equal(s.position([t[3], t[4]]), want[3:5])
    assert np.array_equal(s.velocity(t[:5]), np.broadcast_to(np.asarray(velocity, float), (5, 3)))


def test_heading_kernel_is_numpys_mask():
    rng = np.random.default_rng(8)
    v = rng.normal(0.0, 3.0, (20_000, 3))
    v[::7, :2] *= 1e-5                        # hovering: |v_h|^2 around the 1e-8 threshold
    v[1::11, :2] = 0.0
    v[2::13, 0] = np.nan
    v[3::17, :2] = [7.0710678118654756e-05, 0.0]   # vx^2 a hair either side of 5e-9 ... and the edge
    v[5] = [1e-4, 0.0, 0.0]                   # exactly 1e-8: hovering (not > 1e-8)
    for default in (0.0, -1.25):
        want = heading_twin(v, default)
        got = tr.heading_rad(v, default)
        assert np.array_equal(_bits(got), _bits(want))
        assert np.array_equal(_bits(tr.heading_rad(v[5:9], default)), _bits(want[5:9]))
    assert np.sum(heading_twin(v, -1.25) == -1.25) > 2000        # the mask did act
