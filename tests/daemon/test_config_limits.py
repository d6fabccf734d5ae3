"""Daemon config validation (errors name the file and the key) and the last safety gate."""

from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from foveatrack.control import HeadCommand
from foveatrack.daemon import Limits, load_config
from foveatrack.errors import UserError
from foveatrack.speed_table import TURBO

ROOT = Path(__file__).resolve().parents[2]
GOOD = """
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
[head]
port = "/tmp/x"
[tracker]
deadband_deg = 2.0
"""


def _cfg(tmp_path, text):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    return p


def test_example_config_loads():
    cfg = load_config(ROOT / "examples" / "daemon-virtual.toml")
    assert cfg.tracker.rate_hz == 10.0 and cfg.head.baud == 9600
    assert cfg.tracker.tilt_limits_deg == (-30.0, 60.0)
    assert cfg.tracker.latency_s == pytest.approx(70 / 9600)
    # the shipped table is the virtual unit 3's measured one, not the datasheet's 15 deg/s
    from foveatrack.speed_table import SpeedTable

    shipped = SpeedTable.load(ROOT / "examples" / "pts303h-unit3-speed-table.json")
    assert cfg.speed_table().pan.max_speed_deg_s() == shipped.pan.max_speed_deg_s() != pytest.approx(15.0)


@pytest.mark.parametrize("protocol, baud, frame_bytes", [("D", 9600, 7), ("P", 9600, 8), ("P", 2400, 8)])
def test_the_tracker_dead_reckons_with_the_heads_own_frame_time(tmp_path, protocol, baud, frame_bytes):
    # A Pelco-P frame is 8 bytes: its command reaches the head 80 / baud after the send, not 70 / baud
    # (the old rule, written in four places, assumed Pelco-D everywhere).
    cfg = load_config(_cfg(tmp_path, GOOD.replace("[head]", f"[head]\nprotocol = '{protocol}'\nbaud = {baud}")))
    assert cfg.head.frame_time_s == pytest.approx(frame_bytes * 10 / baud)
    assert cfg.tracker.latency_s == pytest.approx(frame_bytes * 10 / baud)
    assert cfg.tracker_overrides["latency_s"] == pytest.approx(frame_bytes * 10 / baud)


@pytest.mark.parametrize("patch, key", [
    (("[head]", "[head]\nbaud = 9601.5"), "baud"),
    (("[head]", "[head]\nbaud = 9601"), "baud"),
    (("[head]", "[head]\naddress = 0"), "address"),
    (("[head]", "[head]\nprotocol = 'X'"), "protocol"),
    (("[head]", "[head]\nspeed_table = 'nope.json'"), "speed_table"),
    (("[head]", "[head]\ntilt_limits_deg = [10, -10]"), "tilt_limits_deg"),
    (("[head]", "[head]\nspeed = 3"), "speed"),
    (('sensor_ip = "127.0.0.1"', 'sensor_ip = "localhost"'), "sensor_ip"),
    (("[lidar]", "[lidar]\ndata_port = 70000"), "data_port"),
    (("[lidar]", "[lidar]\nbroadcast_port = false"), "sensor_cmd_port"),
    (("deadband_deg = 2.0", "deadband_deg = -1"), "deadband_deg"),
    (("deadband_deg = 2.0", "controler = 'paper'"), "controler"),
    (("[tracker]", "[daemon]\nwatchdog_s = 0\n[tracker]"), "watchdog_s"),
    (("[tracker]", "[recording]\ncompression = 'gzip'\n[tracker]"), "compression"),
])
def test_errors_name_file_and_key(tmp_path, patch, key):
    p = _cfg(tmp_path, GOOD.replace(*patch, 1))
    with pytest.raises(UserError) as e:
        load_config(p)
    msg = str(e.value)
    assert str(p) in msg and key in msg, msg


@pytest.mark.parametrize("baud", [300, 1200, 2400, 9600, 9601, 57600, 115200, 230400])
def test_daemon_and_scene_accept_the_same_bauds(tmp_path, baud):
    """A daemon's [head] baud follows a scene's [gimbal] baud rule (before: the daemon took any
    integer 300-115200, so 9601 was accepted there and refused in a scene)."""
    from sim.scene import scene_from_mapping

    def accepted(load):
        try:
            load()
        except UserError as e:
            assert "baud" in str(e)
            return False
        return True

    daemon_ok = accepted(lambda: load_config(_cfg(tmp_path, GOOD.replace("[head]", f"[head]\nbaud = {baud}", 1))))
    scene_ok = accepted(lambda: scene_from_mapping({"scene": {"name": "b", "duration_s": 1.0},
                                                    "lidar": {"preset": "mid40"}, "gimbal": {"baud": baud}}))
    assert daemon_ok == scene_ok == (baud in (1200, 2400, 9600, 57600, 115200))


