"""Plots of a tracking run: the paper's Fig. 14 a/b/c equivalents and the head angles (PNG).

One set of functions for both drivers: ``foveatrack simulate --plot`` passes the closed loop's log,
``foveatrack replay --plot`` the replay's arrays (see ``replay_plots``), so a simulated run and its
replay look alike.  The functions take plain per-frame arrays (NaN where a value is missing).

Colours are the same in every plot: truth a dark grey line, the tracker's own estimates and
detections orange, frames without a detection red crosses, thresholds (dead band, half FoV, tilt
stops) grey.  The error plot shades the acquisition phase pink and the tracking phase green, the
marking colours of the paper's Fig. 12 that its Fig. 14b reuses.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foveatrack.cli.scan_plots import _plt, _save
from foveatrack.sky.track_paths import last_label

TRUTH_C = "0.2"          # truth: a dark grey line
EST_C = "tab:orange"     # the tracker's estimates and detections
MISS_C = "tab:red"       # frames without a detection
THRESH_C = "0.45"        # dead band, half FoV, stops
ACQ_C = "tab:pink"       # paper Fig. 12: pink, where first detection happens
TRACK_C = "tab:green"    # paper Fig. 12: green, the active tracking phase
STATE_C = {"waiting": "0.75", "tracking": "tab:green", "holding": "gold", "searching": "tab:pink"}

# A run's plot files, the same for `simulate --plot`, `demo` and `replay --plot` (replay once named
# them fig14a_points_vs_lateral.png, fig14b_error_vs_time.png, ... for the same figures)
POINTS_PNG = "points_on_target.png"     # paper Fig. 14a
ERROR_PNG = "error.png"                 # paper Fig. 14b / 12
TRAJECTORY_PNG = "trajectory.png"       # paper Fig. 14c
HEAD_PNG = "head.png"
TRACKS_PNG = "tracks.png"               # the multi-object tracker's runs ([tracker.sky])
LABEL_C = {"drone": "tab:red", "bird": "tab:blue", "clutter": "tab:green", "unknown": "tab:purple"}

_AXIS_LABEL = ("x [m] (forward)", "y [m] (+ = left)", "z [m] (+ = up)")


def _legend_outside(ax, **kw):
    """Legend to the right of the axes: it never covers data (saved with ``bbox_inches="tight"``)."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0, **kw)


def main_axis(xyz) -> int:
    """Index (0 x, 1 y, 2 z) of the world axis along which the positions spread the most: the
    "horizontal line" of the paper's Fig. 14a is y for a crossing pass, x for a target flying
    overhead toward the lidar."""
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    ok = np.all(np.isfinite(xyz), axis=1)
    if not ok.any():
        return 1
    return int(np.argmax(np.ptp(xyz[ok], axis=0)))


def plot_points_vs_position(pos_xyz, off_axis_deg, points, title, path, *, det_points=None,
                            half_fov_deg=None, source="true") -> Path:
    """Fig. 14a: points on the UAV per frame (a) along its path, (b) against its angle off the lidar axis.

    pos_xyz : (F, 3) [m] world positions; off_axis_deg : (F,) [deg] the target's angle off the lidar
    axis; points : (F,) points on the target (truth) or None; det_points : (F,) points in the
    tracker's detection (NaN: none); source : "true" or "reconstructed", what pos/off-axis are.
    Panel (b) is the one to set beside the radial density (paper Fig. 5): it peaks on the axis.
    """
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.2), sharey=True, constrained_layout=True)
    pos = np.asarray(pos_xyz, float).reshape(-1, 3)
    k = main_axis(pos)
    off = np.asarray(off_axis_deg, float)
    series = []
    if points is not None:
        series.append((np.asarray(points, float), "points on the target (truth)", dict(color=TRUTH_C, marker="o")))
    if det_points is not None:
        series.append((np.asarray(det_points, float), "points in the detection (Alg. 1)",
                       dict(color=EST_C, marker="x", ls="none")))
    for n, label, style in series:
        a1.plot(pos[:, k], n, ms=3, lw=0.6, label=label, **style)
        a2.plot(off, n, ms=3, ls="none", **{k2: v for k2, v in style.items() if k2 != "ls"})
    xl = f"{source} target position {_AXIS_LABEL[k]}"
    ok = np.isfinite(pos[:, k])
    if ok.sum() >= 2 and pos[ok, k][-1] < pos[ok, k][0]:
        a1.invert_xaxis()       # the target moves toward smaller values: time still runs left to right
        xl += ", axis reversed"
    a1.set_xlabel(xl + "  (time ->)")
    a1.set_ylabel("points per frame")
    a1.set_title("(a) along its path (paper Fig. 14a)", fontsize="medium")
    a2.set_xlabel(f"{source} target angle off the lidar axis [deg]")
    a2.set_title("(b) against the angle off the axis (cf. density, paper Fig. 5)", fontsize="medium")
    if half_fov_deg is not None:
        a2.axvline(half_fov_deg, color=THRESH_C, ls="--", lw=1, label=f"half FoV {half_fov_deg:.1f} deg")
    a2.set_xlim(left=0)
    for a in (a1, a2):
        a.yaxis.get_major_locator().set_params(integer=True)
        a.set_ylim(bottom=0)
        a.grid(alpha=0.3)
    handles = [h for a in (a1, a2) for h in a.get_legend_handles_labels()[0]]
    labels = [lab for a in (a1, a2) for lab in a.get_legend_handles_labels()[1]]
    fig.legend(handles, labels, loc="outside lower center", ncols=len(labels), fontsize="small")
    fig.suptitle(title)
    return _save(fig, path)


