"""``foveatrack calibrate --config``: the speed-table calibration on live devices (paper App. D.4).

End to end through the virtual devices, as a bench would run it: ``gimbal serve`` (a PTS-303H unit
on a pseudo-terminal, Pelco-D in) and ``lidar serve`` (the calibration room over Livox UDP, following
that head's pose), and the command under test reading the daemon's config.
"""

import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest

from child_procs import dies_with_this_process
from daemon_procs import (ROOT, device_config, env, first_line, free_udp_port, start, start_head_and_lidar, terminate,
                          wait_for)
from foveatrack.calibration import CalibrationPlan
from foveatrack.calibration.live import plan_within_limits
from foveatrack.cli import main
from foveatrack.daemon import load_config
from foveatrack.speed_table import TURBO, SpeedTable
from gimbal.pts303h import PTS303H
from sim.virtual_head import read_truth

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")

UNIT = 101
# The virtual lidar can pause for over 0.5 s (the shipped watchdog) on a busy 2-core machine: "fell
# silent for 0.5 s after 149 frames" at load 2.85, and 2 s once at load 3 beside three other test runs.
# These tests are about calibrating, not the watchdog.
WATCHDOG_S = 5.0
CORNER = ("5.9", "0.8", "0.84")   # the room corner in the lidar frame at the start (within 1 m suffices)


def _config(tmp_path, link, bport, **head):
    return device_config(tmp_path / "d.toml", link, bport, WATCHDOG_S, head={"pan0_deg": 23.0, "tilt0_deg": 6.5, **head})


def _calibrate(cfg, out, *extra) -> subprocess.Popen:
    return subprocess.Popen(dies_with_this_process([sys.executable, "-m", "foveatrack", "calibrate", "--config", str(cfg),
                                                    "--corner", *CORNER, "--out", str(out), "--json", "--max-s", "90",
                                                    *extra]), cwd=ROOT, env=env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _calibration_under_way(cfg, out, truth, procs) -> subprocess.Popen:
    """A one-byte-per-axis calibration, once the head has started its first leg."""
    p = _calibrate(cfg, out, "--pan-bytes", "40", "--tilt-bytes", "63", "--dwell-s", "3")
    n0 = len(read_truth(truth))
    wait_for(lambda: any(r["pan_speed_deg_s"] != 0.0 for r in read_truth(truth)[n0:]), 60, "the head to move",
             procs + [p])
    return p


def test_calibrates_a_head_through_its_serial_port_and_the_lidar_stream(tmp_path):
    link, truth = tmp_path / "head", tmp_path / "truth.jsonl"
    bport = free_udp_port()
    cfg = _config(tmp_path, link, bport, allow_turbo=False, max_pan_byte=50)
    procs = []
    try:
        start_head_and_lidar(tmp_path, ["--unit-seed", str(UNIT), "--pan0-deg", "23", "--tilt0-deg", "6.5"],
                             ROOT / "scenes" / "calibration-room.toml", bport, procs, lidar_timeout_s=60)
        out = tmp_path / "table.json"
        # Pan byte 60 and turbo are beyond this config's limits: left out, and said so.
        p = _calibrate(cfg, out, "--pan-bytes", "40,60,turbo", "--tilt-bytes", "63", "--dwell-s", "3")
        stdout, stderr = p.communicate(timeout=150)
        assert p.returncode == 0, stderr
        summary = json.loads(stdout)
        assert summary["left_out_by_limits"] == {"pan": [60, TURBO]}
        unit = PTS303H(unit_seed=UNIT)
        rows = {(r["axis"], r["byte"]): r for r in summary["entries"]}
        assert set(rows) == {("pan", 40), ("tilt", 63)}
        # The bar (2 % or 3 sigma) is tested where the head's pose is exact: in the simulator
        # (tests/calibration) and on the one-process rig below.  Here the lidar learns the head's pose
        # from a 20 ms truth file in another process, and on a loaded 2-core machine its pose lags or
        # is held (seen: tilt 3-4 % high in two CI runs, 0.2-2 % on an idle machine): this checks that
        # the processes together measure the right speeds.
        for (axis, b), r in rows.items():
            v_true = unit.true_speed_deg_s(axis, b)
            assert abs(r["measured_deg_s"] - v_true) <= max(0.10 * v_true, 3 * r["sigma_deg_s"]), (axis, b, r, v_true)
        table = SpeedTable.load(out)
        assert table.pan.is_measured(40) and not table.pan.is_measured(60)
        # The head's own dead time is 40 ms; the virtual lidar follows the head's pose 20-30 ms late
        # (its truth file's period + a batch), which the calibration cannot tell from dead time, and
        # later on a loaded machine (0.177 s measured beside two busy loops, load 3).  The dead time's
        # own bar is held on the one-process rig below, whose poses are exact.
        assert 0.0 <= summary["dead_time_s"] <= 0.3
        assert summary["command_delay_ms"]["median"] < 100
        # The STOP was the last command; the head takes its dead time and up to 0.2 s of deceleration
        # (tilt 2 deg/s at 10 deg/s^2) to come to rest, and its truth file is 20 ms behind.
        def stopped():
            rest = read_truth(truth)[-1]
            return rest["pan_speed_deg_s"] == 0.0 and rest["tilt_speed_deg_s"] == 0.0
        wait_for(stopped, 3.0, "the head to come to rest after the calibration's STOP", procs)

        # Interrupted: the head stops, no table is written, the error says so.
        out2 = tmp_path / "table2.json"
        p = _calibration_under_way(cfg, out2, truth, procs)
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=30)
        assert p.returncode == 2 and "interrupted" in stderr and "no table was written" in stderr, stderr
        assert not out2.exists()
        time.sleep(0.3)   # the STOP's effect in the next truth lines (20 ms period, 40 ms dead time, ramp)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            rest = read_truth(truth)[-1]
            if rest["pan_speed_deg_s"] == 0.0 and rest["tilt_speed_deg_s"] == 0.0:
                break
            time.sleep(0.1)
        assert rest["pan_speed_deg_s"] == 0.0 and rest["tilt_speed_deg_s"] == 0.0, "Ctrl-C stops the head"

        # The head's link dies mid-run: the next change of command cannot be written, so the run
        # ends with an error naming the port (a leg timed against a head that never got its
        # command would give a wrong speed), and writes no table.
        out3 = tmp_path / "table3.json"
        p = _calibration_under_way(cfg, out3, truth, procs)
        procs[0].kill()
        stdout, stderr = p.communicate(timeout=60)
        assert p.returncode == 2 and "serial link" in stderr and str(link) in stderr, stderr
        assert not out3.exists()
    finally:
        for q in procs:
            terminate(q)


