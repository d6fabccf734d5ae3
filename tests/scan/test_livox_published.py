"""Our presets against Livox's published FoV-coverage curves (issue 27, part 1), and the Horizon's
line spacing against Livox's stated figures.  The curves are read off the Livox wiki's figures by
``scripts/digitise_livox_coverage.py``; the comparison table is ``scripts/livox_coverage_table.py``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sim.scan.coverage import swath_coverage
from sim.scan.line_spacing import LIVOX_HORIZON_SPACING, horizon_line_spacing
from sim.scan.livox_published import published_coverage
from sim.scan.model import ScanModel
from sim.scan.presets import PRESETS

ISSUE_TOLERANCE = 0.03


def deviations(preset: str, reference_rays: int = 1_000_000) -> tuple[np.ndarray, np.ndarray]:
    """(compared times, ours - Livox) at every published point up to the plateau."""
    pub = published_coverage(preset)
    idx = pub.compared_points()
    t = pub.times_s[idx]
    curve = swath_coverage(ScanModel(PRESETS[preset]), float(t.max()), reference_rays=reference_rays)
    ours = np.array([curve.coverage[np.argmin(np.abs(curve.times_s - ti))] for ti in t])
    return t, ours - pub.coverage[idx]


def test_published_curves_as_read():
    """The three curves load, rise, stay in [0, 1], and the Mid-40 reading agrees with the independent
    reading in shared/facts/livox-coverage.md (+-2 points stated there) within 1 point."""
    facts_mid40 = {0.05: 0.109, 0.1: 0.192, 0.2: 0.352, 0.3: 0.483, 0.4: 0.593, 0.5: 0.682, 0.6: 0.757,
                   0.7: 0.815, 0.8: 0.861, 1.0: 0.925, 1.2: 0.962, 1.4: 0.982}
    mid40 = published_coverage("mid40")
    for t, v in facts_mid40.items():
        assert abs(mid40.coverage[np.isclose(mid40.times_s, t)][0] - v) <= 0.01, t
    for name, n_points in (("mid40", 28), ("horizon", 12), ("tele15", 13)):
        pub = published_coverage(name)
        assert len(pub.compared_points()) == n_points
        assert np.all(np.diff(pub.coverage) >= -0.002) and 0 < pub.coverage.min() and pub.coverage.max() <= 1
        assert np.all(pub.plus_minus < 0.02)
    # the page's own words: Tele-15 about 99 % at 0.1 s; Horizon about 60 % at 0.1 s
    assert 0.97 <= published_coverage("tele15").coverage[9] <= 0.995
    assert 0.55 <= published_coverage("horizon").coverage[1] <= 0.65
    with pytest.raises(KeyError, match="avia"):
        published_coverage("avia")


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["mid40", "tele15", "horizon"])
def test_preset_follows_livox_published_curve(preset):
    """Every published point (0.05 s steps, Tele-15 0.01 s, up to the plateau) within 0.03 (issue 27).
    Before the speeds were fitted (scripts/fit_livox_presets.py): mid40 0.044 low at 0.7 s, tele15 0.040
    high at 0.01 s, horizon 0.048 low at 0.35 s."""
    t, dev = deviations(preset)
    assert np.max(np.abs(dev)) <= ISSUE_TOLERANCE, dict(zip(t.round(2).tolist(), dev.round(3).tolist()))


@pytest.mark.slow
def test_horizon_line_spacing_in_0_1_s_matches_livox_statement():
    """Livox: in 0.1 s the centre's lines are 0.2 deg apart on average (most 0.1-0.3), the two side
    circles' 0.4 deg (most 0.2-0.8).  Measured on vertical cuts (sim.scan.line_spacing,
    scripts/horizon_line_spacing.py): the averages within 25 % of Livox's, the median gap inside each
    stated range, and most side gaps inside 0.2-0.8 deg."""
    got = horizon_line_spacing(PRESETS["horizon"], 0.1)
    for region, (average, (lo, hi)) in LIVOX_HORIZON_SPACING.items():
        s = got[region]
        assert abs(s["mean_deg"] - average) <= 0.25 * average, (region, s)
        assert lo <= s["median_deg"] <= hi, (region, s)
    assert got["sides"]["fraction_in_range"] > 0.5, got["sides"]
    assert got["sides"]["mean_deg"] > 1.5 * got["centre"]["mean_deg"]   # sparser at the sides, as Livox says


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="centre: 44 % of the gaps in 0.1-0.3 deg, not most; lines sweeping right "
                                      "and left cross, so a cut near a crossing sees small gaps (docs/livox-files.md)")
def test_horizon_centre_most_line_gaps_in_livox_range():
    assert horizon_line_spacing(PRESETS["horizon"], 0.1)["centre"]["fraction_in_range"] > 0.5


def test_lidar_coverage_compare_plots_ours_against_livox(tmp_path, capsys):
    from foveatrack.cli import main

    png = tmp_path / "cmp.png"
    assert main(["lidar", "coverage", "tele15", "--method", "footprint", "--compare", str(png), "--json",
                 "--no-progress"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert png.stat().st_size > 10_000
    livox = out["livox"]
    assert livox["times_s"][0] == 0.01 and len(livox["ours"]) == 13 and out["duration_s"] == 0.13
    assert livox["max_abs_deviation"] == pytest.approx(
        max(abs(a - b) for a, b in zip(livox["ours"], livox["coverage"])))


@pytest.mark.parametrize("argv, message", [
    (["lidar", "coverage", "avia", "--method", "footprint"], "only for mid40, horizon, tele15"),
    (["lidar", "coverage", "tele15"], "use --method footprint"),
])
def test_lidar_coverage_compare_refuses_what_it_cannot_compare(tmp_path, capsys, argv, message):
    from foveatrack.cli import main

    rc = main(argv + ["--compare", str(tmp_path / "x.png")])
    assert rc != 0 and message in capsys.readouterr().err
