"""Paper Fig. 11b over many seeds: the lidar-IMU calibration error against accumulation time, as a mean
with its spread (docs/imu-calibration.md).

Each seed is the scene's with another ``[scene] seed``: other poses, other IMU noise and biases, other
range noise.  Per seed and accumulation time the simulated rig of :mod:`sim.imu_rig` is calibrated
(:func:`foveatrack.imu_calib.procedure.calibrate`) and scored against the truth; this prints per
accumulation time the mean, standard deviation and largest value over the seeds, and the floors: the
extrinsic solved from the true lidar motions and the IMU's (what the IMU allows) and from the registered
lidar motions and the true IMU motions (what the lidar allows).  ``--plot`` draws the curves with their
min-max band (the plot of ``foveatrack calibrate-imu --plot``).

    python scripts/imu_calib_seeds.py --seeds 8 --poses 13 --accumulate 0.1,0.2,0.5,1,2,5 \\
        --plot docs/img/imu-calibration-seeds.png --json docs/img/imu-calibration-seeds.json
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from foveatrack.cli.imu_calib_plots import plot_error_vs_accumulation  # noqa: E402
from sim import imu_rig  # noqa: E402
from sim.imu import PoseSchedule  # noqa: E402
from sim.scene import load_scene  # noqa: E402

METRICS = ("rotation_error_deg", "translation_error_m", "eq8_mean", "registration_rotation_deg",
           "registration_translation_m", "imu_floor_rotation_deg", "imu_floor_translation_m",
           "lidar_floor_rotation_deg", "lidar_floor_translation_m")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="scenes/imu-calibration-room.toml")
    ap.add_argument("--lidar", default="mid40")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--poses", type=int, default=None, help="poses per run (default: the scene's)")
    ap.add_argument("--accumulate", default="0.1,0.2,0.5,1,2,5")
    ap.add_argument("--bootstrap", type=int, default=0, help="bootstrap resamples per solve (default 0: the "
                    "joint fit's covariance alone; the errors do not depend on it)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--plot")
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    acc = sorted({float(x) for x in args.accumulate.split(",")})
    base = load_scene(args.scene)
    schedule = base.imu_poses or PoseSchedule()
    if args.poses:
        schedule = replace(schedule, count=args.poses)
    per_seed = []
    t0 = time.perf_counter()

    def bar(total, desc):
        if args.no_progress:
            return None
        from tqdm import tqdm

        return tqdm(total=total, desc=f"seed {seed}: {desc}", file=sys.stderr, leave=False)

    for k in range(args.seeds):
        seed = args.first_seed + k
        scene = replace(base, seed=seed, imu_poses=schedule)
        _, out = imu_rig.run(scene, [args.lidar], acc, bootstrap_samples=args.bootstrap, progress_factory=bar)
        rows = [imu_rig.score_row(s) for _, s in out[args.lidar]]
        per_seed.append({"seed": seed, "rows": rows,
                         "removed": {r["accumulate_s"]: r["removed_pairs"] for r in rows if r["removed_pairs"]}})
        last = rows[-1]
        print(f"seed {seed} ({k + 1}/{args.seeds}, {time.perf_counter() - t0:.0f} s): at {last['accumulate_s']:g} s "
              f"{last['rotation_error_deg']:.4f} deg, {last['translation_error_m'] * 100:.3f} cm", file=sys.stderr,
              flush=True)
    wall_s = time.perf_counter() - t0
    summary = []
    for j, a in enumerate(acc):
        row = {"lidar": args.lidar, "accumulate_s": a}
        for m in METRICS:
            v = np.array([s["rows"][j][m] for s in per_seed])
            row[m] = float(v.mean())
            row[f"{m}_std"] = float(v.std(ddof=1)) if len(v) > 1 else 0.0
            row[f"{m}_lo"], row[f"{m}_hi"] = float(v.min()), float(v.max())
        summary.append(row)
    cmd = "python scripts/imu_calib_seeds.py " + " ".join(sys.argv[1:] if argv is None else argv)
    print(f"{args.scene}, {args.lidar}, {schedule.count} poses, seeds {args.first_seed}-{args.first_seed + args.seeds - 1}; "
          f"{wall_s:.0f} s wall; load {os.getloadavg()[0]:.1f}")
    print("| T [s] | X rotation error [deg] mean +- sd (max) | X translation error [cm] mean +- sd (max) "
          "| registration per pair [deg / cm] | eq. (8) mean | IMU-only floor [deg / cm] | lidar-only floor [deg / cm] |")
    print("|---:|---|---|---|---|---|---|")
    for r in summary:
        print(f"| {r['accumulate_s']:g} | {r['rotation_error_deg']:.3f} +- {r['rotation_error_deg_std']:.3f} "
              f"({r['rotation_error_deg_hi']:.3f}) | {r['translation_error_m'] * 100:.2f} +- "
              f"{r['translation_error_m_std'] * 100:.2f} ({r['translation_error_m_hi'] * 100:.2f}) | "
              f"{r['registration_rotation_deg']:.3f} / {r['registration_translation_m'] * 100:.2f} | "
              f"{r['eq8_mean']:.2e} | {r['imu_floor_rotation_deg']:.3f} / {r['imu_floor_translation_m'] * 100:.2f} | "
              f"{r['lidar_floor_rotation_deg']:.3f} / {r['lidar_floor_translation_m'] * 100:.2f} |")
    removed = {s["seed"]: s["removed"] for s in per_seed if s["removed"]}
    print(f"pairs removed by the pair check (seed: {{accumulation: pairs}}): {removed or 'none'}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"command": cmd, "wall_s": round(wall_s, 1), "poses": schedule.count, "summary": summary,
                       "per_seed": per_seed}, fh, indent=1)
            fh.write("\n")
    if args.plot:
        plot_error_vs_accumulation(summary, None, args.plot, f"{base.name}, {schedule.count} poses, "
                                   f"{args.seeds} seeds: mean, band min-max", cmd, spread_note="min-max over seeds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
