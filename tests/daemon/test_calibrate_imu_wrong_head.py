"""``foveatrack calibrate-imu --config`` against the wrong head: the gyro's witness stops the run (issue 25).

The repro: the config of a PTS-303 (``examples/daemon-virtual.toml``'s unit-3 speed table, tilt 2 deg/s
at byte 63) on the port of a ``heavy-worm`` head (tilt 15 deg/s): each 10 deg tilt step is commanded as
5 s at byte 63 and the head turned 77 deg, past ``tilt_limits_deg`` 60 (it reached 64.7), and the
extrinsic was written with no warning.  Now the lidar's gyro witnesses every move
(:class:`foveatrack.turn_witness.TurnWitness`): the run stops with an error naming the axis, the
commanded and the measured turn, the head is stopped well inside its limits, and nothing is written.

The virtual devices as separate processes, as in tests/daemon/test_calibrate_imu_devices.py.
"""

import os
import re
import subprocess
import sys

import pytest

from daemon_procs import ROOT, device_config, env, free_udp_port, start_head_and_lidar, terminate, wait_for
from sim.virtual_head import read_truth

pytestmark = [pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty"), pytest.mark.slow]

SCENE = ROOT / "scenes" / "imu-calibration-head.toml"
TILT_LIMITS = (-30.0, 60.0)


def test_a_head_turning_far_more_than_its_table_says_stops_the_calibration(tmp_path):
    link, truth = tmp_path / "head", tmp_path / "truth.jsonl"
    bport = free_udp_port()
    procs = []
    try:
        start_head_and_lidar(tmp_path, ["--family", "heavy-worm", "--pan0-deg", "31", "--tilt0-deg", "-12"], SCENE,
                             bport, procs)
        # a PTS-303's [head] (examples/daemon-virtual.toml) at this head's start pose
        head = {"speed_table": str(ROOT / "examples" / "pts303h-unit3-speed-table.json"), "pan_speed_max_deg_s": 15.0,
                "tilt_speed_max_deg_s": 2.0, "tilt_limits_deg": list(TILT_LIMITS), "tilt_margin_deg": 2.0,
                "pan0_deg": 31.0, "tilt0_deg": -12.0}
        cfg = device_config(tmp_path / "d.toml", link, bport, 5.0, head=head, lidar={"point_rate_hz": 100000})
        out = tmp_path / "x.json"
        p = subprocess.run([sys.executable, "-m", "foveatrack", "calibrate-imu", "--config", str(cfg), "--out", str(out),
                            "--poses", "9", "--dwell-s", "2", "--settle-s", "0.4", "--max-s", "300"], cwd=ROOT,
                           env=env(), capture_output=True, text=True, timeout=400)
        # the STOP went out as the run ended; the head decelerates before its truth says rest (the
        # server was stopped at once, and its last row caught it mid-deceleration now and then)
        wait_for(lambda: _at_rest(truth), 20, "the head at rest after the STOP", procs)
    finally:
        for q in procs:
            terminate(q)
    err = p.stderr
    print(err[-1500:])
    assert p.returncode == 2 and "Traceback" not in err, err[-3000:]
    m = re.search(r"the head turned (pan|tilt) ([-+][0-9.]+) deg where ([-+][0-9.]+) deg was commanded", err)
    assert m, err[-3000:]
    axis, measured, commanded = m.group(1), float(m.group(2)), float(m.group(3))
    assert abs(measured) > abs(commanded) + 3.0, (axis, measured, commanded)
    assert "the head was stopped and no extrinsic was written" in err and not out.exists()
    # stopped before the head passed its tilt limit (less the gate's margin), and at rest
    rows = read_truth(truth)
    max_tilt = max(r["tilt_deg"] for r in rows)
    print(f"stopped on {axis}: measured {measured} for {commanded} commanded; the head's highest tilt {max_tilt:.1f} deg")
    assert max_tilt < TILT_LIMITS[1] - 2.0, max_tilt
    assert rows[-1]["tilt_speed_deg_s"] == 0.0 and rows[-1]["pan_speed_deg_s"] == 0.0


def _at_rest(truth) -> bool:
    try:
        rows = read_truth(truth)
    except (OSError, ValueError):      # a row being written
        return False
    return bool(rows) and rows[-1]["tilt_speed_deg_s"] == 0.0 and rows[-1]["pan_speed_deg_s"] == 0.0
