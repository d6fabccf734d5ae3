"""Speed-table calibration (paper App. D.4) over several simulated units with the fresh-unit test's
plan (every 4th pan byte, 63 and turbo, 11 tilt bytes, 4 s legs; tests/calibration/calib_fixture.py):
per entry of at least 0.3 deg/s (where the test holds 2 % outright), the rms and the largest error over
the units, and how many entries were over 2 %.  One unit takes ~200 s of virtual time (~11 s wall).

    python scripts/calibration_units.py 11 12 13 14 15 16

A single unit can hide a bias that only some units show (the turbo's ramp, docs/tracker.md "Fast legs").
"""
from __future__ import annotations

import math
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "calibration"))
from calib_fixture import PLAN  # noqa: E402

from sim.calibration_run import default_plan, run_calibration  # noqa: E402
from sim.scene import load_scene  # noqa: E402

MIN_SPEED_DEG_S = 0.3      # the fresh-unit test's "moves usefully": 2 % outright above it


def main(seeds: list[int]) -> None:
    scene = load_scene(ROOT / "scenes" / "calibration-room.toml")
    errors: dict[tuple[str, int], list[float]] = defaultdict(list)
    for seed in seeds:
        run = run_calibration(scene, default_plan(scene, **PLAN), unit_seed=seed, date="2025-01-01T00:00:00Z")
        for r in run.comparison:
            if r["error_pct"] is not None and r["true_deg_s"] >= MIN_SPEED_DEG_S:
                errors[(r["axis"], r["byte"])].append(r["error_pct"])
        print(f"unit {seed}: {run.virtual_s:.0f} s virtual, {run.wall_s:.1f} s wall", file=sys.stderr, flush=True)
    print(f"units {seeds}; entries of at least {MIN_SPEED_DEG_S} deg/s, error [%]:")
    every = []
    for (axis, byte), e in sorted(errors.items()):
        every += e
        print(f"  {axis:4s} {byte:3d}  rms {math.sqrt(sum(v * v for v in e) / len(e)):5.2f}  "
              f"max {max(map(abs, e)):5.2f}  ({len(e)} units)")
    print(f"all: rms {math.sqrt(sum(v * v for v in every) / len(every)):.2f} %, max {max(map(abs, every)):.2f} %, "
          f"{sum(abs(v) > 2.0 for v in every)} of {len(every)} over 2 %")


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [11, 12, 13, 14, 15, 16])
