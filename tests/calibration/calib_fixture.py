"""One calibration of a fresh simulated unit, shared by the calibration and reconstruction tests."""

from functools import lru_cache
from pathlib import Path

from foveatrack.speed_table import TURBO

ROOT = Path(__file__).resolve().parents[2]
# A unit seed no scene, test or doc uses anywhere else (grep unit_seed): the calibration has never seen it.
FRESH_UNIT = 4242
# Every 4th pan byte + 63 + turbo, 11 tilt bytes, 4 s legs: ~200 s of virtual time (~20-60 s wall).
# Bytes in between are interpolated (reported as unmeasured, "not in the plan").
PLAN = dict(pan_bytes=tuple(range(4, 64, 4)) + (63, TURBO), tilt_bytes=(4, 8, 12, 16, 20, 24, 32, 40, 48, 56, 63),
            dwell_s=4.0)


@lru_cache(maxsize=1)
def fresh_unit_calibration():
    from sim.calibration_run import default_plan, run_calibration
    from sim.scene import load_scene

    scene = load_scene(ROOT / "scenes" / "calibration-room.toml")
    return run_calibration(scene, default_plan(scene, **PLAN), unit_seed=FRESH_UNIT, date="2025-01-01T00:00:00Z")
