"""Presets, FoV, radial density (eq. 4) and coverage (Appendix C) of the scan model."""

import numpy as np
import pytest

from sim.scan.coverage import LIVOX_MID40_COVERAGE, footprint_coverage, swath_coverage, voxel_coverage, voxel_grid
from sim.scan.density import radial_density
from sim.scan.fov import field_of_view_deg
from sim.scan.model import ScanModel
from sim.scan.optics import OpticsError, SpeedNoise, optics_from_table
from sim.scan.presets import PRESETS


def test_mid40_exact_fov_is_the_published_38_4_deg_and_paraxial_is_smaller():
    h, v = field_of_view_deg(PRESETS["mid40"])
    assert abs(h - 38.4) <= 0.15 and abs(v - 38.4) <= 0.15
    ph, _ = field_of_view_deg(PRESETS["mid40"], model="paraxial")
    # Paraxial: 2 * 2 (n - 1) alpha = 36.72 deg, ~4.5 % small (facts file).
    assert ph == pytest.approx(4 * 0.51 * 18.0, abs=0.01)


def test_horizon_fov_channels_and_rate():
    optics = PRESETS["horizon"]
    h, v = field_of_view_deg(optics)
    assert abs(h - 81.7) <= 0.5 and abs(v - 25.1) <= 0.5
    assert optics.channels == 6 and optics.point_rate_hz == 240_000
    chunk = ScanModel(optics).scan(0, 12)
    assert list(chunk.channel) == [0, 1, 2, 3, 4, 5] * 2, "line id = point index mod 6"
    assert np.all(chunk.valid)


def test_horizon_p1_p2_sum_is_an_oscillator_along_x():
    """Paper Fig. 9b: with P3 removed, the locked pair sweeps a line (tiny exact-refraction width)."""
    optics = PRESETS["horizon"].with_(channel_offsets_deg=((0.0, 0.0),))
    model = ScanModel(optics)
    revs = model.prism_revs(0, 50_000).copy()
    revs[:, 2] = 0.0
    model3 = ScanModel(optics.with_prism(2, wedge_deg=1e-9, index=1.0000001))
    d, st = model3.directions_from_revs(revs, np.zeros(len(revs), dtype=np.int64))
    az = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    el = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    assert np.ptp(az) > 40 and np.ptp(el) < 0.1 * np.ptp(az)


def test_paraxial_density_matches_eq4_within_5_percent():
    dens = radial_density(ScanModel(PRESETS["prototype"], model="paraxial"), 1.0, bins=60)
    x = dens.centers_deg / dens.r_scale_deg
    sel = (x >= 0.1) & (x <= 1.8)
    assert np.max(np.abs(dens.relative_error[sel])) < 0.05


def test_exact_density_departs_from_eq4_as_the_wider_fov_implies():
    """Exact refraction stretches r outward (FoV 38.43 vs 36.72 deg): the mid-field density drops by
    about the square of the stretch and the rim peak moves past 2R."""
    dens = radial_density(ScanModel(PRESETS["prototype"]), 1.0, bins=60)
    x = dens.centers_deg / dens.r_scale_deg
    mid = (x > 0.3) & (x < 1.2)
    stretch = 38.432 / 36.720
    assert np.median(dens.relative_error[mid]) == pytest.approx(stretch ** -1 - 1, abs=0.03)
    assert dens.simulated[x > 2.0].sum() > 0


def test_prototype_with_speed_noise_reaches_90_percent_voxel_coverage_within_1_s():
    model = ScanModel(PRESETS["prototype"], speed_noise=SpeedNoise(sigma_frac=0.01), rng=np.random.default_rng(0))
    curve = voxel_coverage(model, 1.5)
    assert curve.t90_s is not None and curve.t90_s < 1.0
    assert np.all(np.diff(curve.coverage) >= 0)


def test_commensurable_noise_free_speeds_plateau_and_noise_breaks_the_plateau():
    optics = PRESETS["prototype"].with_prism(0, rpm=6000.0).with_prism(1, rpm=-3000.0)  # repeats every 20 ms
    grid = voxel_grid(optics)
    clean = voxel_coverage(ScanModel(optics), 1.0, grid)
    at_period = clean.coverage[np.searchsorted(clean.times_s, 0.021)]
    assert clean.coverage[-1] == at_period < 0.5, "nothing new after one repeat period"
    noisy = voxel_coverage(ScanModel(optics, speed_noise=SpeedNoise(), rng=np.random.default_rng(1)), 1.0, grid)
    assert noisy.coverage[-1] > clean.coverage[-1] + 0.2


def test_voxel_grid_is_the_papers_100_by_100_with_the_circle_counted():
    grid = voxel_grid(PRESETS["prototype"])
    assert grid.shape == (100, 100)
    # A disc inscribed in the square: pi/4 of the cells (the paper's scene-limited count is 7132).
    assert abs(grid.reachable.sum() / 10_000 - np.pi / 4) < 0.03