def test_missing_file_and_bad_toml(tmp_path):
    with pytest.raises(UserError, match="no such daemon config"):
        load_config(tmp_path / "none.toml")
    with pytest.raises(UserError, match="not valid TOML"):
        load_config(_cfg(tmp_path, "[head\n"))
    with pytest.raises(UserError, match=r"missing \[head\]"):
        load_config(_cfg(tmp_path, "[lidar]\n"))


def test_cli_reports_config_error(tmp_path, capsys):
    from foveatrack.cli import main

    p = _cfg(tmp_path, GOOD.replace("[head]", "[head]\nbaud = 'fast'"))
    assert main(["daemon", "--config", str(p)]) == 2
    err = capsys.readouterr().err
    assert str(p) in err and "baud" in err and "Traceback" not in err


cmds = st.builds(
    lambda pd, pb, td, tb: HeadCommand(pd, 0 if pd == 0 else pb, td, 0 if td == 0 else tb),
    st.sampled_from([-1, 0, 1]), st.sampled_from(list(range(64)) + [TURBO]),
    st.sampled_from([-1, 0, 1]), st.integers(0, 63))


@settings(max_examples=300, deadline=None)
@given(cmds, st.floats(-40, 70), st.floats(0, 3), st.integers(0, 63), st.integers(0, 63), st.booleans())
def test_limits_never_let_a_forbidden_command_out(cmd, tilt, sigma, max_pan, max_tilt, turbo):
    lim = Limits(max_pan, max_tilt, turbo, (-30.0, 60.0), 2.0)
    out, why = lim.apply(cmd, tilt, sigma)
    assert (out.pan_byte <= max_pan) or (turbo and out.pan_byte == TURBO)
    assert out.tilt_byte <= max_tilt
    if out.tilt_dir > 0:
        assert tilt + 2 * sigma < 60.0 - 2.0
    if out.tilt_dir < 0:
        assert tilt - 2 * sigma > -30.0 + 2.0
    assert (out == cmd) == (not why)
    # never adds motion: a stopped axis stays stopped, a direction is never reversed
    assert out.pan_dir in (0, cmd.pan_dir) and out.tilt_dir in (0, cmd.tilt_dir)


def test_status_line_only_on_a_terminal():
    import io

    from foveatrack.daemon.support import StatusLine, format_status

    text = format_status(10.0, 9980, "tracking", 1.2, -0.3, 11.0, 0, True)
    assert "10.0 Hz" in text and "9980 pts/frame" in text and "tracking" in text and "+1.2/ -0.3" in text
    pipe = io.StringIO()
    StatusLine(pipe).show(text)          # StringIO is not a TTY: nothing written
    assert pipe.getvalue() == ""
    tty = io.StringIO()
    s = StatusLine(tty, enabled=True)
    s.show(text)
    s.show(text)
    s.done()
    assert tty.getvalue() == ("\r" + text + "\x1b[K") * 2 + "\n"


def test_the_heads_facts_win_by_one_rule_and_a_contradiction_names_the_key(tmp_path):
    """Stops, start pose and link timing are the head's ([head]); [tracker] may repeat them, not change them."""
    same = load_config(_cfg(tmp_path, GOOD.replace("[tracker]", "[tracker]\ntilt_limits_deg = [-30.0, 60.0]")))
    assert same.tracker.tilt_limits_deg == (-30.0, 60.0)
    head = load_config(_cfg(tmp_path, GOOD.replace("[head]", "[head]\npan0_deg = 12.5\ntilt_limits_deg = [-20, 50]")))
    assert head.tracker.pan0_deg == 12.5 and head.tracker.tilt_limits_deg == (-20.0, 50.0)
    for key, value in (("pan0_deg", "5.0"), ("tilt_limits_deg", "[-10.0, 40.0]"), ("latency_s", "0.02")):
        with pytest.raises(UserError, match=rf"\[tracker\]: {key} = .* contradicts the head's.*\[head\]"):
            load_config(_cfg(tmp_path, GOOD.replace("[tracker]", f"[tracker]\n{key} = {value}")))
