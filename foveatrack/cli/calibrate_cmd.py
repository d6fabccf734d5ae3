"""``foveatrack calibrate``: measure the head's speed table by tracking a room corner (paper App. D.4).

Simulated::

    foveatrack calibrate --scene scenes/calibration-room.toml [--unit-seed N] [--out table.json]
                         [--plot F.png] [--json]

runs :class:`foveatrack.calibration.Calibrator` against the simulated PTS-303H over the virtual UART
(``sim.calibration_run``), writes the speed table (JSON: unit, date, per-entry uncertainty; see
:mod:`foveatrack.speed_table`), prints the entries it could not measure and, since the unit's truth is
known in simulation, each measured entry's error.  The report's warnings (a table written that may
be wrong, and why) go to stderr last, in text and ``--json`` alike, and into the JSON summary's
``warnings``.

Real hardware (a Livox and a head on a serial port)::

    foveatrack calibrate --config DAEMON.toml --corner X Y Z [--lidar IP] [--serial PORT]
                         [--out table.json] [--plot F.png] [--json] [--max-s S]

reads the devices, limits and start pose from the daemon's config (``--lidar``/``--serial`` replace
its ``[lidar] sensor_ip`` and ``[head] port``) and runs the same procedure on the live stream
(:func:`foveatrack.calibration.live.calibrate_live`); ``--corner`` is where the room corner is in
the lidar frame at the start, within 1 m.  The table is written only when the procedure completes;
the head is stopped at the end, on Ctrl-C and on any error.
"""

from __future__ import annotations

import json
import math
import sys

