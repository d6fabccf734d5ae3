"""Plots of a replay: the paper's Fig. 14a/b/c equivalents (matplotlib Agg, PNG; CLI edge only).

* fig14a_points_vs_lateral.png -- points on the target per frame vs the target's lateral position
  (truth: the simulator's points_on_target and target y; otherwise the detection's point count and y)
* fig14b_error_vs_time.png -- tracking error vs time (truth: true error off the axis; and the
  detection bearing error off the lidar axis)
* fig14c_trajectory.png -- reconstructed target trajectory (the tracker's world estimates) vs truth,
  top view (x-y) and height vs time
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_all(res, out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f, t = res.frames, res.truth
    time_s = f["t_end_s"] - (f["t_end_s"][0] if len(f["t_end_s"]) else 0.0)
    det = f["detected"]
    files = []

    fig, ax = plt.subplots(figsize=(6, 4), constrained_layout=True)
    if t is not None:
        ax.plot(t["target_xyz_m"][:, 1], t["points_on_target"], ".", ms=4, label="truth: points on target")
    ax.plot(f["det_xyz"][det, 1], f["det_n_points"][det], "x", ms=4, label="detection: points in D")
    ax.set_xlabel("lateral position y [m] (" + ("world, truth" if t is not None else "lidar frame") + ")")
    ax.set_ylabel("points per frame")
    ax.set_title("Fig. 14a equivalent: points on target vs lateral position")
    ax.grid(alpha=0.3)
    ax.legend()
    files.append(_save(fig, plt, out_dir / "fig14a_points_vs_lateral.png"))

    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    if t is not None:
        ax.plot(time_s, t["true_error_deg"], "-", lw=1.2, label="true error off the axis")
    be = np.hypot(f["error_pan_deg"], f["error_tilt_deg"])
    ax.plot(time_s, be, ".", ms=3, label="detection bearing error")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("error [deg]")
    ax.set_title("Fig. 14b equivalent: tracking error vs time")
    ax.grid(alpha=0.3)
    ax.legend()
    files.append(_save(fig, plt, out_dir / "fig14b_error_vs_time.png"))

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    w = f["world_xyz"]
    if t is not None:
        a1.plot(t["target_xyz_m"][:, 0], t["target_xyz_m"][:, 1], "-", lw=1.5, label="truth")
        a2.plot(time_s, t["target_xyz_m"][:, 2], "-", lw=1.5, label="truth")
    a1.plot(w[:, 0], w[:, 1], ".", ms=3, label="reconstructed")
    a2.plot(time_s, w[:, 2], ".", ms=3, label="reconstructed")
    a1.set_xlabel("x [m]")
    a1.set_ylabel("y [m]")
    a1.set_aspect("equal", adjustable="datalim")
    a1.set_title("top view")
    a2.set_xlabel("time [s]")
    a2.set_ylabel("z [m]")
    a2.set_title("height")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend()
    fig.suptitle("Fig. 14c equivalent: reconstructed trajectory vs truth")
    files.append(_save(fig, plt, out_dir / "fig14c_trajectory.png"))
    return files


def _save(fig, plt, path: Path) -> Path:
    from foveatrack.errors import UserError

    try:
        fig.savefig(path, dpi=110)
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror}") from None
    finally:
        plt.close(fig)
    return path