def plot_error_vs_time(t_s, error_deg, title, path, *, detected=None, bearing_error_deg=None, deadband_deg=None,
                       half_fov_deg=None, in_fov_t_s=None, acquired_t_s=None, axis_error_deg=None,
                       deadband_axes_deg=None) -> Path:
    """Fig. 14b: angular tracking error against time, acquisition and tracking phases shaded.

    error_deg : (F,) [deg] true angle of the target off the lidar axis, or None (no truth);
    bearing_error_deg : (F,) [deg] the detection's bearing off the axis (NaN: no detection);
    in_fov_t_s, acquired_t_s : [s] the acquisition clock's start and the acquisition instant
    (``foveatrack.metrics.tracking_metrics``; ``acquired_t_s`` None: never acquired);
    axis_error_deg : (pan, tilt) (F,) arrays [deg], the true error per axis (azimuth, elevation off
    the axis), drawn as magnitudes beside the total; deadband_axes_deg : (pan, tilt) [deg].  The dead
    band acts per axis, so the total angle may sit at up to sqrt(db_pan^2 + db_tilt^2) with both axes
    inside it: that bound is drawn for the total (a 2 deg line under a 2.8 deg total read as "never
    converges").
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 4.2))
    t = np.asarray(t_s, float)
    t_end = float(t[-1]) if len(t) else 0.0
    if acquired_t_s is not None:
        t0 = in_fov_t_s if in_fov_t_s is not None else (float(t[0]) if len(t) else 0.0)
        if acquired_t_s > t0:
            ax.axvspan(t0, acquired_t_s, color=ACQ_C, alpha=0.15, lw=0,
                       label=f"acquisition, {acquired_t_s - t0:.2f} s")
        ax.axvspan(acquired_t_s, t_end, color=TRACK_C, alpha=0.10, lw=0, label="tracking after acquisition")
    elif in_fov_t_s is not None:
        ax.text(0.01, 0.97, "never acquired", transform=ax.transAxes, va="top", fontsize="small", color=MISS_C)
    top = 0.0
    if error_deg is not None:
        e = np.asarray(error_deg, float)
        ax.plot(t, e, "-", color=TRUTH_C, lw=1.2, label="true error (target off the lidar axis)")
        if detected is not None:
            miss = ~np.asarray(detected, bool)
            ax.plot(t[miss], e[miss], "x", ms=4, color=MISS_C, label="no detection")
        top = max(top, np.nanmax(e) if np.isfinite(e).any() else 0.0)
    if axis_error_deg is not None:
        for a, name, c in zip(axis_error_deg, ("pan (azimuth)", "tilt (elevation)"), ("tab:blue", "tab:purple")):
            ax.plot(t, np.abs(np.asarray(a, float)), "-", color=c, lw=0.8, alpha=0.8, label=f"|true {name} error|")
    if bearing_error_deg is not None:
        b = np.asarray(bearing_error_deg, float)
        ax.plot(t, b, ".", ms=3, color=EST_C, label="detection's bearing off the axis")
        top = max(top, np.nanmax(b) if np.isfinite(b).any() else 0.0)
    if deadband_axes_deg is not None:
        dp, dt_ = (float(v) for v in deadband_axes_deg)
        per_axis = f"{dp:g} deg" if dp == dt_ else f"pan {dp:g} / tilt {dt_:g} deg"
        ax.axhline(max(dp, dt_), color=THRESH_C, ls=":", label=f"dead band per axis, {per_axis}")
        ax.axhline(float(np.hypot(dp, dt_)), color=THRESH_C, ls="-.", lw=1,
                   label=f"total with both axes at their dead band, {np.hypot(dp, dt_):.2f} deg")
    elif deadband_deg is not None:
        ax.axhline(deadband_deg, color=THRESH_C, ls=":", label=f"dead band {deadband_deg:g} deg (per axis)")
    if half_fov_deg is not None and top >= 0.8 * half_fov_deg:   # only where the curve comes near it
        ax.axhline(half_fov_deg, color=THRESH_C, ls="--", lw=1, label=f"half FoV {half_fov_deg:.1f} deg")
    ax.set_ylim(bottom=0)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("angular error [deg]")
    ax.grid(alpha=0.3)
    _legend_outside(ax)
    ax.set_title(title)
    return _save(fig, path)


def plot_trajectory(t_s, est_xyz, title, path, *, true_xyz=None) -> Path:
    """Fig. 14c: the intruder's trajectory reconstructed from lidar + head, against the truth.

    Top view (x forward, y left; the lidar at the origin), height against time and, with truth, the
    reconstruction error against time: at tens of metres a 0.1 m error is invisible in the views.
    """
    plt = _plt()
    ncol = 3 if true_xyz is not None else 2
    fig, axes = plt.subplots(1, ncol, figsize=(5.2 * ncol, 4.6), constrained_layout=True,
                             width_ratios=[1.3] + [1] * (ncol - 1))
    t = np.asarray(t_s, float)
    est = np.asarray(est_xyz, float).reshape(-1, 3)
    a1, a2 = axes[0], axes[1]
    a1.plot([0], [0], marker=(3, 0, -90), ms=9, color="k", ls="none", label="lidar (head centre)")
    if true_xyz is not None:
        tru = np.asarray(true_xyz, float).reshape(-1, 3)
        a1.plot(tru[:, 0], tru[:, 1], "-", color=TRUTH_C, lw=1.5, label="truth")
        a2.plot(t, tru[:, 2], "-", color=TRUTH_C, lw=1.5)
    a1.plot(est[:, 0], est[:, 1], ".", ms=3, color=EST_C, label="reconstructed")
    a2.plot(t, est[:, 2], ".", ms=3, color=EST_C)
    a1.set_xlabel(_AXIS_LABEL[0])
    a1.set_ylabel(_AXIS_LABEL[1])
    a1.set_aspect("equal", adjustable="datalim")
    a1.set_title("top view", fontsize="medium")
    a2.set_xlabel("time [s]")
    if len(t):
        a2.set_xlim(t[0] - 0.02 * (t[-1] - t[0]), t[-1] + 0.02 * (t[-1] - t[0]))
    a2.set_ylabel("height " + _AXIS_LABEL[2])
    a2.set_title("height", fontsize="medium")
    if true_xyz is not None:
        d = np.linalg.norm(est - tru, axis=1)
        a3 = axes[2]
        a3.sharex(a2)
        a3.plot(t, d, ".", ms=3, color=EST_C)
        ok = np.isfinite(d)
        rms = f", rms {np.sqrt(np.mean(d[ok] ** 2)):.2f} m" if ok.any() else ""
        a3.set_title(f"reconstruction error{rms}", fontsize="medium")
        a3.set_xlabel("time [s]")
        a3.set_ylabel("|reconstructed - true| [m]")
        a3.set_ylim(bottom=0)
    for a in axes:
        a.grid(alpha=0.3)
    fig.legend(*a1.get_legend_handles_labels(), loc="outside lower center", ncols=3, fontsize="small")
    fig.suptitle(title)
    return _save(fig, path)


def plot_head(t_s, pan_deg, tilt_deg, title, path, *, est_pan_deg=None, est_tilt_deg=None, state=None,
              tilt_limits_deg=None, tilt_margin_deg=None, source="true", est_label="dead-reckoned",
              residual_label=None) -> Path:
    """Head angles against time: ``source`` (e.g. "true") and ``est_label`` (the tracker's dead
    reckoning), the tilt stops when the tilt comes near them, the residual estimate - source per
    axis in a panel of its own (the two lines overlay at this scale: a speed table of "truth" drew
    them identical), and the tracker's state as a strip along the bottom.

    Pan is unwrapped for the plot (a pass through +-180 deg stays a continuous line).
    residual_label : the residual panel's y label (default "{est_label} - {source}").
    """
    plt = _plt()
    t = np.asarray(t_s, float)
    has_res = (est_pan_deg is not None and np.isfinite(np.asarray(pan_deg, float)).any()
               and np.isfinite(np.asarray(est_pan_deg, float)).any())
    rows = [1.0] + ([0.45] if has_res else []) + ([0.07] if state is not None and len(t_s) else [])
    fig, axes = plt.subplots(len(rows), 1, figsize=(9, 4.2 + 1.6 * has_res), sharex=True, height_ratios=rows,
                             squeeze=False)
    axes = list(axes[:, 0])
    ax = axes[0]
    axr = axes[1] if has_res else None
    axs = axes[-1] if state is not None and len(t_s) else None

    def unwrap(a):
        a = np.asarray(a, float)
        ok = np.isfinite(a)
        out = a.copy()
        if ok.any():
            out[ok] = np.degrees(np.unwrap(np.radians(a[ok])))
        return out

    for name, val, est, c in (("pan (+ = left)", unwrap(pan_deg), est_pan_deg, "tab:blue"),
                              ("tilt (+ = up)", np.asarray(tilt_deg, float), est_tilt_deg, "tab:purple")):
        if np.isfinite(val).any():
            ax.plot(t, val, "-", color=c, lw=3, alpha=0.45, label=f"{name}, {source}")
        if est is not None:
            e = unwrap(est) if name.startswith("pan") else np.asarray(est, float)
            ax.plot(t, e, "--", color=c, lw=1.2, label=f"{name}, {est_label}")
            if axr is not None:
                axr.plot(t, e - val, "-", color=c, lw=1.0, label=f"{name.split()[0]} residual")
    if tilt_limits_deg is not None:
        tilt = np.asarray(est_tilt_deg if est_tilt_deg is not None else tilt_deg, float)
        tilt = tilt[np.isfinite(tilt)]
        for i, stop in enumerate(tilt_limits_deg):
            if tilt.size and np.min(np.abs(tilt - stop)) < 15.0:   # only a stop the tilt comes near
                ax.axhline(stop, color=THRESH_C, ls="-", lw=1.5, label=f"tilt stop {stop:g} deg")
                if tilt_margin_deg:
                    inner = stop - tilt_margin_deg if i == 1 else stop + tilt_margin_deg
                    ax.axhline(inner, color=THRESH_C, ls=":", lw=1,
                               label=f"tracker keeps {tilt_margin_deg:g} deg off the stop")
    ax.set_ylabel("head angle [deg]")
    ax.grid(alpha=0.3)
    ax.set_title(title)
    if axr is not None:
        axr.axhline(0, color=THRESH_C, lw=0.8)
        axr.set_ylabel(residual_label or f"{est_label}\n- {source} [deg]", fontsize="small")
        axr.grid(alpha=0.3)
        axr.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)
    if axs is None:
        axes[-1].set_xlabel("time [s]")
        _legend_outside(ax)
        return _save(fig, path)
    # the tracker's state, frame by frame, in a strip of its own under the angles
    st = np.asarray(state).astype(str)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.1
    for name in dict.fromkeys(st):
        idx = np.flatnonzero(st == name)
        runs = np.split(idx, np.flatnonzero(np.diff(idx) != 1) + 1)
        axs.broken_barh([(t[r[0]] - dt, t[r[-1]] - t[r[0]] + dt) for r in runs], (0, 1),
                        color=STATE_C.get(name, "0.5"), label=f"tracker {name}")
    axs.set_yticks([])
    axs.set_ylim(0, 1)
    axs.set_ylabel("state", rotation=0, ha="right", va="center", fontsize="small")
    axs.set_xlabel("time [s]")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = axs.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", borderaxespad=0.0)
    return _save(fig, path)


#: the most confirmed tracks the time lines of a run without truth draw (the longest-lived)
MAX_TRACK_LINES = 20


def plot_sky_tracks(data: dict, title: str, path) -> Path:
    """Every object and every confirmed track of a multi-object run (``sim.sky_summary.sky_plot_data``):
    the top view (truth paths: drones dark, birds and crowns pale; confirmed tracks: a dot where a frame
    measured them, in the colour of their label in that frame, a faint line in their last label's
    colour through the frames the filter coasted, each ending in its id), and per drone the time line of the fovea (dark where the drone was within
    the fovea's half-angle of the lidar axis) and of a confirmed track near it (within 2 m).  Without
    truth (a daemon's recording) the time lines are the confirmed tracks' own: confirmed, and measured.
    """
    plt = _plt()
    t = data["t_s"]
    drones = sorted(i for i, (c, _) in data["truth"].items() if c == "drone")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12.5, 4.8), constrained_layout=True, width_ratios=[1.3, 1])
    a1.plot([0], [0], marker=(3, 0, -90), ms=9, color="k", ls="none", label="lidar (head centre)")
    shown = set()
    for i, (c, xyz) in sorted(data["truth"].items()):
        key = "truth: drone" if c == "drone" else "truth: bird or scenery"
        a1.plot(xyz[:, 0], xyz[:, 1], "-", color=TRUTH_C if c == "drone" else "0.8", lw=2.0 if c == "drone" else 0.6,
                label=None if key in shown else key, zorder=1)
        shown.add(key)
    for tid, (labels, xyz, hit) in sorted(data["tracks"].items()):
        a1.plot(xyz[:, 0], xyz[:, 1], "-", lw=0.6, alpha=0.35, color=LABEL_C.get(last_label(labels), "k"),
                zorder=2)    # coasting too, in its last label's colour
        for label in sorted(set(labels[hit].tolist())):     # each measured frame in that frame's label
            key = f"track labelled {label} then (dots: measured)"
            on = hit & (labels == label)
            a1.plot(np.where(on, xyz[:, 0], np.nan), np.where(on, xyz[:, 1], np.nan), ".", ms=2.5,
                    color=LABEL_C.get(label, "k"), label=None if key in shown else key,
                    zorder=3 if label == "drone" else 2)     # a drone's dots over a flock's
            shown.add(key)
        ok = np.all(np.isfinite(xyz), axis=1)
        if ok.any():
            last = xyz[ok][-1]
            a1.annotate(str(tid), (last[0], last[1]), fontsize="x-small", xytext=(3, 3), textcoords="offset points")
    a1.set_xlabel(_AXIS_LABEL[0])
    a1.set_ylabel(_AXIS_LABEL[1])
    a1.set_aspect("equal", adjustable="datalim")
    a1.set_title("top view", fontsize="medium")
    a1.grid(alpha=0.3)
    _legend_outside(a1)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.1

    def bars(row, mask, y0, colour):
        a2.broken_barh([(t[a] - dt, (b - a) * dt) for a, b in _runs(mask)], (row + y0, 0.33), color=colour)

    if drones:
        rows = drones
        for row, d in enumerate(drones):
            xyz = data["truth"][d][1]
            near = np.zeros(len(t), bool)
            for tid, (_, txyz, _) in data["tracks"].items():
                dd = np.linalg.norm(txyz - xyz, axis=1)
                near |= np.isfinite(dd) & (dd < 2.0)
            bars(row, near, -0.35, "tab:orange")
            bars(row, data["in_fovea"].get(d, np.zeros(len(t), bool)), 0.02, "0.15")
        a2.set_title("per drone: a confirmed track within 2 m (orange), in the fovea (dark)", fontsize="medium")
    else:
        # no truth (a daemon's recording): what each confirmed track did, not what it followed
        life = sorted(data["tracks"].items(), key=lambda kv: -int(np.isfinite(kv[1][1][:, 0]).sum()))
        shown_tracks = sorted(life[:MAX_TRACK_LINES])
        rows = [f"{tid} ({last_label(labels)})" for tid, (labels, _, _) in shown_tracks]
        for row, (tid, (labels, xyz, hit)) in enumerate(shown_tracks):
            bars(row, np.isfinite(xyz[:, 0]), -0.35, "0.75")
            for label in sorted(set(labels[hit].tolist())):
                bars(row, hit & (labels == label), 0.02, LABEL_C.get(label, "k"))
        more = f"; {len(life) - MAX_TRACK_LINES} shorter ones left out" if len(life) > MAX_TRACK_LINES else ""
        a2.set_title(f"no truth in this recording: per confirmed track, confirmed (grey), measured (in the colour "
                     f"of its label then){more}", fontsize="medium", wrap=True)
    a2.set_yticks(range(len(rows)), rows)
    a2.set_ylim(-0.6, max(len(rows), 1) - 0.4)
    a2.invert_yaxis()
    a2.set_xlabel("time [s]")
    if len(t):
        a2.set_xlim(0, t[-1])
    a2.grid(alpha=0.3, axis="x")
    fig.suptitle(title)
    return _save(fig, path)


def _runs(mask) -> list[tuple[int, int]]:
    """The [start, end) index ranges where ``mask`` is True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.flatnonzero(np.diff(m.astype(np.int8)))
    return list(zip(d[::2].tolist(), d[1::2].tolist()))
