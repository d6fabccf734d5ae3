"""Plots of the accuracy-vs-time study (PNG), one per axis, from :func:`sim.study.runner.run_study`'s
results (plain dicts; nothing here runs a simulation)."""

from __future__ import annotations

from pathlib import Path

from foveatrack.cli.scan_plots import _plt, _save

FILES = {"scan": "scan-model.png", "fidelity": "sim-fidelity.png", "sensing": "sensing-window.png",
         "coverage": "coverage.png", "calibration": "calibration.png", "rate": "point-rate.png"}


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
    a.set_xscale("log")
    a.set_yscale("log")
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
    plt = _plt()
    keys = list(axis)
    fig, axes = plt.subplots(1, len(keys), figsize=(6.5 * len(keys), 4.8), squeeze=False)
    for ax, key in zip(axes[0], keys):
        res = axis[key]
        # one legend entry per setting, each its own colour and marker: settings that cost about the
        # same sit on top of each other, and their labels ran together ("basefine10ms")
        markers = "osD^vP<>Xph"
        for i, r in enumerate(res["rows"]):
            x, y = r["cpu_per_virtual_s"], r["d_error_rms_all_deg"]
            if not (_finite(x) and _finite(y)):
                continue
            ref = r["setting"] == res["reference"]
            ax.plot(x, max(y, 1e-4), "*" if ref else markers[i % len(markers)], ms=13 if ref else 7,
                    mfc="none" if not ref else None, mew=1.4, ls="none",
                    label=f"{r['setting']} (reference)" if ref else r["setting"])
        fl = res["noise_floor"].get("error_rms_all_deg")
        if _finite(fl) and fl > 0:
            ax.axhline(fl, color="0.5", ls="--", lw=0.8, label=f"seed-to-seed spread {fl:.3g} deg")
        ax.legend(fontsize=7, loc="best", ncols=2)
        ax.set_yscale("log")
        ax.set_xscale("log")
        ax.set_xlabel("CPU seconds per virtual second")
        ax.set_ylabel("|tracking error rms - reference| [deg] (0 drawn at 1e-4)")
        ax.set_title(f"{res['scene']} ({res['duration_s']:g} s, {len(res['seeds'])} seeds)")
    fig.suptitle("Simulation fidelity: effect on tracking vs cost (reference: all-exact)")
    return _save(fig, path)


def plot_sensing(axis: dict, path) -> Path:
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.3))
    for target, res in axis["targets"].items():
        rows = res["rows"]
        w = [r["window_ms"] for r in rows]
        lab = f"{target}: {res['scene']}"
        axes[0].plot(w, [r["p_detect"] for r in rows], "o-", label=lab)
        axes[1].plot(w, [r["bearing_rms_deg"] for r in rows], "o-", label=lab)
        axes[2].plot(w, [None if r["latency_mean_s"] is None else 1000 * r["latency_mean_s"] for r in rows], "o-", label=lab)
    for ax, yl in zip(axes, ("detection probability (target in FoV)", "bearing error rms [deg]",
                             "control latency, mean [ms]")):
        ax.set_xscale("log")
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
    axes[0].set_yscale("log")
    axes[0].set_xlabel("calibration time [virtual s on the head]")
    axes[0].set_ylabel("speed-table error, rms [%]")
    axes[0].set_title("Speed table vs calibration time (cf. paper Fig. 11b)")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("calibration time [virtual s on the head]")
    axes[1].set_ylabel("head pointing reconstruction error, rms [deg]")
    axes[1].set_title("Dead reckoning with that table (fig12-tracking)")
    for r in axis["rows"]:
        if "pointing_t_s" in r and r["tilt_prior"] and r["plan"] != "truth":
            lab = "nominal" if r["plan"] == "nominal" else f"{r['plan']} {r['dwell_s']:g} s"
            axes[2].plot(r["pointing_t_s"], r["pointing_err_deg"], lw=0.9, label=lab)
    axes[2].set_yscale("log")
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
            for ax, x in ((a, r["tracker_ms_per_frame"]), (b, r["sim_ms_per_frame"])):
                if _finite(x) and _finite(r["error_rms_all_deg"]):
                    ax.plot(x, r["error_rms_all_deg"], "o" if r["preset"] == "mid40" else "s", ms=8)
                    ax.annotate(f"{res['scene']}: {r['preset']}", (x, r["error_rms_all_deg"]),
                                textcoords="offset points", xytext=(4, 3), fontsize=7)
    a.set_xlabel("tracker CPU per frame [ms] (runs on the real system)")
    b.set_xlabel("whole simulated frame, CPU [ms]")
    for ax in (a, b):
        ax.set_ylabel("tracking error rms over all frames [deg]")
    fig.suptitle("Point rate / channels: Mid-40 100 k single channel vs Horizon 240 k six channels")
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
    }
