"""The plot of ``foveatrack calibrate-imu --plot`` and of ``scripts/imu_calib_seeds.py``: paper Fig. 11b
(calibration error against accumulation time), the registration error behind it, the extrinsic's error
against the truth, and Fig. 6e (coverage against time) beside them.

Degrees and centimetres each get their own panel (never one log axis for both).  Every error panel
(eq. (8), registration, extrinsic) is drawn on a linear axis from zero, so a change of a percent
looks like one (the yard's registration error, 0.01131 -> 0.01124 deg, filled a log panel top to
bottom), unless the values it draws span more than a decade (a 16-line lidar beside the Risley
ones, or a registration that failed at one time): then on a log axis, which its label says.  The accumulation axis is logarithmic, as the times run are (0.1 s to
10 s), with a tick at each time run, in plain numbers.  The coverage panel draws the Risley lidars
only (a spinning lidar's scan repeats every turn) and its title names any lidar of the run it leaves
out.  Rows may carry ``KEY_lo`` / ``KEY_hi`` beside a metric ``KEY`` (a spread over seeds): drawn as a
band.  The lidars' legend is one, below the panels, so it covers no curve.
"""

from __future__ import annotations

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FuncFormatter, NullFormatter  # noqa: E402

COLOURS = {"mid40": "tab:blue", "horizon": "tab:orange", "prototype": "tab:green", "vlp16": "tab:red"}
PLAIN = FuncFormatter(lambda x, _: f"{x:g}")    # 0.2, 1, 10: not 2 x 10^-1


def _error_axis(ax, per_lidar: dict, extra, label: str) -> None:
    """Linear from zero; log where the values drawn span more than a decade (a 16-line lidar beside
    the Risley ones, or one registration that failed: a linear axis then flattens every other curve
    to its floor), said in the label.  ``per_lidar``: {lidar: [values]}; ``extra``: values the axis
    must also show (bands, a floor line)."""
    pos = [x for vs in per_lidar.values() for x in vs if x > 0] + [x for x in extra if x > 0]
    if pos and max(pos) > 10.0 * min(pos):
        ax.set(yscale="log", ylabel=f"{label} (log scale)")
        ax.yaxis.set_major_formatter(PLAIN)
        ax.yaxis.set_minor_formatter(NullFormatter())
    else:
        top = max((x for vs in per_lidar.values() for x in vs if x == x), default=1.0)
        ax.set(ylim=(0, 1.2 * max([top] + [x for x in extra if x == x])), ylabel=label)


def _time_axis(ax, label: str, ticks=None) -> None:
    """Logarithmic accumulation time, ticks in plain numbers (at ``ticks``: the times run)."""
    ax.set(xscale="log", xlabel=label)
    if ticks is not None:
        ax.set_xticks(sorted(set(ticks)))
    ax.xaxis.set_major_formatter(PLAIN)
    ax.xaxis.set_minor_formatter(NullFormatter())


def _curve(ax, rr, key: str, colour, scale: float = 1.0) -> None:
    t = [r["accumulate_s"] for r in rr]
    ax.plot(t, [r[key] * scale for r in rr], "o-", color=colour, ms=4)
    if all(f"{key}_lo" in r and f"{key}_hi" in r for r in rr):
        ax.fill_between(t, [r[f"{key}_lo"] * scale for r in rr], [r[f"{key}_hi"] * scale for r in rr],
                        color=colour, alpha=0.18, lw=0)


def plot_error_vs_accumulation(rows: list[dict], coverage: dict | None, path: str, scene: str, command: str,
                               spread_note: str = "") -> None:
    fig, axes = plt.subplots(2, 3, figsize=(15, 8.5))
    (ax_eq8, ax_reg_r, ax_reg_t), (ax_cov, ax_x_r, ax_x_t) = axes
    lidars = list(dict.fromkeys(r["lidar"] for r in rows))
    for name in lidars:
        rr = [r for r in rows if r["lidar"] == name]
        c = COLOURS.get(name)
        _curve(ax_eq8, rr, "eq8_mean", c)
        _curve(ax_reg_r, rr, "registration_rotation_deg", c)
        _curve(ax_reg_t, rr, "registration_translation_m", c, 100.0)
        _curve(ax_x_r, rr, "rotation_error_deg", c)
        _curve(ax_x_t, rr, "translation_error_m", c, 100.0)
    floors = {}
    for key, ax, scale in (("imu_floor_rotation_deg", ax_x_r, 1.0), ("imu_floor_translation_m", ax_x_t, 100.0)):
        vals = [r[key] for r in rows if key in r]
        if vals:
            floors[ax] = sum(vals) / len(vals) * scale
            ax.axhline(floors[ax], color="grey", lw=1.0, ls=":")
    xl = "accumulation time per pose [s]"
    times = [r["accumulate_s"] for r in rows]
    for ax, key, scale, label, title in (
            (ax_eq8, "eq8_mean", 1.0, "eq. (8) error (mean over pose pairs)", "calibration error, eq. (8) (paper Fig. 11b)"),
            (ax_reg_r, "registration_rotation_deg", 1.0, "rotation [deg]", "lidar registration error per pose pair: rotation"),
            (ax_reg_t, "registration_translation_m", 100.0, "translation [cm]",
             "lidar registration error per pose pair: translation"),
            (ax_x_r, "rotation_error_deg", 1.0, "rotation [deg]", "extrinsic error: rotation"),
            (ax_x_t, "translation_error_m", 100.0, "translation [cm]", "extrinsic error: translation")):
        per_lidar = {n: [r[key] * scale for r in rows if r["lidar"] == n] for n in lidars}
        band = [r[k] * scale for r in rows for k in (f"{key}_lo", f"{key}_hi") if k in r]
        _error_axis(ax, per_lidar, band + ([floors[ax]] if ax in floors else []), label)
        _time_axis(ax, xl, times)
        ax.set_title(title, fontsize=11)
        ax.grid(True, which="both", alpha=0.3)
    if coverage:
        for name, (t, cov) in coverage.items():
            ax_cov.plot(t, cov * 100, color=COLOURS.get(name))
        left_out = [n for n in lidars if n not in coverage]
        _time_axis(ax_cov, "accumulation time [s]")
        ax_cov.set(ylabel="coverage [%]", ylim=(0, 100))
        ax_cov.set_title("coverage of the FoV (paper Fig. 6e), App. C voxels\nthe Risley scan at one pose"
                         + (f"; {', '.join(left_out)} not drawn\n(a spinning scan repeats every turn)" if left_out else ""),
                         fontsize=11)
        ax_cov.grid(True, which="both", alpha=0.3)
    else:
        ax_cov.axis("off")
    handles = [Line2D([], [], color=COLOURS.get(n), marker="o", label=n) for n in lidars]
    if floors:
        handles.append(Line2D([], [], color="grey", ls=":", label="IMU-only floor (true lidar motions, the IMU's)"))
    if spread_note:
        handles.append(matplotlib.patches.Patch(color="grey", alpha=0.3, label=spread_note))
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=9, frameon=False)
    fig.suptitle(f"lidar-IMU calibration, scene {scene}\n{command}", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
