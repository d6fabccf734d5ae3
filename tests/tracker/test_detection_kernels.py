"""The tracker's one-pass box test agrees with the generic route (valid points, turn, Box.contains)."""

import numpy as np
import pytest

from foveatrack.detection import detect_in_box, detect_points
from foveatrack.kernels import box_median_kernel, box_members_kernel
from foveatrack.detection import LEVEL
from foveatrack.reconstruction import head_trig, rotation_matrix
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
    rot, trig = rotation_matrix(pan, tilt), head_trig(pan, tilt)
    offset = np.array([0.05, -0.02, 0.1])
    idx = np.empty(n, dtype=np.int64)
    k = box_members_kernel(xyz, *trig, offset, np.array(box.min_xyz), np.array(box.max_xyz), idx)
    with np.errstate(invalid="ignore"):
        w = (xyz + offset) @ rot.T
        ref = np.isfinite(xyz).all(axis=1) & (xyz != 0).any(axis=1) & box.contains(w)
    np.testing.assert_array_equal(idx[:k], np.flatnonzero(ref))
    a = detect_in_box(xyz, t_ns, box, trig, offset)
    b = detect_points(xyz, t_ns, box, test_xyz=w)
    assert (a is None) == (b is None) == (k == 0)
    if a is not None:
        assert a.n_points == b.n_points and a.t_s == b.t_s
        np.testing.assert_array_equal(a.xyz, b.xyz)


def test_the_kernels_turn_is_rotation_matrixs_to_the_bit():
    """The kernel makes R from the pose's cosines and sines as rotation_matrix does: a box one ulp
    wide around a point turned with rotation_matrix's entries (same order of sums) holds it."""
    rng = np.random.default_rng(9)
    idx = np.empty(1, dtype=np.int64)
    for _ in range(1000):
        pan, tilt = float(rng.uniform(-400.0, 400.0)), float(rng.uniform(-90.0, 90.0))
        rot, offset, p = rotation_matrix(pan, tilt), rng.normal(0, 0.1, 3), rng.normal(0, 20, 3)
        q = p + offset
        w = np.array([rot[k, 0] * q[0] + rot[k, 1] * q[1] + rot[k, 2] * q[2] for k in range(3)])
        assert box_members_kernel(p[None, :].copy(), *head_trig(pan, tilt), offset, w, np.nextafter(w, np.inf),
                                  idx) == 1


def test_box_edges_are_half_open_like_box_contains():
    box = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    xyz = np.array([[0.0, 0.5, 0.5], [1.0, 0.5, 0.5], [0.5, 0.0, 0.999], [0.5, 0.5, 1.0]])
    idx = np.empty(4, dtype=np.int64)
    k = box_members_kernel(xyz, *LEVEL, np.zeros(3), np.zeros(3), np.ones(3), idx)
    assert list(idx[:k]) == list(np.flatnonzero(box.contains(xyz))) == [0, 2]


def _numpy_box_median(xyz, t_ns, rot, offset, lo, hi):
    """Plain-numpy twin of box_median_kernel: valid points inside the turned box, np.median."""
    with np.errstate(invalid="ignore", over="ignore"):
        w = np.stack([rot[k, 0] * (xyz[:, 0] + offset[0]) + rot[k, 1] * (xyz[:, 1] + offset[1])
                      + rot[k, 2] * (xyz[:, 2] + offset[2]) for k in range(3)], axis=1)
        keep = (np.isfinite(xyz).all(axis=1) & (xyz != 0).any(axis=1)
                & (w >= lo).all(axis=1) & (w < hi).all(axis=1))
    if not keep.any():
        return 0, None, None
    return int(keep.sum()), np.median(xyz[keep], axis=0), float(np.median(t_ns[keep].astype(np.float64)))


@pytest.mark.parametrize("pan, tilt", [(0.0, 0.0), (37.0, -12.0), (-179.0, 58.0)])
@pytest.mark.parametrize("n", [0, 1, 2, 7, 5000])
def test_box_median_kernel_matches_numpy_median(pan, tilt, n):
    xyz, t_ns = _cloud(100 + n, n)
    rot, offset = rotation_matrix(pan, tilt), np.array([0.05, -0.02, 0.1])
    trig = head_trig(pan, tilt)
    if n > 7:
        lo, hi = np.array([-5.0, -20.0, -3.0]), np.array([25.0, 10.0, 8.0])
    else:   # few points: a box around everything, so the medians see them all
        lo, hi = np.full(3, -1e9), np.full(3, 1e9)
    out = np.empty(3)
    k, t_med, hypot_xy = box_median_kernel(xyz, t_ns, *trig, offset, lo, hi, out)
    k_ref, p_ref, t_ref = _numpy_box_median(xyz, t_ns, rot, offset, lo, hi)
    assert abs(k) == k_ref
    if k_ref:
        assert k > 0 and t_med == t_ref
        assert out.tobytes() == p_ref.tobytes()
        assert hypot_xy == float(np.hypot(p_ref[0], p_ref[1]))


