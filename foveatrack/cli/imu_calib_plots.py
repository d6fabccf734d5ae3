"""The plot of ``foveatrack calibrate-imu --plot``: paper Fig. 11b (calibration error against
accumulation time), the registration error behind it, the extrinsic's error against the truth, and
Fig. 6e (coverage against time) beside them."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLOURS = {"mid40": "tab:blue", "horizon": "tab:orange", "prototype": "tab:green", "vlp16": "tab:red"}


def plot_error_vs_accumulation(rows: list[dict], coverage: dict | None, path: str, scene: str, command: str) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    (ax_eq8, ax_reg), (ax_x, ax_cov) = axes
    lidars = list(dict.fromkeys(r["lidar"] for r in rows))
    for name in lidars:
        rr = [r for r in rows if r["lidar"] == name]
        t = [r["accumulate_s"] for r in rr]
        c = COLOURS.get(name)
        ax_eq8.plot(t, [r["eq8_mean"] for r in rr], "o-", color=c, label=name)
        ax_reg.plot(t, [r["registration_rotation_deg"] for r in rr], "o-", color=c, label=f"{name} rotation [deg]")
        ax_reg.plot(t, [r["registration_translation_m"] * 100 for r in rr], "s--", color=c,
                    label=f"{name} translation [cm]")
        ax_x.plot(t, [r["rotation_error_deg"] for r in rr], "o-", color=c, label=f"{name} rotation [deg]")
        ax_x.plot(t, [r["translation_error_m"] * 100 for r in rr], "s--", color=c, label=f"{name} translation [cm]")
    imu_rot = [r["imu_floor_rotation_deg"] for r in rows]
    imu_tr = [r["imu_floor_translation_m"] * 100 for r in rows]
    if imu_rot:
        ax_x.axhline(max(imu_rot), color="grey", lw=0.8, ls=":", label="IMU-only floor, rotation [deg]")
        ax_x.axhline(max(imu_tr), color="grey", lw=0.8, ls="-.", label="IMU-only floor, translation [cm]")
    xl = "accumulation time per pose [s]"
    ax_eq8.set(xscale="log", yscale="log", xlabel=xl, ylabel="eq. (8) error (mean over pose pairs)",
               title="calibration error, eq. (8) (paper Fig. 11b)")
    ax_reg.set(xscale="log", yscale="log", xlabel=xl, ylabel="registered vs true lidar motion",
               title="lidar registration error per pose pair (mean)")
    ax_x.set(xscale="log", yscale="log", xlabel=xl, ylabel="estimated vs true extrinsic",
             title="extrinsic error (deg / cm)")
    for ax in (ax_eq8, ax_reg, ax_x):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    if coverage:
        for name, (t, cov) in coverage.items():
            ax_cov.plot(t, cov * 100, color=COLOURS.get(name), label=name)
        ax_cov.set(xscale="log", xlabel="accumulation time [s]", ylabel="coverage [%]",
                   title="coverage of the FoV (paper Fig. 6e)\nspinning lidars: fixed after one turn", ylim=(0, 100))
        ax_cov.grid(True, which="both", alpha=0.3)
        ax_cov.legend(fontsize=8)
    else:
        ax_cov.axis("off")
    fig.suptitle(f"lidar-IMU calibration, scene {scene}\n{command}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
