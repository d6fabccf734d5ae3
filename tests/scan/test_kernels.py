"""The numba kernels against their plain-numpy twins (tests/scan_twins.py), to 1e-12."""

from fractions import Fraction

import numpy as np
import pytest

from scan_twins import (
    add_speed_noise_twin,
    paint_footprint_twin,
    paint_swath_twin,
    first_hit_twin,
    phase_revs_twin,
    point_times_ns_twin,
    trace_exact_twin,
    trace_paraxial_twin,
)
from sim.scan import kernels as K
from sim.scan.model import ScanModel
from sim.scan.optics import Prism, RisleyOptics
from sim.scan.presets import PRESETS


def _random_optics_arrays(rng, p_count, c_count, max_offset_deg):
    wedge = np.radians(rng.uniform(15, 45, p_count))
    index = rng.uniform(1.4, 2.2, p_count)
    exit_tilted = rng.random(p_count) < 0.5
    off = np.radians(rng.uniform(-max_offset_deg, max_offset_deg, (c_count, 2)))
    inc = np.column_stack([np.tan(off[:, 0]), np.tan(off[:, 1]), np.ones(c_count)])
    inc /= np.linalg.norm(inc, axis=1, keepdims=True)
    return np.sin(wedge), np.cos(wedge), index, exit_tilted, inc


@pytest.mark.parametrize("p_count", [2, 3])
def test_exact_trace_matches_twin_on_random_rays_including_tir(p_count):
    seen = np.zeros(3, dtype=np.int64)
    for seed in range(12):
        rng = np.random.default_rng([p_count, seed])
        n = 4_000
        # Steep wedges, high indices and large incident offsets: many optics hit TIR on some rays.
        sw, cw, idx, ex, inc = _random_optics_arrays(rng, p_count, 8, 19.0)
        revs = rng.random((n, p_count))
        ch = rng.integers(0, 8, n)
        out = np.empty((n, 3))
        st = np.empty(n, dtype=np.uint8)
        K.trace_exact_kernel(np.ascontiguousarray(revs.T), ch, inc, sw, cw, idx, ex, out, st)
        ref, ref_st = trace_exact_twin(revs, ch, inc, sw, cw, idx, ex)
        assert np.array_equal(st, ref_st)
        np.testing.assert_allclose(out, ref, rtol=0, atol=1e-12)
        ok = st == K.RAY_OK
        np.testing.assert_allclose(np.linalg.norm(out[ok], axis=1), 1.0, atol=1e-12)
        assert np.all(out[~ok] == 0.0), "invalid rays carry a zero direction, never NaN"
        seen += np.bincount(st, minlength=3)[:3]
    assert seen[K.RAY_OK] > 1000 and seen[K.RAY_TIR] > 1000, f"the random set must exercise both: {seen}"


def test_exact_trace_just_short_of_and_just_past_tir():
    """One prism, exit face tilted: TIR at the exit face when n sin(theta_inside) > 1.  Bisect the
    incidence offset at which that happens and probe 1e-9 deg either side."""
    n_glass, wedge = 1.5, np.radians(40.0)
    sw, cw = np.array([np.sin(wedge)]), np.array([np.cos(wedge)])

    def status_at(offset_deg):
        off = np.radians(offset_deg)
        inc = np.array([[np.tan(off), 0.0, 1.0]])
        inc /= np.linalg.norm(inc)
        revs = np.zeros((1, 1))
        out, st = np.empty((1, 3)), np.empty(1, dtype=np.uint8)
        K.trace_exact_kernel(revs, np.zeros(1, dtype=np.int64), inc, sw, cw, np.array([n_glass]), np.array([True]), out, st)
        ref, ref_st = trace_exact_twin(revs.T, np.zeros(1, dtype=np.int64), inc, sw, cw, np.array([n_glass]), np.array([True]))
        return st[0], out[0], ref_st[0], ref[0]

    lo, hi = -30.0, 30.0  # the ray is refracted at lo and reflected at hi (offset toward +x raises incidence)
    assert status_at(lo)[0] == K.RAY_OK and status_at(hi)[0] == K.RAY_TIR
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if status_at(mid)[0] == K.RAY_OK:
            lo = mid
        else:
            hi = mid
    for offset in (lo - 1e-9, hi + 1e-9):
        st, out, ref_st, ref = status_at(offset)
        assert st == ref_st
        np.testing.assert_allclose(out, ref, atol=1e-12)
    st, out, _, _ = status_at(lo - 1e-9)
    # Just short of TIR the ray leaves at grazing: ~90 deg from the exit-face normal, still unit.
    assert st == K.RAY_OK and abs(np.linalg.norm(out) - 1) < 1e-12