def test_footprint_coverage_paints_the_swept_path():
    model = ScanModel(PRESETS["mid40"])
    curve = footprint_coverage(model, 0.05, reference_rays=200_000)
    assert 0 < curve.coverage[-1] < 1 and np.all(np.diff(curve.coverage) >= 0)
    # Painting the swept path covers more than the spots alone would (substeps=1 paints only spots).
    spots = footprint_coverage(model, 0.05, substeps=1, reference_rays=200_000)
    assert curve.coverage[-1] > 1.5 * spots.coverage[-1]


def test_progress_reaches_the_total_and_changes_nothing():
    """The progress callbacks the CLI's bar uses (lidar density / coverage): monotone, ending at the
    run's sample count, and a run reporting progress gives the same result as one that does not."""
    def run(fn, **kw):
        calls = []
        res = fn(progress=lambda done, total: calls.append((done, total)), **kw)
        done, totals = [c[0] for c in calls], {c[1] for c in calls}
        assert len(totals) == 1 and done == sorted(done) and done[-1] == totals.pop()
        return res, done[-1], fn(**kw)

    model = lambda: ScanModel(PRESETS["prototype"])   # noqa: E731
    dens, n, plain = run(lambda **kw: radial_density(model(), 0.25, bins=30, **kw))
    assert n == 25_000 and np.array_equal(dens.simulated, plain.simulated)
    grid = voxel_grid(PRESETS["prototype"], reference_rays=200_000)
    cov, n, plain = run(lambda **kw: voxel_coverage(model(), 0.1, grid, **kw))
    assert n == 10_000 and np.array_equal(cov.coverage, plain.coverage)
    fp, n, plain = run(lambda **kw: footprint_coverage(model(), 0.01, substeps=3, reference_rays=100_000, **kw))
    assert n == 3_000 and np.array_equal(fp.coverage, plain.coverage)


@pytest.mark.determinism
def test_speed_noise_draws_nothing_unless_asked_and_is_independent_of_chunking():
    optics = PRESETS["prototype"]
    clean = ScanModel(optics)
    clean.scan(0, 10_000)
    assert clean.noise_draws == 0
    a = ScanModel(optics, speed_noise=SpeedNoise(drift_frac=0.001), rng=np.random.default_rng(5))
    b = ScanModel(optics, speed_noise=SpeedNoise(drift_frac=0.001), rng=np.random.default_rng(5))
    whole = a.scan(0, 300_000).direction
    parts = np.concatenate([b.scan(k, 30_000).direction for k in range(0, 300_000, 30_000)])
    assert np.array_equal(whole, parts)
    assert not np.allclose(whole, clean.scan(0, 300_000).direction)


@pytest.mark.parametrize(
    "table, message",
    [
        ({"prisms": [{"wedge_deg": 18, "index": 1.51}]}, "2 or 3"),
        ({"prisms": [{"wedge_deg": 18, "index": 1.51, "colour": 1}] * 2}, "colour"),
        ({"prisms": [{"wedge_deg": 18, "index": 0.9}] * 2}, "index"),
        ({"prisms": [{"wedge_deg": 18, "index": 1.5, "tilted_face": "both"}] * 2}, "tilted_face"),
        ({"prisms": [{"wedge_deg": 18, "index": 1.5}] * 2, "point_rate_hz": 10}, "point_rate_hz"),
    ],
)
def test_custom_optics_errors_name_the_key(table, message):
    with pytest.raises(OpticsError, match=message) as exc:
        optics_from_table(table, where="scene.toml [lidar]")
    assert "scene.toml [lidar]" in str(exc.value)


@pytest.mark.slow
def test_footprint_coverage_meets_the_reference_mid40_curve():
    """Livox's FoV coverage (``--method footprint``, the beam's 0.28 deg swath) against Livox's Mid-40
    curve at 0.1, 0.5 and 1 s (read off its figure: LIVOX_MID40_COVERAGE), within 0.05;
    the fixed-orientation footprint stays far below."""
    curve = swath_coverage(ScanModel(PRESETS["mid40"]), 1.0)
    fixed = footprint_coverage(ScanModel(PRESETS["mid40"]), 0.1)
    for t_s, reference in LIVOX_MID40_COVERAGE.items():
        got = curve.coverage[np.argmin(np.abs(curve.times_s - t_s))]
        assert abs(got - reference) <= 0.05, (t_s, got, reference)
    assert fixed.coverage[-1] < LIVOX_MID40_COVERAGE[0.1] - 0.05


def test_swath_coverage_does_not_depend_on_chunking_and_grows():
    model = lambda: ScanModel(PRESETS["tele15"])   # noqa: E731
    a = swath_coverage(model(), 0.01, reference_rays=120_000)
    b = swath_coverage(model(), 0.01, reference_rays=120_000, chunk_points=777)
    assert np.array_equal(a.coverage, b.coverage) and a.cells == b.cells
    assert 0 < a.coverage[-1] < 1 and np.all(np.diff(a.coverage) >= 0)
    with pytest.raises(ValueError, match="cell_deg"):
        swath_coverage(model(), 0.01, cell_deg=0.05)