from foveatrack.calibration import FeatureSpec
from foveatrack.config_util import check_outputs, seed_arg
from foveatrack.errors import UserError
from foveatrack.speed_table import TURBO
from foveatrack.speed_table import byte_ranges as ranges  # the name its callers and tests use


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="measure the head's speed table by tracking a room corner (App. D.4)")
    p.add_argument("--scene", metavar="SCENE.toml", help="simulate: a scene with a room corner in view "
                   "(scenes/calibration-room.toml)")
    p.add_argument("--config", metavar="DAEMON.toml", help="real hardware: the daemon config naming the lidar "
                   "and the head (ports, limits, start pose)")
    p.add_argument("--unit-seed", type=seed_arg, metavar="N", help="simulate another unit of the head family")
    p.add_argument("--out", metavar="TABLE.json", default="speed-table.json",
                   help="where to write the speed table (default: %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="replace a --out table that exists (else refused)")
    p.add_argument("--plot", metavar="F.png", help="plot measured speeds (and the truth, when simulated)")
    p.add_argument("--json", action="store_true", help="print a JSON summary instead of text")
    p.add_argument("--pan-bytes", metavar="B,B,...", help="pan bytes to measure (0-63, 'turbo'); "
                   "others are interpolated (default: 18 bytes + turbo)")
    p.add_argument("--tilt-bytes", metavar="B,B,...", help="tilt bytes to measure (0-63)")
    p.add_argument("--dwell-s", type=float, help="max seconds per leg (default 6)")
    p.add_argument("--corner", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="approximate corner position in the lidar frame [m], within 1 m (real hardware: "
                   "required; simulated: from the scene)")
    p.add_argument("--seed", type=seed_arg, default=0, help="RANSAC seed of the corner finder")
    p.add_argument("--lidar", metavar="IP", help="real hardware: the Livox's IP (replaces the config's "
                   "[lidar] sensor_ip)")
    p.add_argument("--serial", metavar="PORT", help="real hardware: the head's serial port (replaces the "
                   "config's [head] port)")
    p.add_argument("--max-s", type=float, metavar="S", help="real hardware: give up after S seconds "
                   "(default: no limit)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_calibrate)


def _bytes(text: str | None, what: str) -> tuple[int, ...] | None:
    if text is None:
        return None
    out = []
    for tok in text.split(","):
        tok = tok.strip().lower()
        if not tok:
            continue
        try:
            out.append(TURBO if tok == "turbo" else int(tok, 0))
        except ValueError:
            raise UserError(f"{what}: {tok!r} is not a byte (0-63, 0x3F, or 'turbo' for pan)") from None
    if not out:
        raise UserError(f"{what}: give at least one byte")
    return tuple(out)


def unmeasured_summary(report) -> dict:
    """{axis: {reason: [bytes]}} from a CalibrationReport."""
    out = {}
    for axis, d in report.unmeasured.items():
        by = {}
        for b, reason in d.items():
            by.setdefault(reason, []).append(b)
        out[axis] = by
    return out


def cmd_calibrate(args) -> int:
    if args.config and args.scene:
        raise UserError("calibrate: give --scene (simulated head) or --config (real devices), not both")
    if args.config or args.lidar or args.serial:
        return calibrate_devices(args)
    if args.unit_seed is not None and not args.scene:
        raise UserError("--unit-seed picks a simulated unit: it needs --scene")
    if not args.scene:
        raise UserError("calibrate needs --scene SCENE.toml (simulated, e.g. scenes/calibration-room.toml) "
                        "or --config DAEMON.toml --corner X Y Z (a real lidar and head)")
    _check_outputs(args)
    run = calibrate_scene(args)
    table = run.table
    table.save(args.out)
    summary = {
        "table": str(args.out), "head": table.head, "date": table.date,
        "frames": run.frames, "virtual_s": round(run.virtual_s, 1), "wall_s": round(run.wall_s, 2),
        "dead_time_s": table.dead_time_s, "accel_deg_s2": table.accel_deg_s2,
        "implied_start_tilt_deg": run.report.implied_start_tilt_deg,
        "head_start_deg": list(run.head_start_deg), "head_end_deg": list(run.head_end_deg),
        "unmeasured": {a: {r: bs for r, bs in d.items()} for a, d in unmeasured_summary(run.report).items()},
        "entries": run.comparison,
        "within_tolerance": sum(r["ok"] for r in run.comparison),
        "measured": len(run.comparison),
        "warnings": list(run.report.warnings),
    }
    if args.plot:
        _plot(run.table, run.comparison, args.plot, truth=run.truth)
    if args.json:
        return _print_json(summary)
    print(f"calibrated {table.head}: {run.frames} frames ({run.virtual_s:.0f} s virtual, {run.wall_s:.1f} s wall)")
    print(f"  {'axis':4s} {'byte':>5s} {'measured':>9s} {'sigma':>7s} {'true':>9s} {'error':>8s}   speeds in deg/s")
    for r in run.comparison:
        b = "turbo" if r["byte"] == TURBO else str(r["byte"])
        e = "-" if r["error_pct"] is None else f"{r['error_pct']:+.2f}%"
        print(f"  {r['axis']:4s} {b:>5s} {r['measured_deg_s']:9.4f} {r['sigma_deg_s']:7.4f} {r['true_deg_s']:9.4f} "
              f"{e:>8s}{'' if r['ok'] else '  OUTSIDE max(2 %, 3 sigma)'}")
    print(f"  {summary['within_tolerance']}/{summary['measured']} measured entries within max(2 %, 3 sigma) of the truth")
    _print_unmeasured(summary["unmeasured"])
    # per axis (heads accelerate their two axes differently; the table-wide value alone was pan's)
    acc = ", ".join(f"{a} {'-' if v is None else f'{v:.1f}'}" for a, v in
                    ((a, table.axis_accel_deg_s2(a)) for a in ("pan", "tilt")))
    print(f"  dead time {table.dead_time_s * 1e3:.0f} ms, acceleration {acc} deg/s^2; head back at pan "
          f"{run.head_end_deg[0]:.2f}, tilt {run.head_end_deg[1]:.2f} deg (started {run.head_start_deg[0]:.2f}, "
          f"{run.head_start_deg[1]:.2f})")
    print(f"  table written to {args.out}")
    _print_warnings(summary["warnings"])
    return 0


def _print_json(summary) -> int:
    json.dump(summary, sys.stdout, indent=2, default=_jsonable)
    sys.stdout.write("\n")
    _print_warnings(summary["warnings"])
    return 0


def _print_warnings(warnings) -> None:
    """The report's warnings on stderr, last (text and ``--json`` alike: stdout stays the summary)."""
    for w in warnings:
        print(f"calibrate: warning: {w}", file=sys.stderr)


def _print_unmeasured(unmeasured: dict) -> None:
    for axis, d in unmeasured.items():
        for reason, bs in d.items():
            print(f"  not measured, {axis}: {ranges(bs)}  ({reason})")


def _plan_overrides(args) -> dict:
    kw = {}
    pb, tb = _bytes(args.pan_bytes, "--pan-bytes"), _bytes(args.tilt_bytes, "--tilt-bytes")
    if pb is not None:
        kw["pan_bytes"] = pb
    if tb is not None:
        kw["tilt_bytes"] = tb
    if args.dwell_s is not None:
        # the plan's own check (CalibrationPlan.__post_init__: dwell_s > settle_s) speaks of its
        # fields; a user typed --dwell-s, so name the flag and its range here
        from foveatrack.calibration import CalibrationPlan

        settle = CalibrationPlan.settle_s
        if not (math.isfinite(args.dwell_s) and args.dwell_s > settle):
            raise UserError(f"--dwell-s {args.dwell_s:g}: must be a finite number of seconds > {settle:g} (each leg "
                            f"first discards {settle:g} s while the head settles); default "
                            f"{CalibrationPlan.dwell_s:g}")
        kw["dwell_s"] = args.dwell_s
    return kw


def measured_rows(table) -> list[dict]:
    """Per measured entry of a table: axis, byte, measured speed and its sigma."""
    from foveatrack.speed_table import axis_bytes

    rows = []
    for axis in ("pan", "tilt"):
        ax = table.axis(axis)
        rows += [{"axis": axis, "byte": b, "measured_deg_s": ax.speed_deg_s(b), "sigma_deg_s": ax.sigma_deg_s(b)}
                 for b in axis_bytes(axis) if ax.is_measured(b)]
    return rows


def _check_outputs(args) -> None:
    # before minutes of calibration, not after; a table that exists (perhaps the one a daemon config
    # names, measured on the live head) is not replaced unasked
    # ... nor a plot (--plot replaced an existing file where --out refused one)
    check_outputs([("--out", args.out), ("--plot", args.plot)], overwrite=args.overwrite)


def calibrate_devices(args) -> int:
    """``calibrate --config DAEMON.toml``: the procedure on a real (or virtual) lidar and head."""
    from dataclasses import replace

    from foveatrack.cli.stop_signals import stop_on_signals
    from foveatrack.calibration import CalibrationPlan
    from foveatrack.calibration.live import calibrate_live, delay_summary_ms
    from foveatrack.device_config import load_config

    if not args.config:
        raise UserError("--lidar/--serial calibrate real devices: they need --config DAEMON.toml (the daemon's "
                        "config names the rest: host address, baud, Pelco address, limits, start pose)")
    if args.unit_seed is not None:
        raise UserError("--unit-seed picks a simulated unit; with --config the unit is the real head")
    if not args.corner:
        raise UserError("calibrate --config needs --corner X Y Z: where the room corner is in the lidar "
                        "frame [m] at the start (X forward, Y left, Z up), within 1 m")
    if args.max_s is not None and not args.max_s > 0:
        raise UserError(f"--max-s must be > 0, got {args.max_s}")
    _check_outputs(args)
    cfg = load_config(args.config)
    if args.lidar:
        cfg = replace(cfg, lidar=replace(cfg.lidar, sensor_ip=args.lidar))
    if args.serial:
        cfg = cfg.with_head_port(args.serial, "--serial")
    plan = CalibrationPlan(**_plan_overrides(args))
    bar = None
    progress = None
    if not args.no_progress and not args.json:
        from tqdm import tqdm

        bar = tqdm(total=None, desc="calibrating", unit=" leg", file=sys.stderr, leave=False)

        def progress(frames, legs, total):
            if bar.total != total:
                bar.total = total
            if legs != bar.n:
                bar.update(legs - bar.n)
    try:
        with stop_on_signals() as stop:     # Ctrl-C / SIGTERM: the run stops the head and ends its own way
            run = calibrate_live(cfg, plan, FeatureSpec(tuple(args.corner), radius_m=1.0), seed=args.seed,
                                 max_s=args.max_s, stop=stop, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    table = run.table
    table.save(args.out)
    rows = measured_rows(table)
    delays = delay_summary_ms(run.delay_ms)
    summary = {
        "table": str(args.out), "head": table.head, "date": table.date, "frames": run.frames,
        "wall_s": round(run.wall_s, 2), "dead_time_s": table.dead_time_s, "accel_deg_s2": table.accel_deg_s2,
        "implied_start_tilt_deg": run.report.implied_start_tilt_deg,
        "left_out_by_limits": run.dropped_bytes,
        "command_delay_ms": None if delays is None else {"median": delays[0], "p95": delays[1]},
        "latency_assumed_ms": run.plan.latency_s * 1e3,
        "unmeasured": unmeasured_summary(run.report), "entries": rows, "counters": run.counters,
        "warnings": list(run.report.warnings),
    }
    if args.plot:
        _plot(table, rows, args.plot)
    if args.json:
        return _print_json(summary)
    print(f"calibrated {table.head}: {run.frames} frames in {run.wall_s:.1f} s")
    print(f"  {'axis':4s} {'byte':>5s} {'measured':>9s} {'sigma':>7s}   speeds in deg/s")
    for r in rows:
        b = "turbo" if r["byte"] == TURBO else str(r["byte"])
        print(f"  {r['axis']:4s} {b:>5s} {r['measured_deg_s']:9.4f} {r['sigma_deg_s']:7.4f}")
    for axis, bs in run.dropped_bytes.items():
        print(f"  not measured, {axis}: {ranges(bs)}  (beyond the config's [head] limits)")
    _print_unmeasured(summary["unmeasured"])
    acc = "-" if table.accel_deg_s2 is None else f"{table.accel_deg_s2:.1f}"
    print(f"  dead time {table.dead_time_s * 1e3:.0f} ms, acceleration {acc} deg/s^2")
    if delays is not None:
        print(f"  commands left {delays[0]:.1f} ms (median; p95 {delays[1]:.1f}) after their frame's last point; "
              f"the plan assumed {run.plan.latency_s * 1e3:.1f} ms to the head")
    print(f"  table written to {args.out}")
    _print_warnings(summary["warnings"])
    return 0


def calibrate_scene(args):
    from sim.calibration_run import default_plan, run_calibration
    from sim.scene import load_scene

    scene = load_scene(args.scene)
    plan = default_plan(scene, **_plan_overrides(args))
    feature = FeatureSpec(tuple(args.corner)) if args.corner else None
    progress = None
    bar = None
    if not args.no_progress and not args.json:
        from tqdm import tqdm

        bar = tqdm(total=None, desc="calibrating", unit=" s virtual", file=sys.stderr, leave=False)
        last = [0.0]

        def progress(t_s, budget_s):
            if t_s - last[0] >= 1.0:
                bar.update(t_s - last[0])
                last[0] = t_s
    try:
        return run_calibration(scene, plan, feature, unit_seed=args.unit_seed, seed=args.seed, progress=progress)
    finally:
        if bar is not None:
            bar.close()


def _jsonable(o):
    if isinstance(o, float) and not math.isfinite(o):
        return None
    try:
        return float(o)
    except (TypeError, ValueError):
        return str(o)


def _plot(table, rows_all, path, truth=None) -> None:
    """Measured speeds (3 sigma bars), the table between them and, when simulated, the truth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axs = plt.subplots(1, 2, figsize=(11, 4.4))
    for ax, axis in zip(axs, ("pan", "tilt")):
        b = np.arange(64)
        shown = []    # the speeds the y range is fitted to (an error bar may reach past it)
        if truth is not None:
            tr = truth.axis(axis)
            true_v = [tr.speed_deg_s(int(x)) for x in b]
            ax.plot(b, true_v, "-", color="0.6", label="true (simulated unit)")
            shown += true_v
        rows = [r for r in rows_all if r["axis"] == axis and r["byte"] != TURBO]
        ax.errorbar([r["byte"] for r in rows], [r["measured_deg_s"] for r in rows],
                    yerr=[3 * r["sigma_deg_s"] for r in rows], fmt="o", ms=4, capsize=3, label="measured (3 sigma)")
        t = table.axis(axis)
        table_v = [t.speed_deg_s(int(x)) for x in b]
        ax.plot(b, table_v, ":", lw=1, label="table (interpolated)")
        shown += table_v + [r["measured_deg_s"] for r in rows]
        turbo = [r for r in rows_all if r["axis"] == axis and r["byte"] == TURBO]
        if turbo:
            ax.errorbar([66], [turbo[0]["measured_deg_s"]], yerr=[3 * turbo[0]["sigma_deg_s"]], fmt="s", ms=4,
                        capsize=3, label="turbo (0xFF), drawn at 66")
            shown.append(turbo[0]["measured_deg_s"])
            if truth is not None:
                ax.plot([66], [tr.speed_deg_s(TURBO)], "x", color="0.4")
                shown.append(tr.speed_deg_s(TURBO))
        # A speed is >= 0, and one short leg's wide 3-sigma bar must not squash the curve: fit the range
        # to the speeds and write the size of any bar cut at the top beside its point.
        top = 1.35 * max([v for v in shown if np.isfinite(v)] or [1.0])
        ax.set_ylim(0, top)
        for r in rows + turbo:
            if r["measured_deg_s"] + 3 * r["sigma_deg_s"] > top:
                x = 66 if r["byte"] == TURBO else r["byte"]
                ax.annotate(f"3 sigma = {3 * r['sigma_deg_s']:.2f} deg/s (bar cut)", (x, r["measured_deg_s"]),
                            xytext=(-6 if x > 40 else 6, 8), textcoords="offset points", fontsize=8, color="C0",
                            ha="right" if x > 40 else "left")
        ax.set_xlabel("Pelco-D speed byte")
        ax.set_ylabel(f"{axis} speed [deg/s]")
        ax.set_title(axis, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    fig.suptitle(f"speed table of {table.head}: measured speed per speed byte")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
