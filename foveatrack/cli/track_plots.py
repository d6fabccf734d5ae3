"""Plots of ``foveatrack track`` (matplotlib Agg, PNG; CLI edge only).

* track_xyz.png -- x, y, z of the track against time (and the reference, if given), points per
  frame and in D below
* track_top.png -- the track seen from above (and the reference)
* track_error.png -- the distance to the reference per frame (only with a reference)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_all(res, out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f = res.frames
    out_dir = Path(out_dir)
    name = Path(res.path).name
    t = f["t_s"] - (f["t_s"][0] if f["t_s"].size else 0.0)
    xyz = f["xyz_m"]
    ref = f.get("ref_xyz_m")
    files = []

    fig, axes = plt.subplots(4, 1, figsize=(9, 9), sharex=True)
    for i, ax in enumerate(axes[:3]):
        if ref is not None:
            ax.plot(t, ref[:, i], ".", color="0.6", label="reference")
        ax.plot(t, xyz[:, i], "o-", ms=3, label="track (Algorithm 1 in D)")
        ax.set_ylabel(f"{'xyz'[i]} [m]")
    axes[0].legend(loc="best", fontsize=8)
    axes[3].bar(t, f["n_points"], width=0.08, color="0.7", label="points in frame")
    axes[3].bar(t, f["det_n_points"], width=0.08, color="C0", label="points in D")
    axes[3].set_yscale("symlog")
    axes[3].set_ylabel("points")
    axes[3].set_xlabel("time since the first frame [s]")
    axes[3].legend(loc="best", fontsize=8)
    fig.suptitle(f"{name}: track, {res.summary['frames_tracked']} of {res.summary['frames']} frames")
    fig.tight_layout()
    p = out_dir / "track_xyz.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    files.append(p)

    fig, ax = plt.subplots(figsize=(6, 6))
    if ref is not None:
        ax.plot(ref[:, 0], ref[:, 1], ".", color="0.6", label="reference")
    ax.plot(xyz[:, 0], xyz[:, 1], "o-", ms=3, label="track")
    ax.plot([0], [0], "k^", label="sensor")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{name}: seen from above")
    fig.tight_layout()
    p = out_dir / "track_top.png"
    fig.savefig(p, dpi=110)
    plt.close(fig)
    files.append(p)

    if "error_m" in f:
        e = res.summary["reference"]["error"]
        fig, ax = plt.subplots(figsize=(9, 3.5))
        ax.plot(t, f["error_m"] * 100, "o-", ms=3)
        if e["frames"]:
            ax.axhline(e["median_m"] * 100, color="C1", ls="--", label=f"median {e['median_m'] * 100:.1f} cm")
            ax.axhline(e["p95_m"] * 100, color="C3", ls=":", label=f"p95 {e['p95_m'] * 100:.1f} cm")
            ax.legend(loc="best", fontsize=8)
        ax.set_xlabel("time since the first frame [s]")
        ax.set_ylabel("distance to reference [cm]")
        ax.set_title(f"{name}: track against the reference")
        fig.tight_layout()
        p = out_dir / "track_error.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        files.append(p)
    return files
