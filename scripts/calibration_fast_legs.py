"""Speed-table calibration (App. D.4) of fast legs, per simulated unit: the error of pan 40, pan 63,
pan turbo and tilt 63 with a reduced plan (4 s legs), in percent and in units of the entry's sigma,
and the calibration's virtual time.  Run from the repository root:

    python scripts/calibration_fast_legs.py 4242 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15

(docs/tracker.md, "Fast legs": before the fix the turbo read up to 8.7 % low.)
"""
import sys

from foveatrack.speed_table import TURBO
from sim.calibration_run import default_plan, run_calibration
from sim.scene import load_scene

scene = load_scene("scenes/calibration-room.toml")
plan = default_plan(scene, pan_bytes=(40, 63, TURBO), tilt_bytes=(63,), dwell_s=4.0)
for seed in [int(a) for a in sys.argv[1:]]:
    run = run_calibration(scene, plan, unit_seed=seed, date="2025-01-01T00:00:00Z")
    rows = {(r["axis"], r["byte"]): r for r in run.comparison}
    out = []
    for ax, b in (("pan", 40), ("pan", 63), ("pan", TURBO), ("tilt", 63)):
        r = rows.get((ax, b))
        out.append(f"{ax}{b}: " + ("unmeasured" if r is None else f"{r['error_pct']:+.2f}% ({r['error_sigmas']:+.1f}s)"))
    print(seed, "  ".join(out), f" virt {run.virtual_s:.1f}s", flush=True)
