"""The per-point turn into the world (foveatrack/sky/world_points.py): the numba kernel against its
numpy twin, bit for bit, and against the exact rotation at each point's time."""

from __future__ import annotations

import numpy as np
import pytest

from foveatrack.reconstruction import rotation_matrix
from foveatrack.sky.world_points import lidar_to_world_per_point, lidar_to_world_per_point_numpy


class _TurningHead:
    """Pan and tilt turning at constant rates: ``angles_at`` as a Reconstructor has it."""

    lidar_offset_m = (0.05, -0.02, 0.11)

    def __init__(self, pan_rate, tilt_rate):
        self.rates = pan_rate, tilt_rate

    def angles_at(self, t):
        return 3.0 + self.rates[0] * t, -2.0 + self.rates[1] * t, 0.0, 0.0


@pytest.mark.parametrize("rates", [(0.0, 0.0), (60.0, -20.0), (-100.0, 2.0)])
def test_the_kernel_equals_its_numpy_twin_bit_for_bit(rates):
    rng = np.random.default_rng(5)
    n = 20_000
    xyz = rng.uniform(-80, 80, (n, 3))
    t0, t1 = 12.3, 12.4
    # times inside the frame, and a few just outside it (clipped to the end nodes)
    t_ns = np.sort(rng.integers(int(t0 * 1e9) - 2_000_000, int(t1 * 1e9) + 2_000_000, n)).astype(np.int64)
    pose = _TurningHead(*rates)
    a = lidar_to_world_per_point(xyz, t_ns, pose, t0, t1, 11)
    b = lidar_to_world_per_point_numpy(xyz, t_ns, pose, t0, t1, 11)
    assert a.tobytes() == b.tobytes()


def test_each_point_turns_at_its_own_time():
    pose = _TurningHead(100.0, -30.0)
    t0, t1 = 0.0, 0.1
    t_ns = np.array([0, 25_000_000, 50_000_000, 99_000_000], np.int64)
    xyz = np.tile([[100.0, 0.0, 0.0]], (4, 1))
    got = lidar_to_world_per_point(xyz, t_ns, pose, t0, t1, 11)
    for k, t in enumerate(t_ns * 1e-9):
        p, tl, _, _ = pose.angles_at(t)
        want = rotation_matrix(p, tl) @ (xyz[k] + np.array(pose.lidar_offset_m))
        # the blend of two nodes 10 ms apart: within (w dt)^2 / 8 of the rotation (module docstring),
        # w the head's whole turn rate (here sqrt(100^2 + 30^2) deg/s), times the point's range
        w_dt = np.radians(np.hypot(100.0, 30.0)) * 0.01
        assert np.linalg.norm(got[k] - want) <= w_dt ** 2 / 8 * np.linalg.norm(want) * 1.01


def test_no_points_give_no_points():
    assert lidar_to_world_per_point(np.empty((0, 3)), np.empty(0, np.int64), _TurningHead(0, 0), 0.0, 0.1).shape == (0, 3)


def test_a_frame_of_no_length_turns_every_point_at_its_one_pose():
    # t1 == t0 (a frame of a single instant): no node spacing to divide by; every point takes the
    # pose at t0, in the kernel and in its twin
    pose = _TurningHead(60.0, -20.0)
    xyz = np.array([[50.0, 1.0, 2.0], [10.0, -3.0, 0.5]])
    t_ns = np.array([1_600_000_000, 1_600_000_000], np.int64)
    a = lidar_to_world_per_point(xyz, t_ns, pose, 1.6, 1.6, 11)
    b = lidar_to_world_per_point_numpy(xyz, t_ns, pose, 1.6, 1.6, 11)
    p, tl, _, _ = pose.angles_at(1.6)
    want = (rotation_matrix(p, tl) @ (xyz + np.array(pose.lidar_offset_m)).T).T
    assert a.tobytes() == b.tobytes() and np.allclose(a, want, rtol=0, atol=1e-9)


def test_the_node_rotations_are_rotation_entries_bit_for_bit():
    """rotation_entries_kernel (every node's rotation in one call) against its twin, rotation_entries,
    pose by pose: pans inside (-180, 180] and out of it (wrapped), at +-180, far round, huge and NaN."""
    from foveatrack.reconstruction import rotation_entries
    from foveatrack.sky.world_points import rotation_entries_kernel

    rng = np.random.default_rng(8)
    pans = np.concatenate([rng.uniform(-180.0, 180.0, 2000), rng.uniform(-2000.0, 2000.0, 2000),
                           [180.0, -180.0, 0.0, -0.0, 540.0, -540.0, 179.99999999999997, -179.99999999999997,
                            1e17, -1e17, np.nan]])
    tilts = np.concatenate([rng.uniform(-90.0, 90.0, pans.size - 3), [np.nan, 0.0, -0.0]])
    angles = np.column_stack([pans, tilts])
    out = np.empty((angles.shape[0], 3, 3))
    rotation_entries_kernel(angles, out)
    want = np.array([rotation_entries(p, t) for p, t in angles.tolist()]).reshape(-1, 3, 3)
    assert out.tobytes() == want.tobytes()
