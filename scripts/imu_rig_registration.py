"""How far the lidar-IMU calibration's registration strays on the live rig's plan, at random scan phases.

The rig of ``tests/daemon/test_calibrate_imu_devices.py`` (``scenes/imu-calibration-head.toml``: a
Horizon on the head in the room, the plan's 9 poses from pan 31, tilt -12 deg, 10 deg steps), each
pose's cloud cast offline for ``--dwell-s`` from a random scan phase (the live test's clouds start
wherever the scan is when the window opens), each pair registered from the true motion mapped
through the identity mount (as the live command seeds it with no nominal mount).  Prints the pairs
whose translation strayed more than 2 cm, the error percentiles, and the pairs with a free
translation direction (``Registration.free_directions``).

    python scripts/imu_rig_registration.py --runs 30 --seed 2

Run against another checkout by putting it first on PYTHONPATH (docs/imu-calibration.md compares two).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from foveatrack.imu_calib import registration
from foveatrack.imu_calib.live import RigPlan
from foveatrack.imu_calib.se3 import inv_T, make_T, so3_log
from sim.head_imu import head_rotations
from sim.lidar_server import SceneSource
from sim.scene import load_scene

SCENE = "scenes/imu-calibration-head.toml"
STRAYED_M = 0.02


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=10, help="plans cast and registered (8 pairs each)")
    p.add_argument("--dwell-s", type=float, default=2.0, help="cloud per pose [s] (the live test's: 2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the scan phases")
    args = p.parse_args(argv)
    scene = load_scene(SCENE)
    X = scene.imu.T_lidar_imu
    off = np.array(RigPlan(poses=9).offsets_deg()) + [scene.gimbal.pan0_deg, scene.gimbal.tilt0_deg]
    Rw = head_rotations(off[:, 0], off[:, 1])
    A_true = [make_T(a.T @ b, np.zeros(3)) for a, b in zip(Rw, Rw[1:])]
    rng = np.random.default_rng(args.seed)
    errs, free, strayed = [], 0, 0
    t0 = time.monotonic()
    for run in range(args.runs):
        clouds = []
        for pan, tilt in off:
            src = SceneSource(scene, pose=lambda t, p=pan, q=tilt: (np.full(np.shape(t), p), np.full(np.shape(t), q)))
            start_s = rng.uniform(0, 600)
            clouds.append(src(int(start_s * 1e9), int((start_s + args.dwell_s) * 1e9))[0])
        for i, A in enumerate(A_true):
            r = registration.register(clouds[i + 1], clouds[i], inv_T(X) @ A @ X)
            E = inv_T(A) @ r.T
            e_deg, e_m = float(np.degrees(np.linalg.norm(so3_log(E[:3, :3])))), float(np.linalg.norm(E[:3, 3]))
            errs.append((e_deg, e_m))
            n_free = len(getattr(r, "free_directions", ()))
            free += n_free > 0
            if e_m > STRAYED_M:
                strayed += 1
                print(f"run {run} pair {i + 1}: {e_deg:.3f} deg, {e_m * 100:.1f} cm off "
                      f"({np.round(E[:3, 3] * 100, 1)} cm)", flush=True)
        print(f"run {run + 1}/{args.runs} done, {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
    e = np.array(errs)
    print(f"{args.runs} runs x {len(A_true)} pairs, {args.dwell_s:g} s clouds, seed {args.seed}: "
          f"{strayed} strayed more than {STRAYED_M * 100:g} cm; error p50 / p99 "
          f"{np.percentile(e[:, 0], 50):.3f} / {np.percentile(e[:, 0], 99):.3f} deg, "
          f"{np.percentile(e[:, 1], 50) * 100:.2f} / {np.percentile(e[:, 1], 99) * 100:.2f} cm; "
          f"{free} pairs with a free translation direction; {time.monotonic() - t0:.0f} s wall")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
