"""Plots of the accuracy-vs-time study (PNG), one per axis, from :func:`sim.study.runner.run_study`'s
results (plain dicts; nothing here runs a simulation)."""

from __future__ import annotations

from pathlib import Path

from foveatrack.cli.scan_plots import _plt, _save

FILES = {"scan": "scan-model.png", "fidelity": "sim-fidelity.png", "sensing": "sensing-window.png",
         "coverage": "coverage.png", "calibration": "calibration.png", "rate": "point-rate.png",
         "levers": "levers.png"}


def _log_axis(ax, which: str = "both") -> None:
    """A log axis with labels on the decades only (minor labels overlapped on short ranges)."""
    from matplotlib.ticker import LogLocator, NullFormatter

    for name in ("x", "y") if which == "both" else (which,):
        axis = ax.xaxis if name == "x" else ax.yaxis
        (ax.set_xscale if name == "x" else ax.set_yscale)("log")
        axis.set_major_locator(LogLocator(base=10, numticks=8))
        axis.set_minor_formatter(NullFormatter())


def _mean_half(iv):
    """(mean, half-width or 0) of a study interval, (None, None) if missing."""
    if not iv:
        return None, None
    return iv["mean"], iv["half"] or 0.0


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and v == v and abs(v) != float("inf")


def plot_scan(axis: dict, path) -> Path:
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    floor = None
    for o in axis["optics"]:
        errs = [r["p95_deg"] for r in o["rows"] if r["p95_deg"] > 0]
        floor = min([floor or 1.0] + errs) / 10
    for o, mk in zip(axis["optics"], ("o", "s")):
        rows = o["rows"]
        ns = [r["ns_per_ray"] for r in rows]
        err = [max(r["p95_deg"], floor) for r in rows]
        line = a.plot(ns[2:], err[2:], "-" + mk, lw=0.8, label=f"{o['optics']}: exact every m-th point, interpolated (not offered)")[0]
        a.plot(ns[:1], err[:1], mk, ms=10, color=line.get_color(), mfc="none", label=f"{o['optics']}: exact (reference, error 0)")
        a.plot(ns[1:2], err[1:2], mk, ms=10, color=line.get_color(), label=f"{o['optics']}: paraxial")
        for r, x, y in zip(rows, ns, err):
            a.annotate(r["model"], (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
        prof = o["paraxial_vs_off_axis"]
        b.plot([p["off_axis_deg"] for p in prof], [p["p95_deg"] for p in prof], "-" + mk, label=o["optics"])
    a.axhline(floor, color="0.7", ls=":", lw=0.8)
    _log_axis(a)
    a.set_xlabel("time per ray [ns] (min of repeats, one core)")
    a.set_ylabel("angular error vs exact, p95 [deg]  (exact drawn on the dotted floor)")
    a.set_title("Scan model: error vs time per ray (float32 not offered)")
    a.legend(fontsize=7)
    b.set_xlabel("off-axis angle of the exact ray [deg]")
    b.set_ylabel("paraxial error, p95 [deg]")
    b.set_title("Where the paraxial model goes wrong")
    b.legend()
    return _save(fig, path)


def plot_fidelity(axis: dict, path) -> Path:
    """Paired change of the tracking error against the CPU ratio, both with their intervals, on linear
    axes: a change of zero is a point on the zero line (it was drawn at 1e-4 on a log axis)."""
    plt = _plt()
    keys = list(axis)
    fig, axes = plt.subplots(1, len(keys), figsize=(6.5 * len(keys), 4.8), squeeze=False)
    for ax, key in zip(axes[0], keys):
        res = axis[key]
        markers = "osD^vP<>Xph"
        for i, r in enumerate(res["rows"]):
            x, xe = _mean_half(r.get("cost_ratio"))
            y, ye = _mean_half(r.get("delta", {}).get("error_rms_all_deg"))
            if not (_finite(x) and _finite(y)):
                continue
            ref = r["setting"] == res["reference"]
            ax.errorbar(x, y, xerr=xe, yerr=ye, fmt="*" if ref else markers[i % len(markers)], ms=13 if ref else 7,
                        mfc="none" if not ref else None, mew=1.2, capsize=2, lw=0.8,
                        label=f"{r['setting']} (reference)" if ref else r["setting"])
        ax.axhline(0.0, color="0.5", ls="--", lw=0.8)
        ax.legend(fontsize=7, loc="best", ncols=2)
        ax.set_xlabel("CPU relative to the reference (same seed)")
        ax.set_ylabel("Δ tracking error rms vs reference, paired [deg]")
        ax.set_title(f"{res['scene']} ({res['duration_s']:g} s, {len(res['seeds'])} seeds, 95 % intervals)")
    fig.suptitle("Simulation fidelity: effect on tracking vs cost (reference: all-exact)")
    return _save(fig, path)


def plot_sensing(axis: dict, path) -> Path:
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.3))
    for target, res in axis["targets"].items():
        rows = res["rows"]
        w = [r["window_ms"] for r in rows]
        lab = f"{target}: {res['scene']}"
        for ax, key, scale in ((axes[0], "p_detect", 1.0), (axes[1], "error_rms_all_deg", 1.0),
                               (axes[2], "latency_mean_s", 1000.0)):
            mh = [_mean_half((r.get("ci") or {}).get(key)) for r in rows]
            ax.errorbar(w, [None if m is None else scale * m for m, _ in mh],
                        yerr=[0.0 if h is None else scale * h for _, h in mh], fmt="o-", capsize=2, label=lab)
    for ax, yl in zip(axes, ("detection probability (target in FoV)", "tracking error rms, all frames [deg]",
                             "control latency, mean [ms]")):
        _log_axis(ax, "x")
        ax.set_xlabel("accumulation window [ms]")
        ax.set_ylabel(yl)
        ax.legend(fontsize=7)
    fig.suptitle("Sensing time: what a longer accumulation window buys and costs")
    return _save(fig, path)