def test_live_calibration_is_as_accurate_as_the_simulated_one_when_the_lidar_knows_the_pose(tmp_path):
    # The rig in one process: the head model served on a pty (as gimbal serve does) and a virtual
    # Livox that takes each point's head pose from that model at the point's own time, so the
    # only error left is the live path's (frames from UDP, commands through the pty).  The issue's
    # bar applies: 2 % or 3 sigma.  (Measured with two busy loops beside it, 10 runs: pan 40 within
    # 0.44 %, tilt 63 within 0.79 %.  It failed now and then, tilt 63 4.2 % high or an entry missing,
    # through the calibrator's wrong corners and lost frames, not the load: docs/tracker.md.)
    import threading

    import numpy as np

    from foveatrack.livox import protocol as P
    from sim.lidar_server import SceneSource, warm_up_kernels
    from sim.scene import load_scene
    from sim.virtual_head import VirtualHeadServer
    from sim.virtual_lidar import VirtualLivox

    scene = load_scene(ROOT / "scenes" / "calibration-room.toml")
    head = PTS303H(unit_seed=UNIT, pan0_deg=23.0, tilt0_deg=6.5)
    lock = threading.Lock()
    done = threading.Event()
    server = VirtualHeadServer(head, time.monotonic, link_path=str(tmp_path / "head"), model_lock=lock)
    server.open()
    offset = [0.0]    # head time - lidar stream time [s]

    def serve_head():
        while not done.is_set():
            server.step(0.002)     # takes the lock only while the model changes, never across its wait

    def pose(t_s):
        with lock:
            return head.angles_at(np.asarray(t_s) + offset[0])

    warm_up_kernels(scene)
    bport = free_udp_port()
    lidar = VirtualLivox(SceneSource(scene, pose=pose), cmd_port=0, broadcast_addr=("127.0.0.1", bport),
                         point_rate_hz=float(scene.optics.point_rate_hz), packet_type=0,
                         dev_type=P.DEVICE_TYPES["mid40"])
    head_thread = threading.Thread(target=serve_head, daemon=True)
    head_thread.start()
    offset[0] = time.monotonic() - server.clock_zero     # the stream's time 0 is now (to ~1 ms)
    lidar.start()
    try:
        out = tmp_path / "table.json"
        p = _calibrate(_config(tmp_path, tmp_path / "head", bport), out, "--pan-bytes", "40", "--tilt-bytes", "63",
                       "--dwell-s", "3")
        stdout, stderr = p.communicate(timeout=150)
        assert p.returncode == 0, stderr
        for r in json.loads(stdout)["entries"]:
            v_true = head.true_speed_deg_s(r["axis"], r["byte"])
            assert abs(r["measured_deg_s"] - v_true) <= max(0.02 * v_true, 3 * r["sigma_deg_s"]), (r, v_true)
        summary = json.loads(stdout)
        assert {(r["axis"], r["byte"]) for r in summary["entries"]} == {("pan", 40), ("tilt", 63)}, (
            summary["unmeasured"], summary.get("counters"))
        # the head's dead time (40 ms) plus how late the head model applies a command read from the pty:
        # its thread shares this process with the virtual lidar, and on a loaded machine waits for it
        # (0.132 s in a CI run beside two busy loops, and once in a helper's run on the code before the
        # calibration's prior test: both bounds are the rig's, not the head's; a dead time an order off,
        # or negative, still fails)
        assert 0.0 <= summary["dead_time_s"] <= 0.2, summary["dead_time_s"]
    finally:
        lidar.stop()
        done.set()
        head_thread.join(2)
        server.close()