@pytest.mark.parametrize("x, y", [(3.0, 4.0), (1e-310, 3e-310), (1e300, 1e300), (0.1, 0.2), (-7.25, 1e-9),
                                  (123.456, -0.001)])
def test_box_median_kernels_hypot_is_numpys(x, y):
    """The kernel's hypot of the median (the elevation's denominator) has np.hypot's bits (both call
    libm's hypot; CPython's math.hypot differs in the last bit on some inputs), also where scaling
    matters (subnormal, huge), and over many random points."""
    rng = np.random.default_rng(7)
    pts = np.vstack([[x, y, 1.0], rng.normal(0, 30, (2000, 3))])
    lo, hi = np.full(3, -1e308), np.full(3, 1e308)
    for p in pts:
        out = np.empty(3)
        k, _, hypot_xy = box_median_kernel(p[None, :].copy(), np.zeros(1, np.int64), *LEVEL, np.zeros(3),
                                           lo, hi, out)
        assert k == 1 and hypot_xy == float(np.hypot(p[0], p[1]))


def test_a_zero_median_takes_numpys_route_bit_for_bit():
    """-0.0 and +0.0 tie in a sort, so a zero median's sign is the sort's choice: the kernel flags
    it and detect_in_box answers with numpy's median, sign bit included."""
    xyz = np.array([[5.0, -0.0, 1.0], [6.0, 0.0, 2.0], [7.0, 0.0, -0.0], [8.0, -0.0, 0.0], [9.0, 1.0, 0.0]])
    t_ns = np.arange(5, dtype=np.int64) * 1000
    box = Box((1.0, -5.0, -5.0), (20.0, 5.0, 5.0))
    k, _, _ = box_median_kernel(xyz, t_ns, *LEVEL, np.zeros(3), np.array(box.min_xyz), np.array(box.max_xyz),
                                np.empty(3))
    assert k == -5
    a = detect_in_box(xyz, t_ns, box, LEVEL, np.zeros(3))
    b = detect_points(xyz, t_ns, box)
    assert a.xyz.tobytes() == b.xyz.tobytes() and (a.t_s, a.n_points, a.az_deg, a.el_deg, a.range_m) == \
        (b.t_s, b.n_points, b.az_deg, b.el_deg, b.range_m)


@pytest.mark.parametrize("seed", range(5))
def test_detect_in_box_equals_detect_points_to_the_bit(seed):
    xyz, t_ns = _cloud(seed, 3000)
    box = Box((-5.0, -20.0, -3.0), (25.0, 10.0, 8.0), frame="world")
    rot, offset = rotation_matrix(20.0 * seed, 7.0 * seed), np.array([0.05, -0.02, 0.1])
    trig = head_trig(20.0 * seed, 7.0 * seed)
    # the generic route tests D on points turned exactly as the kernel turns them
    q = xyz + offset
    with np.errstate(invalid="ignore"):
            w = np.stack([rot[k, 0] * q[:, 0] + rot[k, 1] * q[:, 1] + rot[k, 2] * q[:, 2] for k in range(3)], axis=1)
    a = detect_in_box(xyz, t_ns, box, trig, offset)
    with np.errstate(invalid="ignore"):
        b = detect_points(xyz, t_ns, box, test_xyz=w)
    assert a.xyz.tobytes() == b.xyz.tobytes()
    assert (a.t_s, a.n_points, a.az_deg, a.el_deg, a.range_m) == (b.t_s, b.n_points, b.az_deg, b.el_deg, b.range_m)


