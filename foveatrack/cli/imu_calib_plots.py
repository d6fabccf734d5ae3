"""The plot of ``foveatrack calibrate-imu --plot``: paper Fig. 11b (calibration error against
accumulation time) beside Fig. 6e (coverage against time)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

COLOURS = {"mid40": "tab:blue", "horizon": "tab:orange", "prototype": "tab:green", "vlp16": "tab:red"}


def plot_error_vs_accumulation(rows: list[dict], coverage: dict | None, path: str, scene: str, command: str) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    lidars = list(dict.fromkeys(r["lidar"] for r in rows))
    for name in lidars:
        rr = [r for r in rows if r["lidar"] == name]
        t = [r["accumulate_s"] for r in rr]
        c = COLOURS.get(name)
        axes[0].plot(t, [r["eq8_mean"] for r in rr], "o-", color=c, label=name)
        axes[1].plot(t, [r["rotation_error_deg"] for r in rr], "o-", color=c, label=f"{name} rotation [deg]")
        axes[1].plot(t, [r["translation_error_m"] * 100 for r in rr], "s--", color=c, label=f"{name} translation [cm]")
    axes[0].set(xscale="log", yscale="log", xlabel="accumulation time per pose [s]",
                ylabel="eq. (8) error, mean over pose pairs", title="calibration error (paper Fig. 11b)")
    axes[1].set(xscale="log", yscale="log", xlabel="accumulation time per pose [s]",
                ylabel="extrinsic error vs truth", title="extrinsic error (deg / cm)")
    for ax in axes[:2]:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    if coverage:
        for name, (t, cov) in coverage.items():
            axes[2].plot(t, cov * 100, color=COLOURS.get(name), label=name)
        axes[2].set(xscale="log", xlabel="accumulation time [s]", ylabel="coverage [%]",
                    title="coverage of the FoV (paper Fig. 6e)", ylim=(0, 100))
        axes[2].grid(True, which="both", alpha=0.3)
        axes[2].legend(fontsize=8)
    else:
        axes[2].axis("off")
    fig.suptitle(f"lidar-IMU calibration, scene {scene}   ({command})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
