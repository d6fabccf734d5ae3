"""``foveatrack calibrate-imu``: the lidar-IMU extrinsic from static poses (paper Section IV.A,
Fig. 10-11), on the simulated rig or on a real one.

Simulated::

    foveatrack calibrate-imu SCENE.toml [--lidar mid40,horizon,vlp16] [--accumulate 0.1,0.2,...,10]
                             [--out X.json] [--plot F.png] [--json] [--bootstrap N]

The scene's ``[imu]`` gives the true mount and ``[imu_poses]`` the pose sequence
(``docs/imu-calibration.md``).  For each lidar and accumulation time the procedure of
:mod:`foveatrack.imu_calib.procedure` runs on the same poses and IMU data; the error of eq. (8)
against the true lidar motion, and the extrinsic's error against the true mount, are printed.
``--out`` gets the extrinsic of the first lidar at the longest accumulation, with its 1-sigma
(:mod:`foveatrack.imu_calib.uncertainty`: none, ``null``, when the pairs are too few to give one)
and the warnings of the solve (pairs removed, axes close together), which are also printed on stderr.  ``--plot``: eq. (8) error and extrinsic error against accumulation time (Fig. 11b) beside
the coverage of the Risley lidars (Fig. 6e).

Real rig (a Livox with an IMU on the daemon's head)::

    foveatrack calibrate-imu --config DAEMON.toml [--by-hand] [--poses N] [--step-deg D]
                             [--tilt-step-deg D] [--dwell-s S] [--settle-s S] [--speed-deg-s V]
                             [--lidar-ip IP] [--serial PORT] [--max-s S] [--out X.json] [--json]

steps the head through static poses by Pelco-D (or, ``--by-hand``, prompts for each pose and waits
for Enter), gathers each pose's cloud and every IMU sample from the live stream and runs the same
procedure (:mod:`foveatrack.imu_calib.live`); ``--out`` (default ``imu-extrinsic.json``) gets the
extrinsic in the simulated command's format, without truth.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from foveatrack.config_util import check_outputs
from foveatrack.errors import UserError


def _floats(text: str, flag: str) -> list[float]:
    try:
        vals = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"{flag} {text!r}: a comma-separated list of seconds, e.g. 0.1,0.5,1,10") from None
    if not vals or any(not (v > 0) for v in vals):
        raise UserError(f"{flag} {text!r}: every time must be > 0 s")
    return vals


def register(sub) -> None:
    p = sub.add_parser("calibrate-imu", help="lidar-IMU extrinsic from static poses (paper Sec. IV.A, Fig. 11)")
    p.add_argument("scene", metavar="SCENE.toml", nargs="?", help="simulate: a scene with [imu] and [imu_poses] "
                   "(scenes/imu-calibration-room.toml)")
    live = p.add_argument_group("real rig (a Livox with an IMU on the daemon's head)")
    live.add_argument("--config", metavar="DAEMON.toml", help="the daemon config naming the lidar and the head")
    live.add_argument("--by-hand", action="store_true", help="do not drive the head: prompt for each pose and "
                      "wait for Enter (the rig moved by hand)")
    live.add_argument("--poses", type=int, metavar="N", help="static poses (default: 25)")
    live.add_argument("--step-deg", type=float, metavar="DEG", help="pan step between poses (default: 10)")
    live.add_argument("--tilt-step-deg", type=float, metavar="DEG",
                      help="tilt step between poses (default: --step-deg)")
    live.add_argument("--dwell-s", type=float, metavar="S", help="accumulation per pose (default: 10)")
    live.add_argument("--settle-s", type=float, metavar="S",
                      help="wait after each stop before the pose's window opens (default: 1)")
    live.add_argument("--speed-deg-s", type=float, metavar="DEG/S",
                      help="head speed while moving, per axis, within the config's limits (default: 10)")
    live.add_argument("--lidar-ip", metavar="IP", help="the Livox's IP (replaces the config's [lidar] sensor_ip)")
    live.add_argument("--serial", metavar="PORT", help="the head's serial port (replaces the config's [head] port)")
    live.add_argument("--max-s", type=float, metavar="S", help="give up after S seconds (default: no limit)")
    p.add_argument("--accumulate", default="0.1,0.2,0.5,1,2,5,10", metavar="S,S,...",
                   help="accumulation times per pose [s] (default: %(default)s)")
    p.add_argument("--lidar", metavar="NAME,...", help="lidars to compare (Risley presets prototype, mid40, horizon, "
                   "mid70, avia, tele15, mid100; spinning vlp16); default: the scene's [lidar] preset")
    p.add_argument("--out", metavar="X.json", help="write the extrinsic (first lidar, longest accumulation)")
    p.add_argument("--overwrite", action="store_true", help="replace an --out file that exists (else refused)")
    p.add_argument("--plot", metavar="F.png", help="plot error vs accumulation time beside coverage")
    p.add_argument("--json", action="store_true", help="print a JSON summary instead of text")
    p.add_argument("--bootstrap", type=int, default=200, metavar="N", help="bootstrap resamples for the "
                   "1-sigma (default: %(default)s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=cmd_calibrate_imu)


def _extrinsic_json(score, res, truth=None) -> dict:
    from scipy.spatial.transform import Rotation

    out = extrinsic_record(res, score.lidar, score.accumulate_s)
    if truth is not None:
        out["truth_translation_m"] = truth[:3, 3].round(6).tolist()
        out["truth_rotation_rpy_deg"] = Rotation.from_matrix(truth[:3, :3]).as_euler("xyz", degrees=True).round(5).tolist()
        out["error_rotation_deg"] = round(score.rotation_error_deg, 5)
        out["error_translation_m"] = round(score.translation_error_m, 6)
    return out


def _sigma(values, digits: int):
    """A 1-sigma for JSON: rounded, or None where none is given (NaN)."""
    return [round(float(v), digits) if np.isfinite(v) else None for v in values]


def extrinsic_record(res, lidar: str, accumulate_s: float) -> dict:
    """The extrinsic file's fields, simulated or live: ``X``, its 1-sigma, what solved it, warnings."""
    from scipy.spatial.transform import Rotation

    X = res.X
    unc = res.uncertainty
    out = {
        "frame": "T_lidar_imu: the IMU's pose in the lidar frame (p_lidar = R p_imu + t)",
        "rotation_matrix": X[:3, :3].round(9).tolist(),
        "rotation_rpy_deg": Rotation.from_matrix(X[:3, :3]).as_euler("xyz", degrees=True).round(5).tolist(),
        "translation_m": X[:3, 3].round(6).tolist(),
        "sigma_rotation_deg": _sigma(unc.rotation_sigma_deg, 5),
        "sigma_translation_m": _sigma(unc.translation_sigma_m, 6),
        # 1-sigma of the total rotation angle and translation distance (root of the summed per-axis variances)
        "sigma_rotation_total_deg": _sigma([unc.rotation_rss_deg], 5)[0],
        "sigma_translation_total_m": _sigma([unc.translation_rss_m], 6)[0],
        "sigma_method": unc.method,
        "lidar": lidar,
        "accumulate_s": accumulate_s,
        "pairs": res.handeye.pairs_used,
        "pairs_removed": [r.index + 1 for r in res.removed],
        # pairs whose registration fixed no translation along these directions (lidar frame of the
        # pair's first pose: the planes in view did not face them): their translation along them is unused
        "pairs_translation_free": [{"pair": i + 1, "directions": np.round(r.free_directions, 4).tolist()}
                                   for i, r in enumerate(res.registrations) if len(r.free_directions)],
        "axis_spread_deg": round(res.handeye.axis_spread_deg, 3),
        "consistency_eq8_mean": float(np.mean(res.consistency())),
        "warnings": list(res.warnings),
    }
    return out