_TRACKER_AFTER_COMPILE_ALL = """
import numpy as np
from foveatrack.frames import Frame
from foveatrack.detection import compile_all
from foveatrack.kernels import box_median_kernel, box_members_kernel
from foveatrack.space_of_interest import Box
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import Tracker, TrackerConfig

compile_all()
before = (len(box_median_kernel.signatures), len(box_members_kernel.signatures))
rng = np.random.default_rng(0)
for frame_name in ("lidar", "world"):
    tracker = Tracker(TrackerConfig(space=Box((1.0, -5.0, -1.0), (30.0, 5.0, 5.0), frame=frame_name)),
                      SpeedTable.nominal())
    xyz = np.array([12.0, 1.0, 0.5]) + rng.normal(0, 0.05, (50, 3))
    assert tracker.process(Frame(0.0, 0.1, xyz, np.linspace(0, 99_000_000, 50).astype(np.int64))).detection
    xyz[:, 1] = 0.0          # a zero median: the numpy route, through box_members_kernel
    tracker.process(Frame(0.1, 0.2, xyz, np.linspace(100_000_000, 199_000_000, 50).astype(np.int64)))
print(list(before), [len(box_median_kernel.signatures), len(box_members_kernel.signatures)])
"""


def test_compile_all_covers_what_the_tracker_calls():
    """The daemon compiles before data flows; if the tracker then calls a kernel with other argument
    types (numba compiles per signature: e.g. read-only D bounds), its first frame stalls for the
    compile (1.8 s, seen in a fresh clone).  In a fresh interpreter (nothing loaded yet), a tracker's
    frames after compile_all add no signature."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _TRACKER_AFTER_COMPILE_ALL], capture_output=True, text=True,
                         check=True).stdout
    before, after = out.strip().split("] [")
    assert before.lstrip("[") == after.rstrip("]"), f"signatures (median, members) before/after: {out}"


@pytest.mark.parametrize("kind", ["random", "sorted", "reversed", "ties", "two values", "huge"])
@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 10, 11, 64, 1001, 4096])
def test_the_median_selection_is_numpys_median(kind, n):
    """The box kernel's median by selection (Wirth) against np.median, bit for bit, on the orders and
    ties that break selection algorithms (sorted and reversed input, all-equal runs, two values)."""
    from foveatrack.kernels import _median_select

    rng = np.random.default_rng(n)
    a = {"random": rng.normal(0, 30, n), "sorted": np.sort(rng.normal(0, 30, n)),
         "reversed": np.sort(rng.normal(0, 30, n))[::-1].copy(), "ties": rng.integers(-3, 4, n).astype(float) + 0.5,
         "two values": np.where(rng.random(n) < 0.5, 1.25, -7.5), "huge": rng.choice([1e308, -1e308, 3.0], n)}[kind]
    with np.errstate(over="ignore"):        # "huge": numpy's mean of the two middle values overflows to inf
        want = np.median(a)
        got = _median_select(a.copy(), n)
    assert np.float64(got).tobytes() == want.tobytes(), (got, want)


@pytest.mark.parametrize("n", [0, 1, 5000])
def test_the_sky_trackers_point_tests_are_their_numpy_twins(n):
    """The sky tracker's frame tests (foveatrack.sky.tracks): valid_mask_kernel against valid_points,
    box_inside_kernel against Box.contains, point for point, on non-finite points, the no-return
    marker, signed zeros and points exactly on the box's faces."""
    from foveatrack.detection import valid_points
    from foveatrack.kernels import box_inside_kernel, valid_mask_kernel

    xyz, _ = _cloud(n + 1, n)
    rng = np.random.default_rng(n)
    box = Box((-5.0, -20.0, -3.0), (25.0, 10.0, 8.0), frame="world")
    if n:
        k = rng.integers(0, n, 60)
        xyz[k[:10]] = -0.0
        xyz[k[10:20], 0] = -0.0
        xyz[k[20:30]] = np.where(rng.random((10, 3)) < 0.5, box.min_xyz, box.max_xyz)   # on the faces
        xyz[k[30:40], 1] = np.nextafter(box.max_xyz[1], -np.inf)
    ok = np.empty(n, np.bool_)
    assert valid_mask_kernel(xyz, ok) == int(valid_points(xyz).sum())
    np.testing.assert_array_equal(ok, valid_points(xyz))
    idx = np.empty(n, np.int64)
    lo, hi = np.array(box.min_xyz), np.array(box.max_xyz)
    with np.errstate(invalid="ignore"):
        want = np.flatnonzero(box.contains(xyz))
    got = idx[:box_inside_kernel(xyz, lo, hi, idx)]
    np.testing.assert_array_equal(got, want)
    assert n < 100 or 0 < want.size < n
