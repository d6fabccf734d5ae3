"""Algorithm 1 (per-axis median) and the bearing/dead-band step of Algorithm 2 at their hard inputs
(paper Appendix D.2, D.3): one point, identical points, no-return (0,0,0) points, NaN/inf, a target
behind the sensor, straight overhead, and errors exactly on the dead-band edge.

Coordinates are drawn within +-1e7 m: the Livox wire format carries int32 millimetres (+-2.1e6 m),
and beyond ~1e307 the median's mean of two middle values would overflow by design of floats.

Bounds asserted
---------------
* one point / N identical points: the detection is that point exactly (bit for bit), its time the
  point's time; (0,0,0) and non-finite rows change nothing; nothing valid -> None, never NaN;
* bearings: az in (-180, 180], el in [-90, 90]; (r, az, el) maps back to the point to 1e-12 r;
  mirror images give exactly (-az, el) and (az, -el); across the -X axis (behind the sensor) the
  wrapped azimuth is continuous (jump <= the geometric angle + 1e-12 deg); exactly behind is +180;
* straight overhead (x = y = 0, either sign of zero): el = +90 and az = 0, as the control module
  documents, so the paper controller does not spin the pan axis;
* dead band: v(-e) = -v(e) exactly; |e| == db moves the head, the next float below does not; the
  whole tracker commands mirrored targets with mirrored directions and the same byte.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from foveatrack.control import deadband_p, lidar_errors_deg
from foveatrack.detection import bearing_deg, detect_points, valid_points
from foveatrack.fixed_order import norm3
from foveatrack.frames import Frame
from foveatrack.speed_table import SpeedTable
from foveatrack.tracker import Tracker, TrackerConfig
from stability_util import deg_diff, examples

coord = st.floats(-1e7, 1e7, allow_nan=False, allow_infinity=False)
nonzero_point = st.tuples(coord, coord, coord).filter(lambda p: any(v != 0.0 for v in p))
bad_value = st.sampled_from([math.nan, math.inf, -math.inf])
times = st.integers(0, 2**62)


@examples(200)
@given(nonzero_point, times)
def test_one_point_is_its_own_detection(p, t_ns):
    det = detect_points(np.array([p]), np.array([t_ns]))
    assert det is not None and det.n_points == 1
    assert np.array_equal(det.xyz, np.array(p))
    assert det.t_s == float(t_ns) * 1e-9
    assert det.range_m == norm3(p)     # the fixed-order |p|, within rounding of numpy's (BLAS's) norm
    assert abs(det.range_m - float(np.linalg.norm(p))) <= 6 * 2.0**-53 * det.range_m
    az, el = bearing_deg(*p)
    assert (det.az_deg, det.el_deg) == (az, el)


@examples(150)
@given(nonzero_point, st.integers(2, 200), st.lists(times, min_size=1, max_size=1))
def test_identical_points_give_that_point_exactly(p, n, t):
    xyz = np.tile(p, (n, 1))
    det = detect_points(xyz, np.full(n, t[0]))
    assert det is not None and det.n_points == n
    assert np.array_equal(det.xyz, np.array(p))


@st.composite
def clouds_with_junk(draw):
    good = draw(st.lists(nonzero_point, min_size=0, max_size=30))
    n_zero = draw(st.integers(0, 10))
    bad = []
    for _ in range(draw(st.integers(0, 10))):
        row = list(draw(st.tuples(coord, coord, coord)))
        row[draw(st.integers(0, 2))] = draw(bad_value)
        bad.append(row)
    rows = [list(g) for g in good] + [[0.0, 0.0, 0.0]] * n_zero + bad
    order = draw(st.permutations(range(len(rows))))
    rows = [rows[i] for i in order]
    t = draw(st.lists(st.integers(0, 10**12), min_size=len(rows), max_size=len(rows)))
    return np.array(rows, dtype=float).reshape(-1, 3), np.array(t, dtype=np.int64), len(good)


@examples(200)
@given(clouds_with_junk())
def test_no_return_and_non_finite_points_change_nothing(cloud):
    xyz, t, n_good = cloud
    keep = valid_points(xyz)
    assert keep.sum() == n_good
    det = detect_points(xyz, t)
    if n_good == 0:
        assert det is None
        return
    ref = detect_points(xyz[keep], t[keep])
    assert det.n_points == n_good
    assert np.array_equal(det.xyz, ref.xyz) and det.t_s == ref.t_s
    assert np.isfinite(det.xyz).all() and math.isfinite(det.range_m)
    assert math.isfinite(det.az_deg) and math.isfinite(det.el_deg)
    assert det.az_deg == ref.az_deg and det.el_deg == ref.el_deg
    # the median lies inside the bounding box of the retained points
    lo, hi = xyz[keep].min(axis=0), xyz[keep].max(axis=0)
    assert np.all(lo <= det.xyz) and np.all(det.xyz <= hi)


@examples(300)
@given(nonzero_point)
def test_bearing_ranges_inverse_and_mirrors(p):
    x, y, z = p
    az, el = bearing_deg(x, y, z)
    assert -180.0 < az <= 180.0 and -90.0 <= el <= 90.0
    r = math.hypot(x, y, z)
    a, e = math.radians(az), math.radians(el)
    back = np.array([r * math.cos(e) * math.cos(a), r * math.cos(e) * math.sin(a), r * math.sin(e)])
    assert np.max(np.abs(back - np.array(p))) <= 1e-12 * r
    az_m, el_m = bearing_deg(x, -y, z)
    assert el_m == el and (az_m == -az or (az == 180.0 and az_m == 180.0) or (az == 0.0 and az_m == 0.0))
    az_z, el_z = bearing_deg(x, y, -z)
    assert az_z == az and el_z == -el
    if x < 0:
        assert abs(az) >= 90.0  # behind the sensor: the paper's arctan(y/x) would say "ahead"


@examples(150)
@given(st.floats(1e-3, 1e6), st.floats(1e-300, 1e3), st.floats(-1e3, 1e3))
def test_azimuth_is_continuous_behind_the_sensor(x_back, eps, z):
    """Points just left and just right of the -X axis: wrapped azimuths differ by the true angle."""
    a1, _ = bearing_deg(-x_back, eps, z)
    a2, _ = bearing_deg(-x_back, -eps, z)
    true = 2.0 * math.degrees(math.atan2(eps, x_back))
    assert abs(abs(deg_diff(a1, a2)) - true) <= 1e-12 + 1e-12 * true
    for y0 in (0.0, -0.0):
        assert bearing_deg(-x_back, y0, z)[0] == 180.0


@pytest.mark.parametrize("x0", [0.0, -0.0])
@pytest.mark.parametrize("y0", [0.0, -0.0])
def test_straight_overhead_has_zero_pan_error(x0, y0):
    """x = y = 0 with either sign of zero (a spherical Livox point at zenith 0 and azimuth > 90 deg
    decodes to x = r sin(0) cos(az) = -0.0): el = +90, az = 0, so the paper controller's pan error
    is inside any dead band instead of +180 (full-speed pan)."""
    for z in (1e-9, 5.0, 1e7):
        az, el = bearing_deg(x0, y0, z)
        assert (az, el) == (0.0, 90.0)
        assert lidar_errors_deg([x0, y0, z]) == (0.0, 90.0)
        assert deadband_p(lidar_errors_deg([x0, y0, z])[0], 2.0, 2.0) == 0.0
        assert bearing_deg(x0, y0, -z) == (0.0, -90.0)


def test_overhead_point_from_a_spherical_packet():
    """The chain Livox spherical packet -> decode -> Algorithm 1: zenith 0, azimuth 180 deg."""
    from foveatrack.livox import protocol as lp

    arr = np.zeros(1, dtype=lp.packet_dtype(1))
    arr["hdr"]["version"] = lp.DATA_VERSION
    arr["hdr"]["data_type"] = 1
    arr["pts"]["depth"][0, 0] = 5000
    arr["pts"]["zenith"][0, 0] = 0
    arr["pts"]["azimuth"][0, 0] = 18000
    batch = lp.decode_packet(arr.tobytes(), 100_000)
    det = detect_points(batch.xyz, batch.t_ns)
    assert det.el_deg == 90.0 and det.az_deg == 0.0


@examples(100)
@given(st.floats(5.0, 50.0), st.floats(-1e3, 1e3))
def test_elevation_is_continuous_at_the_zenith(z, eps_sign):
    eps = eps_sign * 1e-6
    _, el = bearing_deg(eps, 0.0, z)
    assert 90.0 - el <= math.degrees(abs(eps) / z) * (1 + 1e-12) + 1e-12


@examples(300)
@given(st.floats(-720.0, 720.0), st.floats(0.0, 20.0), st.floats(0.0, 100.0))
def test_deadband_is_symmetric_and_the_edge_moves(e, db, gain):
    v = deadband_p(e, db, gain)
    assert deadband_p(-e, db, gain) == -v
    if abs(e) < db:
        assert v == 0.0
    else:
        assert v == gain * e
    if db > 0 and gain * db > 0:
        assert deadband_p(db, db, gain) == gain * db != 0.0
        assert deadband_p(-db, db, gain) == -gain * db
        below = math.nextafter(db, 0.0)
        assert deadband_p(below, db, gain) == 0.0 and deadband_p(-below, db, gain) == 0.0


def _frame(p):
    return Frame(0.0, 0.1, np.array([p], float), np.array([50_000_000], np.int64))


@examples(60)
@given(st.floats(10.0, 500.0), st.one_of(st.floats(0.01, 50.0), st.just(2.0)), st.floats(-0.2, 0.2), st.booleans())
def test_tracker_dead_band_edge_is_symmetric(x, y_frac, z_frac, on_edge):
    """Through the whole tracker: the dead band is set to exactly the target's azimuth error (on the
    edge: the head moves) or one float above it (inside: it does not); the mirrored target gets the
    mirrored pan direction and the same speed byte.  (Before wrap_deg returned in-range angles
    unchanged, x = 1, y = +-2 broke this: +63.434948822922024 vs -63.43494882292201, one ulp apart,
    so the left target moved the head and the right one did not.)"""
    p = (x, y_frac * x, z_frac * x)
    e_pan, _ = lidar_errors_deg(p)
    db = e_pan if on_edge else math.nextafter(e_pan, math.inf)
    outs = []
    for q in (p, (p[0], -p[1], p[2])):
        cfg = TrackerConfig(deadband_pan_deg=db, deadband_tilt_deg=90.0, gain_pan_1_s=1.0)
        outs.append(Tracker(cfg, SpeedTable.nominal()).process(_frame(q)))
    a, b = outs
    assert a.error_pan_deg == -b.error_pan_deg
    if on_edge:
        assert a.command.pan_dir == 1 and b.command.pan_dir == -1
        assert a.command.pan_byte == b.command.pan_byte
    else:
        assert a.command.pan_dir == 0 and b.command.pan_dir == 0


@pytest.mark.parametrize("y0", [0.0, -0.0, 1e-9, -1e-9])
def test_target_behind_turns_the_head_the_short_way(y0):
    """A target behind the sensor: finite errors near +-180, the pan axis turns toward it at a
    known speed byte (exactly behind: left, as the control module documents)."""
    out = Tracker(TrackerConfig(), SpeedTable.nominal()).process(_frame((-50.0, y0, 1.0)))
    assert math.isfinite(out.error_pan_deg) and abs(out.error_pan_deg) > 179.0
    expect = -1 if y0 < 0 else 1  # exactly behind (y = +-0): atan2 gives +-180, wrapped to +180 -> left
    assert out.command.pan_dir == expect
    assert math.isfinite(SpeedTable.nominal().pan.speed_deg_s(out.command.pan_byte))
