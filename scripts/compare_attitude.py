"""Head attitude from the commands (dead reckoning) or from the gyro: both on every scene with a target.

Each scene runs twice, ``[tracker] attitude = "commands"`` and ``"gyro"``, with an IMU on the head
(``[imu]`` added with the BMI088 defaults of sim/imu.py where the scene has none; see
sim/attitude_study.py), once with the scene's own speed table and once per hard table: the unit's
truth with every speed 3 % high (``speeds x1.03``), and with each axis's acceleration 20 % low
(``accel x0.8``: the calibrated-timing error of docs/tracker.md).  Printed per run: the
reconstruction error of ``foveatrack simulate --json`` (``reconstruction_error_m`` rms / p95 / max)
and the head-angle error (the rotation between the true and the estimated lidar attitude at
mid-frame, every frame) rms / max, for both attitude sources side by side::

    python scripts/compare_attitude.py                     # every scene, three tables (about 1-2 min)
    python scripts/compare_attitude.py --scenes fig12-tracking,noisy-link --tables shipped,speed --json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sim.attitude_study import run_variant, scene_variant  # noqa: E402

SCENES = ("fig12-tracking", "fig12-predictive", "fig14a-frozen-pass", "fast-crossing-close",
          "far-target-range-limit", "overhead-tilt-stop", "noisy-link")
TABLES = {"shipped": {}, "speed": {"table_scale": 1.03}, "accel": {"accel_scale": 0.8}}
TABLE_LABEL = {"shipped": "scene's", "speed": "speeds x1.03", "accel": "accel x0.8"}


def _fmt(m: dict, keys=("rms", "p95", "max"), digits=3) -> str:
    if m.get("rms") is None:
        return "-"
    return " / ".join(f"{m[k]:.{digits}f}" for k in keys)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES), help="scene names under scenes/ (comma-separated)")
    ap.add_argument("--tables", default=",".join(TABLES), help=f"which tables: {', '.join(TABLES)}")
    ap.add_argument("--duration", type=float, default=None, help="virtual seconds (default: each scene's own)")
    ap.add_argument("--rest-before-s", type=float, default=None,
                    help="seconds the IMU streams with the head at rest before the first frame (default: sim/imu.py's 5)")
    ap.add_argument("--json", action="store_true", help="print every number as JSON instead of the table")
    a = ap.parse_args(argv)
    scenes = [s for s in a.scenes.split(",") if s]
    tables = [t for t in a.tables.split(",") if t]
    for s in scenes:
        if not (ROOT / "scenes" / f"{s}.toml").is_file():
            ap.error(f"no scene scenes/{s}.toml")
    for t in tables:
        if t not in TABLES:
            ap.error(f"unknown table {t!r}; allowed: {', '.join(TABLES)}")
    rows = []
    jobs = [(s, t) for s in scenes for t in tables]
    for s, t in tqdm(jobs, desc="scenes x tables", file=sys.stderr):
        imu = None if a.rest_before_s is None else {"rest_before_s": a.rest_before_s}
        pair = {att: run_variant(scene_variant(ROOT / "scenes" / f"{s}.toml", att, duration_s=a.duration, imu=imu,
                                               **TABLES[t]))
                for att in ("commands", "gyro")}
        rows.append({"scene": s, "table": t, **pair})
    if a.json:
        print(json.dumps(rows, indent=1))
        return 0
    print("| scene | table | reconstruction error [m] rms / p95 / max: commands | gyro "
          "| head-angle error [deg] rms / max: commands | gyro |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        c, g = r["commands"], r["gyro"]
        print(f"| {r['scene']} | {TABLE_LABEL[r['table']]} | {_fmt(c['reconstruction_error_m'])} "
              f"| {_fmt(g['reconstruction_error_m'])} | {_fmt(c['head_angle_error_deg'], ('rms', 'max'))} "
              f"| {_fmt(g['head_angle_error_deg'], ('rms', 'max'))} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
