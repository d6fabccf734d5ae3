"""What ``calibrate-imu --plot`` draws (paper Section IV.A, Fig. 11b beside Fig. 6e): the scales and
titles say what is plotted (not how it looks).

The figure is drawn by the command's own function from rows as ``sim.imu_rig.score_row`` gives them;
the figure is taken where the function closes it."""

import matplotlib.pyplot as plt
import numpy as np
import pytest

import foveatrack.cli.imu_calib_plots as P

ERROR_KEYS = ("eq8_mean", "registration_rotation_deg", "registration_translation_m", "rotation_error_deg",
              "translation_error_m")


def _row(lidar, t, scale=1.0, **kw):
    r = {"lidar": lidar, "accumulate_s": t, "eq8_mean": 1e-3 * scale, "registration_rotation_deg": 0.0113 * scale,
         "registration_translation_m": 0.0012 * scale, "rotation_error_deg": 0.03 * scale,
         "translation_error_m": 0.0033 * scale, "imu_floor_rotation_deg": 0.012, "imu_floor_translation_m": 0.0019}
    r.update(kw)
    return r


def _figure(monkeypatch, tmp_path, rows, coverage):
    figs = []
    monkeypatch.setattr(P.plt, "close", figs.append)
    P.plot_error_vs_accumulation(rows, coverage, str(tmp_path / "f.png"), "yard", "foveatrack calibrate-imu ...")
    assert (tmp_path / "f.png").stat().st_size > 10_000
    fig = figs[0]
    plt.close(fig)
    return fig


def _error_panels(fig):
    """The five error panels (every one but the coverage's), in drawing order."""
    return [ax for ax in fig.axes if ax.get_ylabel() and "coverage" not in ax.get_ylabel()]


def test_errors_within_a_decade_are_drawn_from_zero_on_a_linear_axis(monkeypatch, tmp_path):
    # the shipped yard figure: registration 0.01131 -> 0.01124 deg on a log axis filled its panel top to
    # bottom (a 0.6 % change drawn as the whole fall), its ticks "1.124 x 10^-2" ... "1.131 x 10^-2"
    # ... and a curve that falls tenfold (the paper's Fig. 11b: "drops rapidly during the first second")
    rows = [_row("mid40", 1.0), _row("mid40", 10.0, registration_rotation_deg=0.01124, eq8_mean=1.01e-3,
                                     rotation_error_deg=0.019, translation_error_m=0.00033)]
    fig = _figure(monkeypatch, tmp_path, rows, None)
    panels = _error_panels(fig)
    assert len(panels) == 5
    for ax in panels:
        assert ax.get_yscale() == "linear", ax.get_title()
        lo, hi = ax.get_ylim()
        top = max(np.max(line.get_ydata()) for line in ax.get_lines())     # the curve and any floor line
        assert lo == 0.0 and top <= hi <= 1.5 * top, (ax.get_title(), lo, hi, top)


def test_lidars_a_decade_apart_keep_a_log_axis_and_say_so(monkeypatch, tmp_path):
    # a 16-line lidar 30 x worse beside the Risley one (the room figure): a linear axis would flatten
    # the Mid-40 onto its floor
    rows = [_row("mid40", t) for t in (0.1, 1.0, 10.0)] + [_row("vlp16", t, scale=30.0) for t in (0.1, 1.0, 10.0)]
    fig = _figure(monkeypatch, tmp_path, rows, None)
    for ax in _error_panels(fig):
        assert ax.get_yscale() == "log" and "log scale" in ax.get_ylabel(), (ax.get_title(), ax.get_ylabel())


def test_one_failed_registration_keeps_a_log_axis(monkeypatch, tmp_path):
    # the room figure redrawn: the 16-line lidar 3 x the Risley ones but one of its times 45 x (a
    # registration that slid): by the medians a linear axis, which drew the Mid-40 and the Horizon
    # flat on the floor under the spike
    rows = ([_row("mid40", t) for t in (0.1, 1.0, 10.0)]
            + [_row("vlp16", t, scale=s) for t, s in ((0.1, 3.0), (1.0, 3.0), (5.0, 45.0), (10.0, 3.0))])
    fig = _figure(monkeypatch, tmp_path, rows, None)
    for ax in _error_panels(fig):
        assert ax.get_yscale() == "log" and "log scale" in ax.get_ylabel(), (ax.get_title(), ax.get_ylabel())


def test_accumulation_ticks_are_the_times_run_in_plain_numbers(monkeypatch, tmp_path):
    # on a log axis spanning less than two decades matplotlib labelled the minor ticks too:
    # "2 x 10^-1 3 x 10^-1 4 x 10^-1 6 x 10^-1" ran into one another under the panels
    times = (0.2, 1.0, 5.0)
    fig = _figure(monkeypatch, tmp_path, [_row("mid40", t) for t in times], None)
    for ax in _error_panels(fig):
        fig.canvas.draw()
        major = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
        minor = [t.get_text() for t in ax.get_xticklabels(minor=True) if t.get_text()]
        assert major == ["0.2", "1", "5"] and minor == [], (ax.get_title(), major, minor)


@pytest.mark.parametrize("lidars, drawn, said", [
    (["mid40"], ["mid40"], None),
    (["mid40", "vlp16"], ["mid40"], "vlp16"),
])
def test_the_coverage_titles_say_which_lidars_are_drawn(monkeypatch, tmp_path, lidars, drawn, said):
    # coverage (App. C, eq. 9) is drawn for the Risley lidars only; the subtitle spoke of spinning
    # lidars ("fixed after one turn") on a Mid-40-only figure, and drew none of them where one ran
    t = np.linspace(0.025, 10.0, 50)
    coverage = {name: (t, 1 - np.exp(-t)) for name in drawn}
    rows = [_row(name, a) for name in lidars for a in (1.0, 10.0)]
    fig = _figure(monkeypatch, tmp_path, rows, coverage)
    ax = next(a for a in fig.axes if "coverage" in a.get_ylabel())
    title = ax.get_title()
    assert "Fig. 6e" in title and "fixed after one turn" not in title, title
    if said is None:
        assert "spinning" not in title, title
    else:
        assert f"{said} not drawn" in title, title