def test_no_lidar_is_an_error_that_names_it_and_stops_the_head(tmp_path, capsys):
    link, truth = tmp_path / "head", tmp_path / "truth.jsonl"
    cfg = load_config(_config(tmp_path, link, free_udp_port()))
    head = start(["gimbal", "serve", "--link", str(link), "--truth", str(truth)], tmp_path / "h.out", tmp_path / "h.err")
    try:
        wait_for(lambda: first_line(tmp_path / "h.out"), 20, "the head's pty", [head])
        from foveatrack.calibration import FeatureSpec
        from foveatrack.calibration.live import calibrate_live
        from foveatrack.errors import UserError

        with pytest.raises(UserError, match=r"no data from the lidar 127\.0\.0\.1 within 1 s.*head was stopped") as e:
            calibrate_live(cfg, CalibrationPlan(pan_bytes=(40,), tilt_bytes=(63,)), FeatureSpec((5.9, 0.8, 0.84)),
                           first_data_s=1.0)
        # the counters in words, not a raw dict
        assert "(lidar counters: " in str(e.value) and "{" not in str(e.value), str(e.value)
    finally:
        terminate(head)


def test_the_plan_is_cut_to_the_configs_limits(tmp_path):
    cfg = load_config(_config(tmp_path, tmp_path / "x", 55000, max_pan_byte=30, max_tilt_byte=20, allow_turbo=False))
    plan, dropped = plan_within_limits(CalibrationPlan(pan_bytes=(10, 30, 31, TURBO), tilt_bytes=(5, 20, 63)), cfg)
    assert plan.pan_bytes == (10, 30) and plan.tilt_bytes == (5, 20)
    assert dropped == {"pan": [31, TURBO], "tilt": [63]}
    from foveatrack.errors import UserError
    with pytest.raises(UserError, match=r"d\.toml \[head\].*leave no tilt byte"):
        plan_within_limits(CalibrationPlan(pan_bytes=(10,), tilt_bytes=(40,)), cfg)


@pytest.mark.parametrize("argv, message", [
    (["--config", "X.toml", "--scene", "S.toml"], "not both"),
    (["--serial", "/dev/ttyUSB0"], "need --config"),
    (["--config", "{cfg}"], "needs --corner X Y Z"),
    (["--config", "{cfg}", "--corner", "1", "2", "3", "--unit-seed", "4"], "simulated unit"),
    (["--config", "{cfg}", "--corner", "1", "2", "3", "--max-s", "0"], "--max-s must be > 0"),
    # the port is blamed where it was given: --serial (the file's [head] port was right), or the file
    (["--config", "{cfg}", "--corner", "1", "2", "3", "--serial", "/nonexistent/tty-x"],
     r"(?s)\A(?!.*\[head\]).*error: --serial '/nonexistent/tty-x' cannot be opened"),
    (["--config", "{cfg}", "--corner", "1", "2", "3"], r"d\.toml \[head\]: port '\S*/x' cannot be opened"),
])
def test_command_line_mistakes_are_named(tmp_path, capsys, argv, message):
    cfg = _config(tmp_path, tmp_path / "x", free_udp_port())
    rc = main(["calibrate", *[a.format(cfg=cfg) for a in argv], "--out", str(tmp_path / "t.json")])
    err = capsys.readouterr().err
    assert rc == 2
    assert re.search(message, err), err
    assert "Traceback" not in err and not (tmp_path / "t.json").exists()
