"""Speed-table calibration (paper App. D.4) against the simulated PTS-303H in the calibration room.

Must show (issue 5): on a unit seed never used elsewhere, the calibration recovers the true speed
table within 2 % (or its stated uncertainty) for the bytes it measures, and reports the entries it
could not measure.
"""

import json
import math

import pytest

from calib_fixture import FRESH_UNIT, PLAN, fresh_unit_calibration
from foveatrack.speed_table import TURBO, SpeedTable

pytestmark = pytest.mark.slow     # ~30 s wall: 170 s of virtual time at 20 Hz frames


def test_fresh_unit_recovers_the_true_table_within_2_percent_or_its_uncertainty(tmp_path):
    run = fresh_unit_calibration()
    print(f"\nunit {FRESH_UNIT}: {run.frames} frames, {run.virtual_s:.0f} s virtual, {run.wall_s:.1f} s wall")
    for r in run.comparison:
        e = "-" if r["error_pct"] is None else f"{r['error_pct']:+6.2f} %"
        print(f"  {r['axis']:4s} {r['byte']:3d}  measured {r['measured_deg_s']:8.4f} +- {r['sigma_deg_s']:.4f}"
              f"  true {r['true_deg_s']:8.4f}  {e}  {'ok' if r['ok'] else 'OUT'}")
    table = run.table
    for axis, planned in (("pan", PLAN["pan_bytes"]), ("tilt", PLAN["tilt_bytes"])):
        ax, tr = table.axis(axis), run.truth.axis(axis)
        unmeasured = run.report.unmeasured[axis]
        for b in planned:
            v, s, tv = ax.speed_deg_s(b), ax.sigma_deg_s(b), tr.speed_deg_s(b)
            if not ax.is_measured(b):
                # a planned byte it could not measure must be reported with a reason
                assert b in unmeasured and "not in the plan" not in unmeasured[b], (axis, b)
                continue
            assert math.isfinite(s) and s > 0
            if tv > 0:
                assert abs(v - tv) <= max(0.02 * tv, 3 * s), (axis, b, v, tv, s)
            else:
                assert abs(v) <= 3 * s + 0.01
            # where the head moves usefully (>= 0.3 deg/s), the 2 % must hold outright, not via sigma
            if tv >= 0.3:
                assert abs(v - tv) <= 0.02 * tv, (axis, b, v, tv)
        # at least all planned bytes above the dead zone with >= 0.3 deg/s were measured
        assert all(ax.is_measured(b) for b in planned if tr.speed_deg_s(b) >= 0.3)
        # bytes outside the plan: reported as unmeasured (interpolated), never claimed measured
        for b in range(64):
            if b not in planned:
                assert not ax.is_measured(b) and "not in the plan" in unmeasured[b]
        assert (axis == "pan") == (TURBO in ax.unmeasured_bytes or ax.is_measured(TURBO))
    # the head was stopped and brought back near where it started
    assert abs(run.head_end_deg[0] - run.head_start_deg[0]) < 1.0
    assert abs(run.head_end_deg[1] - run.head_start_deg[1]) < 1.0
    # the table is a file a user keeps: unit, date, per-entry uncertainty, and it loads back
    path = tmp_path / "table.json"
    table.save(path)
    d = json.loads(path.read_text())
    assert d["unit"] == "deg/s" and d["date"] == "2025-01-01T00:00:00Z" and str(FRESH_UNIT) in d["head"]
    assert all("sigma" in e for e in d["axes"]["pan"]["entries"])
    back = SpeedTable.load(path)
    assert back.pan.speed_deg_s(40) == pytest.approx(table.pan.speed_deg_s(40))
    print(f"dead time {table.dead_time_s * 1e3:.1f} ms, accel pan {table.pan.accel_deg_s2:.1f} tilt "
          f"{table.tilt.accel_deg_s2:.1f} deg/s^2 (truth 40 ms, 40 / 10 deg/s^2)")
