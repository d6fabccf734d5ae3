"""The head-pose rotation kernel given the points' integer ns gives the bits it gives for the float
seconds ``t_ns * 1e-9`` (the loop passes the ns and no longer builds the float array)."""

import numpy as np
import pytest

from sim.world import kernels as K


@pytest.mark.parametrize("n", [1, 7, 100, 20_000])
def test_ns_and_seconds_give_the_same_bits(n):
    from gimbal.pelco import encode_pan_tilt
    from gimbal.pts303h import PTS303H, HeadParams

    head = PTS303H(HeadParams(ripple_rel=0.0), unit_seed=5, pan0_deg=179.0, tilt0_deg=10.0)
    head.receive(encode_pan_tilt(1, 1, 0xFF, 1, 0x3F), [0.01 + 0.001 * i for i in range(7)])
    head.receive(encode_pan_tilt(1, -1, 0x20, -1, 0x10), [0.52 + 0.001 * i for i in range(7)])
    rng = np.random.default_rng(n)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_ns = np.sort(rng.integers(400_000_000, 700_000_000, n))   # a command takes effect in here
    pieces = head.pose_segments(0.4, 0.7)
    assert pieces[0].shape[1] >= 2
    by_ns, by_s = np.empty_like(d), np.empty_like(d)
    K.rotate_head_pieces_kernel(d, t_ns, 0.4, 0.001, 301, pieces[0], pieces[1], by_ns)
    K.rotate_head_pieces_kernel(d, t_ns * 1e-9, 0.4, 0.001, 301, pieces[0], pieces[1], by_s)
    assert np.array_equal(by_ns.view(np.int64), by_s.view(np.int64))
    # and the pure-Python helper agrees with the kernels' conversion
    assert K._seconds(np.int64(123_456_789)) == 123_456_789 * 1e-9 and K._seconds(0.25) == 0.25
