"""Each head and timing effect (sim.effects, "Head and timing") on fig12: its cost per frame and its
influence on tracking, against fig12 as shipped, per seed and as a 95 % interval over the seeds.

    python scripts/measure_head_effects.py [--seeds 3] [--duration 15] [--effects a,b,...]

Per configuration: CPU ms per frame and its ratio to the plain run of the same seed (the reference is
measured in the same invocation, so the ratio carries across machines better than the ms), the rms
of the true off-axis error over all frames and after acquisition [deg], and the rms of the dead
reckoning's error against the head's true pose [deg] (what the head effects act on).  Prints the
machine load before and after: timings on a shared machine are noisy.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

HEAD_EFFECTS = ("head_thermal_drift", "head_dead_time_jitter", "link_latency_jitter", "lidar_clock_drift",
                "head_backlash", "head_wind")


def scene_with(extra: tuple[str, ...], seed: int, duration_s: float):
    from sim.scene import scene_from_mapping

    data = tomllib.loads((ROOT / "scenes" / "fig12-tracking.toml").read_text())
    data["scene"]["effects"] = list(data["scene"]["effects"]) + list(extra)
    data["scene"]["seed"] = seed
    data["scene"]["duration_s"] = duration_s
    return scene_from_mapping(data, "fig12 + " + ("+".join(extra) or "nothing"))


def recon_rms_deg(log) -> float:
    d_pan = (log["est_pan_deg"] - log["head_pan_deg"] + 180.0) % 360.0 - 180.0
    d_tilt = log["est_tilt_deg"] - log["head_tilt_deg"]
    d = np.hypot(d_pan, d_tilt)
    d = d[np.isfinite(d)]
    return float(np.sqrt(np.mean(d * d))) if d.size else math.nan


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=15.0)
    ap.add_argument("--effects", default=",".join(HEAD_EFFECTS))
    args = ap.parse_args(argv)
    from sim.study.common import run_loop
    from sim.study.stats import fmt, interval, paired_ratio

    configs = [()] + [(e,) for e in args.effects.split(",") if e] + [HEAD_EFFECTS]
    print(f"load before: {os.getloadavg()[0]:.1f}; fig12-tracking, {args.duration:g} s, seeds 1-{args.seeds}",
          flush=True)
    run_loop(scene_with((), 99, 0.3))      # numba kernels loaded before anything is timed
    rows = {}
    for cfg in configs:
        per = {"ms": {}, "err": {}, "acq": {}, "recon": {}}
        for seed in range(1, args.seeds + 1):
            m = run_loop(scene_with(cfg, seed, args.duration))
            per["ms"][seed] = 1e3 * m["cpu_s"] / m["frames"]
            per["err"][seed] = m["error_rms_all_deg"]
            per["acq"][seed] = m["error_rms_acq_deg"]
            per["recon"][seed] = recon_rms_deg(m["_log"])
        rows[cfg] = per
        print(f"  {'+'.join(cfg) or 'fig12 as shipped'}: done", file=sys.stderr, flush=True)
    base = rows[()]
    print(f"{'effect':<24} {'ms/frame':>16} {'x plain':>16} {'err rms all [deg]':>20} {'err rms acq [deg]':>20}"
          f" {'dead reckoning [deg]':>22}")
    for cfg, per in rows.items():
        name = "+".join(cfg) if len(cfg) < 2 else "all six"
        print(f"{name or 'fig12 as shipped':<24} {fmt(interval(per['ms'].values())):>16} "
              f"{fmt(paired_ratio(per['ms'], base['ms'])):>16} {fmt(interval(per['err'].values())):>20} "
              f"{fmt(interval(per['acq'].values())):>20} {fmt(interval(per['recon'].values())):>22}")
    print(f"load after: {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
