"""Plots of a closed-loop run: the paper's Fig. 14 a/b/c equivalents (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.cli.scan_plots import _plt, _save


def plot_points_vs_position(log, title, path) -> Path:
    """Fig. 14a: points on the UAV per frame against its lateral position."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(log["target_lateral_m"], log["points_on_target"], "o-", ms=3, lw=0.8)
    ax.set_xlabel("target lateral position y [m] (+ = left)")
    ax.set_ylabel("points on the target per frame")
    ax.set_title(title)
    return _save(fig, path)


def plot_error_vs_time(log, deadband_deg, title, path) -> Path:
    """Fig. 14b: angular tracking error against time."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    t = log["t_end_s"]
    ax.plot(t, log["true_error_deg"], lw=1, label="true error (target off the lidar axis)")
    det = log["detected"].astype(bool)
    ax.plot(t[~det], log["true_error_deg"][~det], "x", ms=4, color="tab:red", label="no detection")
    ax.axhline(deadband_deg, color="0.5", ls=":", label=f"dead band {deadband_deg:g} deg")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("angular error [deg]")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.legend()
    ax.set_title(title)
    return _save(fig, path)


def plot_trajectory(log, title, path) -> Path:
    """Fig. 14c: the intruder's trajectory reconstructed from lidar + head commands, vs truth."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    tru = np.asarray(log["target_xyz"], float)
    est = np.asarray(log["estimate_xyz"], float)
    for ax, (i, j, lab) in zip(axes, ((0, 1, "top view: x [m], y [m]"), (1, 2, "front view: y [m], z [m]"))):
        ax.plot(tru[:, i], tru[:, j], "-", color="0.3", lw=1.5, label="truth")
        ax.plot(est[:, i], est[:, j], ".", ms=3, color="tab:orange", label="reconstructed")
        ax.set_title(lab)
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend()
    fig.suptitle(title)
    return _save(fig, path)


def plot_head(log, title, path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 4))
    t = log["t_end_s"]
    ax.plot(t, log["head_pan_deg"], label="pan, true")
    ax.plot(t, log["est_pan_deg"], "--", label="pan, dead-reckoned")
    ax.plot(t, log["head_tilt_deg"], label="tilt, true")
    ax.plot(t, log["est_tilt_deg"], "--", label="tilt, dead-reckoned")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("[deg]")
    ax.legend()
    ax.set_title(title)
    return _save(fig, path)