def _print_warnings(warnings, prefix: str = "") -> None:
    for w in warnings:
        print(f"calibrate-imu: warning: {prefix}{w}", file=sys.stderr)


def _sigma_text(value, scale: float, unit: str, width: int, digits: int) -> str:
    return f"{value * scale:{width}.{digits}f} {unit}" if value is not None else f"{'none':>{width}} {unit}"


def cmd_calibrate_imu(args) -> int:
    if args.bootstrap < 0:
        raise UserError(f"--bootstrap {args.bootstrap}: must be >= 0")
    live_flags = [f for f, v in (("--by-hand", args.by_hand), ("--lidar-ip", args.lidar_ip), ("--serial", args.serial),
                                 ("--max-s", args.max_s), ("--poses", args.poses), ("--step-deg", args.step_deg),
                                 ("--tilt-step-deg", args.tilt_step_deg), ("--dwell-s", args.dwell_s),
                                 ("--settle-s", args.settle_s), ("--speed-deg-s", args.speed_deg_s))
                  if v is not None and v is not False]
    if args.config and args.scene:
        raise UserError("calibrate-imu: give SCENE.toml (simulated rig) or --config DAEMON.toml (real rig), not both")
    if args.scene and live_flags:
        raise UserError(f"{', '.join(live_flags)}: real-rig options; a simulated rig takes its poses from the scene's "
                        "[imu_poses] (give --config DAEMON.toml instead of SCENE.toml for a real rig)")
    if args.config or live_flags:
        return calibrate_live_rig(args, live_flags)
    if not args.scene:
        raise UserError("calibrate-imu needs SCENE.toml (simulated, e.g. scenes/imu-calibration-room.toml) or "
                        "--config DAEMON.toml (a Livox with an IMU on the daemon's head)")
    from sim import imu_rig
    from sim.scene import load_scene

    acc = sorted(set(_floats(args.accumulate, "--accumulate")))
    # an extrinsic that exists is kept, and so is a plot
    check_outputs([("--out", args.out), ("--plot", args.plot)], overwrite=args.overwrite)
    scene = load_scene(args.scene)
    lidars = [s.strip() for s in args.lidar.split(",") if s.strip()] if args.lidar else [scene.optics.name]
    for name in lidars:
        imu_rig.scan_model_for(scene, name)   # unknown names fail here, before any work
    if acc:
        imu_rig.check_rig_scene(scene, max(acc))   # and a scene without [imu]: before the progress bar

    def bar(total, desc):
        if args.no_progress:
            return None
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, file=sys.stderr, leave=False)

    t0 = time.perf_counter()
    data, results = imu_rig.run(scene, lidars, acc, bootstrap_samples=args.bootstrap, progress_factory=bar)
    wall_s = time.perf_counter() - t0
    coverage = None
    if args.plot:
        coverage = imu_rig.coverage_curves(scene, lidars, max(acc))
    first = results[lidars[0]][-1]
    extrinsic = _extrinsic_json(first[1], first[0], data.X_true)
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(extrinsic, fh, indent=2)
            fh.write("\n")
    rows = [imu_rig.score_row(s) for name in lidars for _, s in results[name]]
    for name in lidars:
        for res, s in results[name]:
            _print_warnings(res.warnings, f"{name}, {s.accumulate_s:g} s: ")
    if args.plot:
        from foveatrack.cli.imu_calib_plots import plot_error_vs_accumulation

        plot_error_vs_accumulation(rows, coverage, args.plot, scene.name,
                                   " ".join(["foveatrack calibrate-imu", str(args.scene)]       # the command as given
                                            + ([f"--lidar {args.lidar}"] if args.lidar else [])
                                            + [f"--accumulate {args.accumulate}", f"--plot {args.plot}"]
                                            + ([f"--out {args.out}"] if args.out else [])))
    summary = {"scene": scene.name, "poses": len(data.lidar_poses), "wall_s": round(wall_s, 1),
               "extrinsic": extrinsic, "rows": rows}
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"scene {scene.name}: {len(data.lidar_poses)} static poses, {len(data.lidar_poses) - 1} pairs; "
          f"{wall_s:.1f} s wall")
    # the 1-sigma beside each total error is that of the total (root of the summed per-axis variances)
    print(f"{'lidar':8} {'T [s]':>6} {'pts/pose':>9} {'eq8':>8} {'rot err':>9} {'1-sigma':>9} {'trans err':>10} "
          f"{'1-sigma':>10} {'reg rot':>8} {'reg tr':>8} {'removed':>7}")
    for r in rows:
        print(f"{r['lidar']:8} {r['accumulate_s']:6.1f} {r['points_per_pose']:9.0f} {r['eq8_mean']:8.5f} "
              f"{r['rotation_error_deg']:7.4f} d {_sigma_text(r['rotation_rss_sigma_deg'], 1, 'd', 7, 4)} "
              f"{r['translation_error_m'] * 100:7.3f} cm {_sigma_text(r['translation_rss_sigma_m'], 100, 'cm', 7, 3)} "
              f"{r['registration_rotation_deg']:6.4f} d {r['registration_translation_m'] * 100:5.3f} cm "
              f"{','.join(str(i + 1) for i in r['removed_pairs']) or '-':>7}")
    for name in lidars:
        r = [x for x in rows if x["lidar"] == name][-1]
        print(f"what the noise allows ({name}, {r['accumulate_s']:g} s): true lidar motions with the IMU's -> "
              f"{r['imu_floor_rotation_deg']:.4f} deg, {r['imu_floor_translation_m'] * 100:.3f} cm; registered lidar "
              f"motions with the true IMU's -> {r['lidar_floor_rotation_deg']:.4f} deg, "
              f"{r['lidar_floor_translation_m'] * 100:.3f} cm")
    e = extrinsic
    print(f"extrinsic ({e['lidar']}, {e['accumulate_s']:g} s): rpy {e['rotation_rpy_deg']} deg "
          f"(truth {e['truth_rotation_rpy_deg']}), t {e['translation_m']} m (truth {e['truth_translation_m']})"
          + (f" -> {args.out}" if args.out else ""))
    if args.plot:
        print(f"plot: {args.plot}")
    return 0


