"""The fused scan kernel (``scan_exact_kernel``, used by ``ScanModel.scan``) against the composed path.

Two routes must agree: the kernel against the twins composed from the per-stage twins (exact rational
phases), and ``ScanModel.scan`` against ``ScanModel.scan_composed`` (the separate kernels), to 1e-12 in
direction with times, channels, statuses and the noise draws identical.
"""

import math

import numpy as np
import pytest

from scan_twins import scan_exact_twin
from sim.scan import kernels as K
from sim.scan.model import ScanModel
from sim.scan.optics import Prism, RisleyOptics, SpeedNoise
from sim.scan.presets import PRESETS

DAY_300K = 24 * 3600 * 300_000  # a point 24 h into a run at 300 kHz


def _kernel(model, k0, count, noise_on):
    t_ns = np.empty(count, dtype=np.int64)
    channel = np.empty(count, dtype=np.uint8)
    direction = np.empty((count, 3))
    status = np.empty(count, dtype=np.uint8)
    seg = model.speed_noise.segment_s if noise_on else 1.0
    K.scan_exact_kernel(k0, model.optics.point_rate_hz, model._r_h1, model._r_h2, model._r_lo, model._phase0_rev,
                        noise_on, seg, model._noise_cum, model._noise_eps, model._noise_seg0, model._rev_per_s,
                        model.optics.channels, model._incident, model._sin_wedge, model._cos_wedge, model._index, model._exit_tilted,
                        t_ns, channel, direction, status)
    return t_ns, channel, direction, status


def _twin(model, k0, count, noise_on):
    o = model.optics
    noise = (model.speed_noise.segment_s, model._noise_cum, model._noise_eps, model._rev_per_s) if noise_on else None
    return scan_exact_twin(k0, count, o.point_rate_hz, [o.revs_per_point(i) for i in range(model.prism_count)],
                           model._phase0_rev, noise, o.channels, model._incident, model._sin_wedge,
                           model._cos_wedge, model._index, model._exit_tilted)


def _assert_same(got, want):
    t, c, d, s = got
    t2, c2, d2, s2 = want
    assert np.array_equal(t, t2), "times must be identical integers"
    assert np.array_equal(c, c2) and np.array_equal(s, s2)
    np.testing.assert_allclose(d, d2, rtol=0, atol=1e-12)
    assert np.all(d[s != K.RAY_OK] == 0.0)


# Near-TIR optics: wedge 35 deg, n 1.51, both exit faces tilted: ~40 % of phases are TIR, so many
# rays sit close to the boundary; three prisms of mixed faces at a rate that does not divide 1e9.
NEAR_TIR = RisleyOptics(prisms=(Prism(35.0, 1.51, "exit", 6000.0), Prism(35.0, 1.51, "exit", -4100.0)))
THREE_ODD_RATE = RisleyOptics(
    prisms=(Prism(20.0, 1.6, "entry", 5021.5, 10.0), Prism(14.0, 1.5, "exit", -3303.25), Prism(9.0, 1.7, "exit", 977.0)),
    point_rate_hz=299_993, channel_offsets_deg=((0.0, -1.0), (0.5, 0.0), (0.0, 1.0)),
)
OPTICS = {"mid40": PRESETS["mid40"], "horizon": PRESETS["horizon"], "near_tir": NEAR_TIR, "three_odd": THREE_ODD_RATE}


@pytest.mark.parametrize("name", sorted(OPTICS))
@pytest.mark.parametrize("noise_on", [False, True])
def test_fused_kernel_matches_the_composed_twins(name, noise_on):
    """Random k0 (up to 24 h at 300 kHz and 2^40 without noise), n not a multiple of 256, n = 0 and 1, against exact
    rational phases.  Noise segments of 1.37 ms span block boundaries (several per 256-ray block)."""
    optics = OPTICS[name]
    rng = np.random.default_rng([len(name), noise_on])
    seg = 0.00137
    # With noise the huge index stays ~100 s in (the segment tables grow with time: 24 h would be 6e7 rows).
    huge = 3 * 10**7 + 13 if noise_on else DAY_300K + 13
    for k0, count in [(0, 0), (7, 1), (int(rng.integers(0, 10**7)), 777), (huge, 300)]:
        model = ScanModel(optics, speed_noise=SpeedNoise(segment_s=seg) if noise_on else None,
                          rng=np.random.default_rng(1) if noise_on else None)
        if noise_on:
            model._grow_noise(int(math.floor((k0 + count) / optics.point_rate_hz / seg)) + 2)
        _assert_same(_kernel(model, k0, count, noise_on), _twin(model, k0, count, noise_on))
    model = ScanModel(optics)  # noise-free only: 2^40 points would need ~10^6 noise segments
    _assert_same(_kernel(model, 2**40 + 5, 300, False), _twin(model, 2**40 + 5, 300, False))