def plot_coverage(axis: dict, windows_ms, path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for name, c in axis["coverage"].items():
        ax.plot(c["times_s"], [100 * v for v in c["coverage"]], label=f"{name} (voxel, {c['cells']} cells)")
    for w in windows_ms:
        ax.axvline(w / 1000, color="0.8", lw=0.8)
    ax.plot([0.3, 0.8], [50, 90], "k^", label="paper Fig. 6(e): 50 % at 0.3 s, 90 % at 0.8 s (real scene)")
    ax.set_xlabel("accumulation time [s] (grey: the study's windows)")
    ax.set_ylabel("FoV coverage [%]")
    ax.set_title("Coverage vs accumulation time (paper Fig. 6e, Appendix C voxel definition)")
    ax.legend(fontsize=8)
    return _save(fig, path)


def plot_calibration(axis: dict, path) -> Path:
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    rows = [r for r in axis["rows"] if r["plan"] not in ("truth",) and r["tilt_prior"]]
    plans = sorted({r["plan"] for r in rows if r["plan"] != "nominal"})
    for plan in plans:
        pr = [r for r in rows if r["plan"] == plan and _finite(r["cal_virtual_s"])]
        x = [r["cal_virtual_s"] for r in pr]
        axes[0].plot(x, [r["table_err_measured_pct"] for r in pr], "o-", label=f"{plan}: bytes measured")
        axes[0].plot(x, [r["table_err_all_pct"] for r in pr], "s--", label=f"{plan}: all bytes (interpolated too)")
        axes[1].plot(x, [r["pointing_rms_deg"] for r in pr], "o-", label=plan)
        for r, xi in zip(pr, x):
            axes[0].annotate(f"{r['dwell_s']:g} s", (xi, r["table_err_all_pct"]), textcoords="offset points",
                             xytext=(3, 3), fontsize=7)
    nom = next((r for r in rows if r["plan"] == "nominal"), None)
    if nom is not None:
        axes[0].axhline(nom["table_err_all_pct"], color="0.5", ls=":", label="no calibration (nominal table)")
        axes[1].axhline(nom["pointing_rms_deg"], color="0.5", ls=":", label="no calibration (nominal table)")
    _log_axis(axes[0], "y")
    axes[0].set_xlabel("calibration time [virtual s on the head]")
    axes[0].set_ylabel("speed-table error, rms [%]")
    axes[0].set_title("Speed table vs calibration time (cf. paper Fig. 11b)")
    _log_axis(axes[1], "y")
    axes[1].set_xlabel("calibration time [virtual s on the head]")
    axes[1].set_ylabel("head pointing reconstruction error, rms [deg]")
    axes[1].set_title("Dead reckoning with that table (fig12-tracking)")
    for r in axis["rows"]:
        if "pointing_t_s" in r and r["tilt_prior"] and r["plan"] != "truth":
            lab = "nominal" if r["plan"] == "nominal" else f"{r['plan']} {r['dwell_s']:g} s"
            axes[2].plot(r["pointing_t_s"], r["pointing_err_deg"], lw=0.9, label=lab)
    _log_axis(axes[2], "y")
    axes[2].set_xlabel("time in fig12-tracking [s]")
    axes[2].set_ylabel("pointing reconstruction error [deg]")
    axes[2].set_title("Error growth during tracking (first seed)")
    for ax in axes:
        ax.legend(fontsize=7)
    return _save(fig, path)


def plot_rate(axis: dict, path) -> Path:
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    for key, res in axis.items():
        for r in res["rows"]:
            ci = r.get("ci") or {}
            y, ye = _mean_half(ci.get("error_rms_all_deg"))
            for ax, k in ((a, "tracker_ms_per_frame"), (b, "sim_ms_per_frame")):
                x, xe = _mean_half(ci.get(k))
                if _finite(x) and _finite(y):
                    ax.errorbar(x, y, xerr=xe, yerr=ye, fmt="o" if r["preset"] == "mid40" else "s", ms=8, capsize=2)
                    ax.annotate(f"{res['scene']}: {r['preset']}", (x, y), textcoords="offset points", xytext=(4, 3),
                                fontsize=7)
    a.set_xlabel("tracker CPU per frame [ms] (runs on the real system)")
    b.set_xlabel("whole simulated frame, CPU [ms]")
    for ax in (a, b):
        ax.set_ylabel("tracking error rms over all frames [deg]")
    fig.suptitle("Point rate / channels: Mid-40 100 k single channel vs Horizon 240 k six channels (95 % intervals)")
    return _save(fig, path)


def plot_levers(axis: dict, path) -> Path:
    """Per lever: the paired change of the tracking error and of the world position error, and the
    CPU ratio, each with its interval."""
    plt = _plt()
    rows = axis["rows"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 0.45 * len(rows) + 1.8), sharey=True)
    ys = list(range(len(rows)))[::-1]
    for ax, get, xl in ((axes[0], lambda r: r["delta"]["error_rms_acq_deg"], "Δ tracking error after acquisition [deg]"),
                        (axes[1], lambda r: r["delta"]["recon_rms_m"], "Δ world position error rms [m]"),
                        (axes[2], lambda r: r["cost_ratio"], "CPU relative to the paper's loop")):
        for y, r in zip(ys, rows):
            m, h = _mean_half(get(r))
            if _finite(m):
                ax.errorbar(m, y, xerr=h, fmt="o", capsize=3, color="C0")
        ax.axvline(1.0 if ax is axes[2] else 0.0, color="0.5", ls="--", lw=0.8)
        ax.set_xlabel(xl)
    axes[0].set_yticks(ys, [r["lever"] for r in rows])
    fig.suptitle(f"Levers on {axis['scene']} ({axis['duration_s']:g} s, {len(axis['seeds'])} seeds, 95 % intervals, "
                 "paired with the reference)")
    return _save(fig, path)


def write_plots(results: dict, img_dir) -> dict[str, Path]:
    """Every plot of the study into ``img_dir``; returns {axis: path}."""
    img_dir = Path(img_dir)
    ax = results["axes"]
    windows = [r["window_ms"] for r in next(iter(ax["sensing"]["targets"].values()))["rows"]]
    return {
        "scan": plot_scan(ax["scan"], img_dir / FILES["scan"]),
        "fidelity": plot_fidelity(ax["fidelity"], img_dir / FILES["fidelity"]),
        "sensing": plot_sensing(ax["sensing"], img_dir / FILES["sensing"]),
        "coverage": plot_coverage(ax["sensing"], windows, img_dir / FILES["coverage"]),
        "calibration": plot_calibration(ax["calibration"], img_dir / FILES["calibration"]),
        "rate": plot_rate(ax["rate"], img_dir / FILES["rate"]),
        **({"levers": plot_levers(ax["levers"], img_dir / FILES["levers"])} if ax.get("levers") else {}),
    }
