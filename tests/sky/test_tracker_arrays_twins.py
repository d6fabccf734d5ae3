"""The sky tracker's fused kernels against their plain-numpy twins, bit for bit (tests/sky; the
kernels: foveatrack/openloop/kernels.py frame_objects_kernel, ...)."""

import numpy as np
import pytest

from foveatrack.openloop.objects import frame_objects, frame_objects_numpy


def _same(a, b):
    if a is None or b is None:
        assert a is None and b is None
        return
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype
    assert a.tobytes() == b.tobytes()


def _cloud(rng, n_clusters, spread):
    parts = [rng.normal(rng.uniform(-40, 40, 3), spread, (int(rng.integers(1, 12)), 3)) for _ in range(n_clusters)]
    parts.append(rng.uniform(-50, 50, (int(rng.integers(0, 20)), 3)))     # scattered single returns
    xyz = np.concatenate(parts) if parts else np.empty((0, 3))
    return xyz[rng.permutation(xyz.shape[0])]


@pytest.mark.parametrize("seed", range(40))
def test_frame_objects_equal_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    xyz = _cloud(rng, int(rng.integers(0, 12)), float(rng.choice([0.05, 0.3, 1.5])))
    if seed % 7 == 3 and xyz.shape[0]:
        xyz[rng.integers(0, xyz.shape[0])] = np.nan          # not from the tracker (it drops them), but equal
    t_ns = rng.integers(0, 100_000_000, xyz.shape[0]).astype(np.int64)
    flag = rng.random(xyz.shape[0]) < 0.3
    for min_points, max_extent, lone in ((2, 3.0, True), (1, np.inf, True), (3, 0.4, False), (2, 3.0, False)):
        got = frame_objects(xyz, t_ns, 0.5, 0.01, min_points, max_extent, flag, lone)
        want = frame_objects_numpy(xyz, t_ns, 0.5, 0.01, min_points, max_extent, flag, lone)
        for g, w in zip(got, want):
            _same(g, w)


@pytest.mark.parametrize("xyz", [np.empty((0, 3)), np.array([[10.0, 1.0, 2.0]]), np.array([[10.0, 1.0, 2.0]] * 2),
                                 np.array([[10.0, 1.0, 2.0], [60.0, 0.0, 0.0]])])
def test_frame_objects_edge_cases(xyz):
    t_ns = np.arange(xyz.shape[0], dtype=np.int64)
    for flag in (np.zeros(xyz.shape[0], bool), np.ones(xyz.shape[0], bool)):
        for min_points in (1, 2):
            got = frame_objects(xyz, t_ns, 0.5, 0.01, min_points, 3.0, flag, True)
            want = frame_objects_numpy(xyz, t_ns, 0.5, 0.01, min_points, 3.0, flag, True)
            for g, w in zip(got, want):
                _same(g, w)


class _CountingHead:
    """Pan and tilt turning at constant rates (a Reconstructor's ``angles_at``), counting its asks."""

    lidar_offset_m = (0.05, -0.02, 0.11)

    def __init__(self, pan_rate, tilt_rate):
        self.rates = pan_rate, tilt_rate
        self.asked = 0

    def angles_at(self, t):
        self.asked += 1
        return 3.0 + self.rates[0] * t, -2.0 + self.rates[1] * t, 0.0, 0.0


def _world_in_box_both(xyz, t_ns, rates, t0, t1, lo, hi):
    from foveatrack.sky.world_points import lidar_to_world_in_box, lidar_to_world_in_box_numpy

    a_head, b_head = _CountingHead(*rates), _CountingHead(*rates)
    a = lidar_to_world_in_box(xyz, t_ns, a_head, t0, t1, 11, lo, hi)
    b = lidar_to_world_in_box_numpy(xyz, t_ns, b_head, t0, t1, 11, lo, hi)
    for g, w in zip(a, b):
        _same(g, w)
    return a, a_head.asked, b_head.asked


@pytest.mark.parametrize("seed", range(12))
def test_world_in_box_equals_numpy_twin(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.choice([1, 7, 3000]))
    xyz = rng.uniform(-80, 80, (n, 3))
    # invalid points: NaN, inf, the (0, 0, 0) no-return marker
    bad = rng.random(n) < 0.1
    xyz[bad] = rng.choice([np.nan, np.inf, 0.0], (int(bad.sum()), 1))
    t0, t1 = 12.3, 12.4
    t_ns = np.sort(rng.integers(int(t0 * 1e9) - 2_000_000, int(t1 * 1e9) + 2_000_000, n)).astype(np.int64)
    lo = np.array([-30.0, -40.0, -5.0])
    hi = np.array([40.0, 20.0, 60.0])
    lo.flags.writeable = hi.flags.writeable = False        # as box_bounds gives them
    rates = tuple(rng.uniform(-100, 100, 2))
    (_, _, world), asked_kernel, asked_twin = _world_in_box_both(xyz, t_ns, rates, t0, t1, lo, hi)
    assert asked_kernel == asked_twin
    assert ((world >= lo) & (world < hi)).all()


@pytest.mark.parametrize("xyz", [np.empty((0, 3)), np.zeros((3, 3)), np.full((2, 3), np.nan),
                                 np.array([[0.0, 0.0, 0.0], [10.0, 1.0, 1.0]]), np.array([[1e3, 0.0, 0.0]])])
def test_world_in_box_edge_cases(xyz):
    # no points, none valid (the pose is not asked, as the turn of no valid points does not ask it),
    # one valid, none inside
    t_ns = np.full(xyz.shape[0], 100_000_000, np.int64)
    lo, hi = np.array([-50.0, -50.0, -50.0]), np.array([50.0, 50.0, 50.0])
    _, asked_kernel, asked_twin = _world_in_box_both(xyz, t_ns, (10.0, 0.0), 0.1, 0.2, lo, hi)
    assert asked_kernel == asked_twin