def test_paraxial_trace_matches_twin():
    rng = np.random.default_rng(7)
    n = 10_000
    revs = rng.random((n, 3))
    ch = rng.integers(0, 6, n)
    off = np.radians(rng.uniform(-3, 3, (6, 2)))
    dev = np.radians(rng.uniform(1, 15, 3))
    out = np.empty((n, 3))
    K.trace_paraxial_kernel(np.ascontiguousarray(revs.T), ch, off, dev, out)
    np.testing.assert_allclose(out, trace_paraxial_twin(revs, ch, off, dev), atol=1e-12)


@pytest.mark.parametrize("k0", [0, 123_456_789, 8_640_000_000, 2**45 + 12345])
def test_phase_kernel_is_exact_at_any_index(k0):
    optics = PRESETS["horizon"]
    model = ScanModel(optics)
    count = 64
    got = model.prism_revs(k0, count)
    exact = phase_revs_twin(k0, [optics.revs_per_point(i) for i in range(3)], model._phase0_rev, count)
    diff = (got - exact + 0.5) % 1.0 - 0.5
    assert np.max(np.abs(diff)) * 2 * np.pi < 1e-12


def test_beam_direction_after_24_hours_agrees_with_exact_reference_to_1e9_rad():
    optics = PRESETS["prototype"]
    model = ScanModel(optics)
    k = 24 * 3600 * optics.point_rate_hz + 7  # a point 24 h into the run
    chunk = model.scan(k, 4)
    # Reference: prism angles from exact rational arithmetic, then one float trace.
    revs = np.array([[float((Fraction(k + j) * optics.revs_per_point(p)) % 1) for p in range(2)] for j in range(4)])
    ref, _ = trace_exact_twin(revs, np.zeros(4, dtype=np.int64), model._incident, model._sin_wedge,
                              model._cos_wedge, model._index, model._exit_tilted)
    angle = np.linalg.norm(chunk.direction - ref, axis=1)  # chord = angle for tiny angles; arccos would lose 1e-8
    assert np.max(angle) < 1e-9
    assert chunk.t_ns[0] == (k * 10**9) // optics.point_rate_hz


def test_point_times_are_exact_integers():
    for rate in (100_000, 240_000, 300_000):
        for k0 in (0, 10**12 + 3):
            got = np.empty(100, dtype=np.int64)
            K.point_times_ns_kernel(k0, rate, got)
            assert np.array_equal(got, point_times_ns_twin(k0, rate, 100))


def test_first_hit_matches_twin():
    rng = np.random.default_rng(3)
    first = np.full(500, -1, dtype=np.int64)
    first[:50] = 7  # already hit earlier
    cells = rng.integers(-1, 500, 5_000)
    ref, ref_new = first_hit_twin(cells, 1000, first)
    new = K.first_hit_kernel(cells, 1000, first)
    assert new == ref_new and np.array_equal(first, ref)


def test_single_prism_deviation_matches_facts():
    """shared/facts/risley-optics.md: one 18 deg, n 1.51 prism deviates 9.81 (exit) / 9.37 (entry)."""
    for face, expected in (("exit", 9.81), ("entry", 9.37)):
        optics = RisleyOptics(prisms=(Prism(18, 1.51, face), Prism(1e-9, 1.0001, "exit")))
        d, st = ScanModel(optics).directions_from_revs(np.zeros((1, 2)), np.zeros(1, dtype=np.int64))
        assert st[0] == K.RAY_OK
        assert abs(np.degrees(np.arccos(d[0, 0])) - expected) < 0.005
        assert d[0, 1] > 0, "phase 0 deflects toward +x_opt = lidar +Y (left)"


