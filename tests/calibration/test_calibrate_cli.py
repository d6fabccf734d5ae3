"""`foveatrack calibrate` and the driver adapter (fast cases)."""

import json

import numpy as np
import pytest

from calib_fixture import ROOT
from foveatrack.cli import main
from foveatrack.calibration.drive import CalibrationDriver, drive_calibration
from foveatrack.cli.calibrate_cmd import ranges
from foveatrack.control import STOP, HeadCommand
from foveatrack.frames import Frame
from foveatrack.reconstruction import rotation_matrix

SCENE = str(ROOT / "scenes" / "calibration-room.toml")


class _Script:
    """A calibrator stand-in: returns scripted commands (None = keep) and is done after them."""

    def __init__(self, script):
        self.script = list(script)
        self.done = False

    def step(self, frame):
        cmd = self.script.pop(0)
        self.done = not self.script
        return cmd


def _frames(n):
    for k in range(n):
        yield Frame(k * 0.1, (k + 1) * 0.1, np.zeros((0, 3)), np.zeros(0, np.int64))


def test_driver_latches_none_and_ends_with_stop():
    left = HeadCommand(1, 20, 0, 0)
    sent = []
    drv = drive_calibration(_Script([None, left, None, None, HeadCommand(0, 0, 1, 5)]), _frames(100),
                            lambda t, c: sent.append(c), send_delay_s=0.002)
    assert [c for c in sent] == [STOP, left, left, left, STOP]        # done -> STOP, frames not consumed further
    assert drv.finished and [c for _, c in drv.sent] == [left, STOP]
    assert CalibrationDriver(_Script([None, None]))(next(_frames(1)), 0.1) == STOP


def test_the_room_corner_is_found_from_the_scene():
    from sim.calibration_run import room_corner_in_view
    from sim.scene import load_scene

    q = room_corner_in_view(load_scene(SCENE))
    # room x in [-3, 5], y in [-3, 3], z in [-1.5, 1.5]: the (5, 3, 1.5) corner, seen from pan 23, tilt 6.5
    assert np.allclose(rotation_matrix(23.0, 6.5) @ q, [5.0, 3.0, 1.5], atol=1e-9)


def test_ranges():
    assert ranges([0, 1, 2, 5, 7, 8, 255]) == "0-2, 5, 7-8, turbo"


def test_missing_or_mixed_modes_are_clear_errors(capsys):
    # Real devices are named by a daemon config (tests/daemon/test_calibrate_devices.py runs them).
    assert main(["calibrate", "--serial", "/dev/ttyUSB0", "--lidar", "192.168.1.50"]) == 2
    assert "need --config DAEMON.toml" in capsys.readouterr().err
    assert main(["calibrate"]) == 2
    err = capsys.readouterr().err
    assert "--scene SCENE.toml" in err and "--config DAEMON.toml" in err
    assert main(["calibrate", "--scene", SCENE, "--pan-bytes", "12,x"]) == 2


@pytest.mark.parametrize("dwell", ["0", "0.5", "-1", "nan", "inf"])
def test_a_bad_dwell_names_the_flag_and_its_range(capsys, dwell):
    # before: "calibration plan: need dwell_s > settle_s >= 0 ...", the plan's field names, not the flag
    assert main(["calibrate", "--scene", SCENE, "--dwell-s", dwell]) == 2
    err = capsys.readouterr().err
    assert f"--dwell-s {float(dwell):g}:" in err and "> 0.5" in err and "Traceback" not in err


def test_calibrate_cli_writes_the_table_and_reports(tmp_path, capsys):
    out, png = tmp_path / "t.json", tmp_path / "t.png"
    rc = main(["calibrate", "--scene", SCENE, "--unit-seed", "4343", "--pan-bytes", "24,40", "--tilt-bytes", "63",
               "--dwell-s", "3", "--out", str(out), "--plot", str(png), "--json"])
    assert rc == 0
    s = json.loads(capsys.readouterr().out)
    assert s["measured"] == 3 and s["within_tolerance"] == 3
    # byte 0 lies below the lowest byte measured (24): no speed, not interpolated (it said
    # interpolated while the table held NaN there); 30 lies between 24 and 40
    assert 0 in s["unmeasured"]["pan"]["not in the plan, outside the measured bytes (no speed: never sent)"]
    assert 30 in s["unmeasured"]["pan"]["not in the plan (interpolated)"]
    t = json.loads(out.read_text())
    assert t["format"] == "foveatrack-speed-table" and "4343" in t["head"]
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize("cmd", [["calibrate", "--scene", SCENE], ["calibrate-imu", str(ROOT / "scenes" / "imu-calibration-yard.toml")]])
def test_a_plot_that_exists_is_not_replaced_unasked(tmp_path, capsys, cmd):
    # --out refused an existing file, --plot replaced one in silence
    png = tmp_path / "mine.png"
    png.write_bytes(b"a plot the user keeps")
    assert main(cmd + ["--plot", str(png), "--out", str(tmp_path / "out.json")]) == 2   # (--out: never the cwd's)
    err = capsys.readouterr().err
    assert "--plot" in err and "exists" in err and "Traceback" not in err, err
    assert png.read_bytes() == b"a plot the user keeps"