def test_fused_kernel_sees_both_statuses_on_the_near_tir_optics():
    model = ScanModel(NEAR_TIR)
    _, _, _, status = _kernel(model, 12_345, 5000, False)
    frac = np.mean(status == K.RAY_OK)
    assert 0.3 < frac < 0.8, frac


def _pair(optics, noise, seed=4):
    """Two models with one seed: one scans fused, the other composed."""
    if noise is None:
        return ScanModel(optics), ScanModel(optics)
    return (ScanModel(optics, speed_noise=noise, rng=np.random.default_rng(seed)),
            ScanModel(optics, speed_noise=noise, rng=np.random.default_rng(seed)))


def _assert_chunks_equal(a, b):
    assert a.k0 == b.k0 and len(a) == len(b)
    assert np.array_equal(a.t_ns, b.t_ns) and a.t_ns.dtype == b.t_ns.dtype
    assert np.array_equal(a.channel, b.channel) and a.channel.dtype == b.channel.dtype
    assert np.array_equal(a.status, b.status)
    np.testing.assert_allclose(a.direction, b.direction, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", sorted(OPTICS))
@pytest.mark.parametrize("segment_s", [None, 0.01, 0.00093])
def test_scan_equals_scan_composed_chunk_by_chunk(name, segment_s):
    """Consecutive chunks of odd sizes (noise segments and 256-ray blocks straddle chunk ends), the same
    noise draws in the same order, then a jump to 24 h (noise-free) and the empty / one-point scans."""
    optics = OPTICS[name]
    noise = None if segment_s is None else SpeedNoise(segment_s=segment_s)
    fused, composed = _pair(optics, noise)
    assert fused.fused
    k = 3
    for count in (1000, 2345, 1, 0, 4097):
        _assert_chunks_equal(fused.scan(k, count), composed.scan_composed(k, count))
        assert fused.noise_draws == composed.noise_draws
        k += count
    if noise is not None:
        assert fused.noise_draws > 0
        assert np.array_equal(fused._noise_eps, composed._noise_eps)
    else:
        _assert_chunks_equal(fused.scan(DAY_300K + 99, 1500), composed.scan_composed(DAY_300K + 99, 1500))


def test_scan_time_is_fused_and_equals_the_composed_path_for_a_scene_frame():
    from sim.scene import load_scene
    from sim.sensor import scene_scan_model

    scene = load_scene("scenes/fig12-tracking.toml")
    fused, composed = scene_scan_model(scene), scene_scan_model(scene)
    assert fused.fused and fused.speed_noise is not None
    for t0 in (0.0, 0.1, 12.3):
        a = fused.scan_time(t0, t0 + 0.1)
        b = composed.scan_composed(a.k0, len(a))
        assert len(a) == 10_000
        _assert_chunks_equal(a, b)
    assert fused.noise_draws == composed.noise_draws > 0


def test_drift_and_paraxial_keep_the_composed_path():
    drift = ScanModel(PRESETS["mid40"], speed_noise=SpeedNoise(drift_frac=0.001), rng=np.random.default_rng(2))
    assert not drift.fused and not ScanModel(PRESETS["mid40"], model="paraxial").fused
    other = ScanModel(PRESETS["mid40"], speed_noise=SpeedNoise(drift_frac=0.001), rng=np.random.default_rng(2))
    a, b = drift.scan(500, 3000), other.scan_composed(500, 3000)
    assert np.array_equal(a.direction, b.direction) and drift.noise_draws == other.noise_draws


@pytest.mark.parametrize("rate", [1_000, 100_000, 240_000, 299_993, 300_000, 1_999_999, 2_000_000])
def test_fused_times_are_the_exact_integer_floor(rate):
    """floor(k 1e9 / rate) for rates that do and do not divide 1e9 (the float division in the block is
    exact because N = R0 + i 1e9 < 2^53, see ``_scan_block_setup``), up to k ~ 2^45 or 31 years."""
    optics = PRESETS["mid40"].with_(point_rate_hz=rate)
    model = ScanModel(optics)
    for k0 in (0, rate - 3, 10**12 + 3, min(2**45, 10**9 * rate) + 12345):  # t_ns < 2^63: k < 292 years
        t = model.scan(k0, 600).t_ns
        want = np.array([((k0 + j) * 10**9) // rate for j in range(600)], dtype=np.int64)
        assert np.array_equal(t, want)


def test_scan_after_24_hours_has_the_exact_phase():
    """A 24 h point: the fused direction agrees with the one traced from exact rational phases to 1e-12
    (the block increment adds at most 255 |r| 2^-52 rev to the exact block-start phase)."""
    optics = PRESETS["horizon"]
    model = ScanModel(optics)
    k0 = 24 * 3600 * optics.point_rate_hz + 11
    got = model.scan(k0, 600)
    _, _, want, _ = _twin(model, k0, 600, False)
    assert np.max(np.linalg.norm(got.direction - want, axis=1)) < 1e-12


@pytest.mark.determinism
@pytest.mark.parametrize("preset", ["mid40", "horizon"])
def test_chunking_does_not_change_a_bit(preset):
    # Blocks are anchored at absolute multiples of 256 points: the closed loop (100 ms frames) and
    # the virtual lidar (packets of any size) must produce the very same directions.
    def model():
        return ScanModel(PRESETS[preset], speed_noise=SpeedNoise(sigma_frac=0.01, segment_s=0.0037),
                         rng=np.random.default_rng(3))

    k0, n = 123_457, 30_001
    whole = model().scan(k0, n)
    m = model()
    cuts = [k0, k0 + 1, k0 + 97, k0 + 256 * 7 + 3, k0 + 20_000, k0 + n]
    parts = [m.scan(a, b - a) for a, b in zip(cuts[:-1], cuts[1:])]
    assert np.array_equal(np.concatenate([p.direction for p in parts]), whole.direction)
    assert np.array_equal(np.concatenate([p.t_ns for p in parts]), whole.t_ns)


def test_speed_noise_tables_stay_bounded_on_long_runs_with_the_same_points(monkeypatch):
    """Segments far behind the scan are dropped (a day at 10 ms segments held 280 MB); the points do
    not change, and asking for a dropped time is an error naming it.  Small table limits stand in for
    the real 65 536 segments (about 11 min at 10 ms)."""
    noise = SpeedNoise(segment_s=0.001)
    kept = ScanModel(PRESETS["mid40"], speed_noise=noise, rng=np.random.default_rng(4))
    full = ScanModel(PRESETS["mid40"], speed_noise=noise, rng=np.random.default_rng(4))
    monkeypatch.setattr(kept, "_NOISE_KEEP", 50)
    monkeypatch.setattr(kept, "_NOISE_GROW_MAX", 64)
    monkeypatch.setattr(full, "_NOISE_KEEP", 10**9)
    monkeypatch.setattr(full, "_NOISE_GROW_MAX", 64)
    rows = []
    for k in range(0, 200_000, 10_000):          # 2 s in 100 ms frames: 2000 segments
        a, b = kept.scan(k, 10_000), full.scan(k, 10_000)
        assert np.array_equal(a.direction, b.direction) and np.array_equal(a.t_ns, b.t_ns)
        rows.append(kept._noise_eps.shape[0])
    assert kept._noise_seg0 > 0 and max(rows) <= 3 * 50 + 64 + 200
    assert full._noise_eps.shape[0] >= 2000
    with pytest.raises(ValueError, match="older than the kept motor-speed noise"):
        kept.scan(0, 10)
    assert np.array_equal(kept.scan_composed(190_000, 500).direction, full.scan_composed(190_000, 500).direction)