def test_footprint_painting_matches_twin():
    rng = np.random.default_rng(11)
    az = rng.uniform(-1, 1, 300)
    el = rng.uniform(-0.5, 0.5, 300)
    shape = (80, 150)
    first = np.full(shape, -1, dtype=np.int64)
    new = K.paint_footprint_kernel(az, el, 50, 0.14, 0.015, -1.1, -0.6, 0.015, first)
    ref = paint_footprint_twin(az, el, 50, 0.14, 0.015, -1.1, -0.6, 0.015, shape)
    assert np.array_equal(first, ref) and new == int((ref >= 0).sum()) > 0


def test_speed_noise_kernel_matches_twin():
    rng = np.random.default_rng(6)
    cum = np.vstack([np.zeros((1, 2)), np.cumsum(rng.normal(0, 0.01, (50, 2)), axis=0) * 0.01])
    eps = rng.normal(0, 0.01, (51, 2))
    revs = rng.random((2, 3000))
    want = add_speed_noise_twin(12_345, 100_000.0, 0.01, cum, eps, np.array([121.6, -77.7]), revs)
    K.add_speed_noise_kernel(12_345, 100_000.0, 0.01, cum, eps, 0, np.array([121.6, -77.7]), revs)
    d = (revs - want + 0.5) % 1 - 0.5
    assert np.max(np.abs(d)) < 1e-12


def test_swath_painting_matches_twin_and_sweeps_a_strip_of_its_width():
    rng = np.random.default_rng(12)
    u = rng.uniform(-1, 1, 300)
    v = rng.uniform(-0.5, 0.5, 300)
    shape = (70, 130)
    first = np.full(shape, -1, dtype=np.int64)
    new = K.paint_swath_kernel(u, v, 7, 0.14, -1.2, -0.7, 0.02, first)
    ref = paint_swath_twin(u, v, 7, 0.14, -1.2, -0.7, 0.02, shape)
    assert np.array_equal(first, ref) and new == int((ref >= 0).sum()) > 0
    # painted in another order (the later half first) the cells keep the smallest index
    again = np.full(shape, -1, dtype=np.int64)
    K.paint_swath_kernel(u[150:], v[150:], 157, 0.14, -1.2, -0.7, 0.02, again)
    K.paint_swath_kernel(u[:150], v[:150], 7, 0.14, -1.2, -0.7, 0.02, again)
    assert np.array_equal(again, ref)
    # a straight path 2 deg long, samples 0.01 deg apart: a 0.28 deg strip with round ends
    t = np.arange(0, 2.0 + 1e-9, 0.01)
    for ang in (0.0, 0.6, np.pi / 2):
        strip = np.full((300, 300), -1, dtype=np.int64)
        n = K.paint_swath_kernel(t * np.cos(ang) - 1, t * np.sin(ang) - 1, 0, 0.14, -1.5, -1.5, 0.01, strip)
        area = n * 0.01**2
        want = 2.0 * 0.28 + np.pi * 0.14**2
        assert abs(area / want - 1) < 0.02, (ang, area, want)


def test_times_past_the_int64_nanosecond_clock_are_refused():
    """floor(k * 1e9 / rate) past int64 (about 292 years of scanning) is an error, not a silent wrap
    (802524f wrapped); the last index that fits still gives its exact time, on every route."""
    from sim.scan.model import ScanModel
    from sim.scan.presets import PRESETS
    from sim.scan.spinning import SPINNING_PRESETS, SpinningScanModel

    m = ScanModel(PRESETS["mid40"])
    rate = PRESETS["mid40"].point_rate_hz
    k_last = ((2**63 - 1) * rate) // 10**9   # the last index whose time fits
    assert int(m.times_ns(k_last - 1, 2)[-1]) == (k_last * 10**9) // rate
    for call in (lambda: m.times_ns(k_last, 2), lambda: m.scan(k_last, 2), lambda: m.scan_composed(k_last, 2)):
        with pytest.raises(ValueError, match="int64"):
            call()
    spin = SpinningScanModel(next(iter(SPINNING_PRESETS.values())))
    k = 10**10   # k * 1e9 alone would pass int64; the time itself fits
    got = spin.scan(k, 3).t_ns
    assert [int(x) for x in got] == [((k + j) * 10**9) // spin.optics.point_rate_hz for j in range(3)]