def calibrate_live_rig(args, live_flags: list[str]) -> int:
    """``calibrate-imu --config DAEMON.toml [--by-hand]``: the procedure on a live lidar and head."""
    from dataclasses import replace

    from foveatrack.cli.stop_signals import stop_on_signals
    from foveatrack.device_config import load_config
    from foveatrack.imu_calib.live import RigPlan, calibrate_rig

    if not args.config:
        raise UserError(f"{', '.join(live_flags)} calibrate a real rig: they need --config DAEMON.toml (the daemon's "
                        "config names the lidar, the head and its limits)")
    if args.lidar:
        raise UserError("--lidar names simulated lidars; on a real rig the lidar is the config's (--lidar-ip IP "
                        "replaces its [lidar] sensor_ip)")
    if args.plot:
        raise UserError("--plot draws the simulated error-vs-accumulation curves; a real rig has no truth to plot")
    if args.max_s is not None and not args.max_s > 0:
        raise UserError(f"--max-s must be > 0, got {args.max_s}")
    out = args.out or "imu-extrinsic.json"
    check_outputs([("--out", out)], overwrite=args.overwrite)
    given = {k: getattr(args, k) for k in ("poses", "step_deg", "tilt_step_deg", "dwell_s", "settle_s", "speed_deg_s")
             if getattr(args, k) is not None}
    plan = RigPlan(**given)
    plan.check_axes()
    cfg = load_config(args.config)
    if args.lidar_ip:
        cfg = replace(cfg, lidar=replace(cfg.lidar, sensor_ip=args.lidar_ip))
    if args.serial:
        cfg = cfg.with_head_port(args.serial, "--serial")
    bar = None
    progress = None
    if not args.no_progress and not args.json and not args.by_hand:
        from tqdm import tqdm

        bar = tqdm(total=plan.poses, desc="static poses", unit=" pose", file=sys.stderr, leave=False)

        def progress(done, total):
            bar.update(done - bar.n)
    try:
        with stop_on_signals() as stop:     # Ctrl-C / SIGTERM: the run stops the head and ends its own way
            run = calibrate_rig(cfg, plan, by_hand=args.by_hand, bootstrap_samples=args.bootstrap, max_s=args.max_s,
                                stop=stop, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    res = run.result
    extrinsic = extrinsic_record(res, "live", plan.dwell_s)
    extrinsic.update({
        "mode": "by hand" if run.by_hand else "head stepped by Pelco-D",
        "poses": plan.poses,
        "translation_singular_values": np.round(run.translation_singular_values, 5).tolist(),
        "weakest_translation_direction": np.round(run.weakest_translation_direction, 4).tolist(),
        "gravity_m_s2": round(res.imu.gravity_m_s2, 4),
        "pair_rotations_deg": [round(v, 3) for v in run.turned_deg],
    })
    warnings = []
    short = run.short_turns()
    if short:
        warnings.append(f"{len(short)} of {len(run.turned_deg)} moves turned less than half the plan (pairs "
                        f"{', '.join(str(i + 1) for i in short)}: {', '.join(f'{run.turned_deg[i]:.1f}' for i in short)} deg "
                        f"for {', '.join(f'{run.planned_deg[i]:.1f}' for i in short)} planned): the head's speed table "
                        f"is off ([head] speed_table = {cfg.head.speed_table!r}); calibrate it first "
                        "(foveatrack calibrate --config) for a better extrinsic")
    extrinsic["warnings"] = list(res.warnings) + warnings
    _print_warnings(extrinsic["warnings"])
    with open(out, "w") as fh:
        json.dump(extrinsic, fh, indent=2)
        fh.write("\n")
    summary = {"extrinsic": extrinsic, "out": out, "wall_s": round(run.wall_s, 1), "imu_samples": run.imu_samples,
               "points_per_pose": run.points_per_pose,
               "static_spread_deg_s": [round(v, 4) for v in run.static_spread_deg_s],
               "registration_rms_m": [round(r.rms_m, 5) for r in res.registrations],
               "consistency_eq8": np.round(res.consistency(), 6).tolist(), "counters": run.counters,
               # per pose pair: the lidar's registered motion A and the IMU's integrated B (4 x 4)
               "motions": [{"A": np.round(a, 9).tolist(), "B": np.round(b, 9).tolist()} for a, b in zip(res.A, res.B)]}
    if args.json:
        print(json.dumps(summary, indent=2, default=float))
        return 0
    e = extrinsic
    print(f"lidar-IMU extrinsic from {plan.poses} static poses ({e['mode']}), {plan.dwell_s:g} s each, "
          f"{run.wall_s:.0f} s wall; {run.imu_samples} IMU samples; gravity {e['gravity_m_s2']:.3f} m/s^2")
    print(f"  rotation rpy {e['rotation_rpy_deg']} deg (1-sigma per axis {e['sigma_rotation_deg']}, of the angle "
          f"{e['sigma_rotation_total_deg']})")
    print(f"  translation {e['translation_m']} m (1-sigma per axis {e['sigma_translation_m']}, of the distance "
          f"{e['sigma_translation_total_m']})")
    print(f"  {res.handeye.pairs_used} pairs, rotation axes spread {res.handeye.axis_spread_deg:.1f} deg; translation "
          f"pinned by singular values {e['translation_singular_values']} (weakest along "
          f"{e['weakest_translation_direction']})")
    for f in e["pairs_translation_free"]:
        print(f"  pair {f['pair']}: the planes in view fixed no translation along "
              f"{' and '.join(str(d) for d in f['directions'])} (lidar frame); its translation there is not used")
    print(f"  consistency eq. (8) without truth: mean {e['consistency_eq8_mean']:.2e}")
    print(f"  written to {out}")
    return 0