# ---- the report's warnings reach the user, whichever way the report is shown --------------------

WARNING = "the plan's start tilt disagrees with the corner's motion (a test's sentence)"


def _report(warnings):
    from foveatrack.calibration import CalibrationReport

    return CalibrationReport({"pan": {}, "tilt": {}}, {"pan": (0.0, 0.0, 1.0), "tilt": (0.0, 1.0, 0.0)}, 0.0,
                             {"pan": {}, "tilt": {}}, 0.04, None, 10, 10, warnings=warnings)


def _scene_run(warnings):
    from sim.calibration_run import CalibrationRun
    from foveatrack.speed_table import SpeedTable

    t = SpeedTable.nominal()
    return CalibrationRun(t, _report(warnings), t, [], 10, 1.0, 0.1, (23.0, 6.5), (23.0, 6.5))


def _device_run(warnings):
    from foveatrack.calibration import CalibrationPlan
    from foveatrack.calibration.live import LiveCalibration
    from foveatrack.speed_table import SpeedTable

    return LiveCalibration(SpeedTable.nominal(), _report(warnings), CalibrationPlan(), {}, 10, 1.0)


def _device_config(tmp_path):
    cfg = tmp_path / "d.toml"
    cfg.write_text('[lidar]\nsensor_ip = "127.0.0.1"\nhost_ip = "127.0.0.1"\n[head]\nport = "loop://"\ntilt0_deg = 35.0\n')
    return str(cfg)


@pytest.mark.parametrize("mode", ["scene", "config"])
@pytest.mark.parametrize("json_out", [False, True])
def test_the_reports_warnings_are_shown_in_text_and_json(tmp_path, capsys, monkeypatch, mode, json_out):
    # Both routes of `calibrate` (simulated head, real devices) with the calibration itself replaced
    # by a finished run whose report carries a warning: the printing is what is tested here (what
    # raises the warning: test_start_tilt_prior.py).
    import foveatrack.calibration.live as live
    import foveatrack.cli.calibrate_cmd as cc

    if mode == "scene":
        module, name, run = cc, "calibrate_scene", _scene_run
        argv = ["calibrate", "--scene", SCENE]
    else:
        module, name, run = live, "calibrate_live", _device_run
        argv = ["calibrate", "--config", _device_config(tmp_path), "--corner", "5.9", "0.8", "0.84", "--no-progress"]
    argv += ["--json"] if json_out else []
    for k, warnings in enumerate([(WARNING,), ()]):
        monkeypatch.setattr(module, name, lambda *a, w=warnings, **kw: run(w))
        assert main(argv + ["--out", str(tmp_path / f"t{k}.json")]) == 0
        out, err = capsys.readouterr()
        said = [line for line in err.splitlines() if "warning" in line.lower()]
        assert said == [f"calibrate: warning: {w}" for w in warnings], err
        if json_out:
            assert json.loads(out)["warnings"] == list(warnings)


def test_too_short_legs_are_named_as_such_and_the_accelerations_per_axis(tmp_path, capsys):
    # before: "the corner was lost in every leg" of legs whose 0.6 s held 0.1 s after the settle, and
    # one acceleration printed, pan's, where the table holds both (a user's audit)
    argv = ["calibrate", "--scene", SCENE, "--pan-bytes", "40", "--tilt-bytes", "63"]
    assert main(argv + ["--dwell-s", "0.6", "--out", str(tmp_path / "a.json")]) == 2
    err = capsys.readouterr().err
    assert "0.1 s after its 0.5 s settle (dwell 0.6 s)" in err and "longer dwell" in err, err
    assert main(argv + ["--dwell-s", "1.5", "--out", str(tmp_path / "b.json")]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if "dead time" in ln)
    t = json.loads((tmp_path / "b.json").read_text())
    assert f"acceleration pan {t['axes']['pan']['accel_deg_s2']:.1f}, tilt {t['axes']['tilt']['accel_deg_s2']:.1f}" \
        in line, line
