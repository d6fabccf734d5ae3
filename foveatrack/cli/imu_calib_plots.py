"""The plot of ``foveatrack calibrate-imu --plot`` and of ``scripts/imu_calib_seeds.py``: paper Fig. 11b
(calibration error against accumulation time), the registration error behind it, the extrinsic's error
against the truth, and Fig. 6e (coverage against time) beside them.

Degrees and centimetres each get their own panel (never one log axis for both); eq. (8) is drawn on a
linear axis from zero, so a change of a percent looks like one.  Rows may carry ``KEY_lo`` / ``KEY_hi``
beside a metric ``KEY`` (a spread over seeds): drawn as a band.  The lidars' legend is one, below the
panels, so it covers no curve.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

COLOURS = {"mid40": "tab:blue", "horizon": "tab:orange", "prototype": "tab:green", "vlp16": "tab:red"}


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
    floors = []
    for key, ax, scale in (("imu_floor_rotation_deg", ax_x_r, 1.0), ("imu_floor_translation_m", ax_x_t, 100.0)):
        vals = [r[key] for r in rows if key in r]
        if vals:
            ax.axhline(sum(vals) / len(vals) * scale, color="grey", lw=1.0, ls=":")
            floors.append(ax)
    xl = "accumulation time per pose [s]"
    top = max((r.get("eq8_mean_hi", r["eq8_mean"]) for r in rows), default=1.0)
    ax_eq8.set(xscale="log", xlabel=xl, ylabel="eq. (8) error (mean over pose pairs)", ylim=(0, 1.2 * top),
               title="calibration error, eq. (8) (paper Fig. 11b)")
    ax_reg_r.set(xscale="log", yscale="log", xlabel=xl, ylabel="rotation [deg]",
                 title="lidar registration error per pose pair (mean)")
    ax_reg_t.set(xscale="log", yscale="log", xlabel=xl, ylabel="translation [cm]",
                 title="lidar registration error per pose pair (mean)")
    ax_x_r.set(xscale="log", yscale="log", xlabel=xl, ylabel="rotation [deg]", title="extrinsic error: rotation")
    ax_x_t.set(xscale="log", yscale="log", xlabel=xl, ylabel="translation [cm]", title="extrinsic error: translation")
    for ax in (ax_eq8, ax_reg_r, ax_reg_t, ax_x_r, ax_x_t):
        ax.grid(True, which="both", alpha=0.3)
    if coverage:
        for name, (t, cov) in coverage.items():
            ax_cov.plot(t, cov * 100, color=COLOURS.get(name))
        ax_cov.set(xscale="log", xlabel="accumulation time [s]", ylabel="coverage [%]",
                   title="coverage of the FoV (paper Fig. 6e)\nspinning lidars: fixed after one turn", ylim=(0, 100))
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
