"""The tracker's one-pass box test agrees with the generic route (valid points, turn, Box.contains)."""

import numpy as np
import pytest

from foveatrack.detection import detect_in_box, detect_points
from foveatrack.kernels import box_members_kernel
from foveatrack.reconstruction import rotation_matrix
from foveatrack.space_of_interest import Box


def _cloud(seed, n):
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(-30, 30, (n, 3))
    bad = rng.random(n)
    xyz[bad < 0.02] = 0.0                              # Livox "no return"
    xyz[(bad >= 0.02) & (bad < 0.03), 1] = np.nan
    xyz[(bad >= 0.03) & (bad < 0.04), 2] = np.inf
    xyz[(bad >= 0.04) & (bad < 0.05), 0] = -np.inf
    return xyz, np.sort(rng.integers(0, 10**8, n))


@pytest.mark.parametrize("pan, tilt", [(0.0, 0.0), (37.0, -12.0), (-179.0, 58.0)])
@pytest.mark.parametrize("n", [0, 1, 5000])
def test_box_members_match_the_generic_route(pan, tilt, n):
    xyz, t_ns = _cloud(n, n)
    box = Box((-5.0, -20.0, -3.0), (25.0, 10.0, 8.0), frame="world")
    rot = rotation_matrix(pan, tilt)
    offset = np.array([0.05, -0.02, 0.1])
    idx = np.empty(n, dtype=np.int64)
    k = box_members_kernel(xyz, rot, offset, np.array(box.min_xyz), np.array(box.max_xyz), idx)
    with np.errstate(invalid="ignore"):
        w = (xyz + offset) @ rot.T
        ref = np.isfinite(xyz).all(axis=1) & (xyz != 0).any(axis=1) & box.contains(w)
    np.testing.assert_array_equal(idx[:k], np.flatnonzero(ref))
    a = detect_in_box(xyz, t_ns, box, rot, offset)
    b = detect_points(xyz, t_ns, box, test_xyz=w)
    assert (a is None) == (b is None) == (k == 0)
    if a is not None:
        assert a.n_points == b.n_points and a.t_s == b.t_s
        np.testing.assert_array_equal(a.xyz, b.xyz)


def test_box_edges_are_half_open_like_box_contains():
    box = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    xyz = np.array([[0.0, 0.5, 0.5], [1.0, 0.5, 0.5], [0.5, 0.0, 0.999], [0.5, 0.5, 1.0]])
    idx = np.empty(4, dtype=np.int64)
    k = box_members_kernel(xyz, np.eye(3), np.zeros(3), np.zeros(3), np.ones(3), idx)
    assert list(idx[:k]) == list(np.flatnonzero(box.contains(xyz))) == [0, 2]
