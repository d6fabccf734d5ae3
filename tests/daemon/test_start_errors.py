"""A daemon whose head port, lidar port or recording path cannot be used fails at start with a
message naming the config key, and leaves no recording behind; a run that got no lidar data says
why at the end.  (Found by a review: a head port that was a typo, a regular file or /dev/null gave
a daemon that "tracked" for minutes with no head and said nothing; every failed start left an empty
recording; a mistyped sensor_ip ended on "0 frames" with the reason only in the log.)"""

import socket
import time
from pathlib import Path

import pytest

from daemon_procs import silent_lidar_table

from foveatrack.daemon import Daemon, load_config
from foveatrack.errors import UserError


def _daemon(tmp_path, port, sensor_ip="127.0.0.1", data_port=0, rec_dir=None):
    rec_dir = rec_dir or tmp_path / "runs"
    cfg = tmp_path / "d.toml"
    cfg.write_text(f"""
{silent_lidar_table(sensor_ip, data_port)}[head]
port = "{port}"
[recording]
path = "{rec_dir}/run-{{time}}.mcap"
make_dirs = true
""")
    return Daemon(load_config(cfg), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)


@pytest.mark.parametrize("port", ["{tmp}/not-a-tty.txt", "{tmp}/no-such-adapter", "/dev/null", "sockett://x:1"])
def test_a_head_port_that_cannot_be_opened_fails_the_start(tmp_path, port):
    (tmp_path / "not-a-tty.txt").write_text("a regular file\n")
    port = port.format(tmp=tmp_path)
    d = _daemon(tmp_path, port)
    with pytest.raises(UserError) as exc:
        d._open()
    msg = str(exc.value)
    assert "[head]" in msg and repr(port) in msg and "cannot be opened" in msg and "/dev/ttyUSB0" in msg
    if port in (str(tmp_path / "not-a-tty.txt"), "/dev/null"):     # pyserial's ENOTTY, said in words
        assert "is not a serial device" in msg, msg
    assert not (tmp_path / "runs").exists()   # no empty recording left behind


def test_a_busy_lidar_port_fails_the_start_without_a_recording(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        d = _daemon(tmp_path, "loop://", data_port=s.getsockname()[1])
        with pytest.raises(UserError, match="Address already in use"):
            d._open()
    assert not (tmp_path / "runs").exists()


def test_a_busy_live_port_fails_the_start_without_a_recording(tmp_path):
    """The live view is opened after the recording (it serves the recording's channels): a port in
    use failed the start and left a recording with no frame and an empty command journal."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        d = _daemon(tmp_path, "loop://")
        d.live_port = s.getsockname()[1]
        with pytest.raises(UserError, match=f"--live {d.live_port}: cannot serve"):
            d._open()
    assert list((tmp_path / "runs").iterdir()) == []
    assert d.recording_path is None     # the end-of-run line names no recording


def test_a_recording_path_that_cannot_be_created_is_a_user_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    d = _daemon(tmp_path, "loop://", rec_dir=blocker / "runs")   # a directory inside a regular file
    # asked before anything is opened (DaemonConfig.check_recording_dir, the question --check asks too)
    with pytest.raises(UserError, match=r"\[recording\] path: \S*file is not a directory this user can write in"):
        d._open()


def test_no_lidar_data_is_explained_naming_the_senders_dropped(tmp_path):
    d = _daemon(tmp_path, "loop://", sensor_ip="127.0.0.2")   # the lidar really is 127.0.0.1
    d._open()
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b"\x00" * 32, ("127.0.0.1", d.host_ports["data"]))
        deadline = time.monotonic() + 2.0
        while not d.client.foreign_addresses and time.monotonic() < deadline:
            d.client.poll(0.05)
        d.rx.counters = d.client.counters
        problems = d.problems()
    finally:
        d.client.close()
        d.head.close()
        d.recorder.close()
    assert len(problems) == 1
    assert "no lidar data arrived from [lidar] sensor_ip 127.0.0.2" in problems[0]
    assert "from 127.0.0.1 were dropped" in problems[0] and "is sensor_ip the lidar's address?" in problems[0]


def test_the_recording_path_is_printed_resolved(tmp_path, monkeypatch, capsys):
    """A recording path relative to a config given by a relative path was printed as
    `sub/../out/runs/...`; it is printed (and logged) absolute, without `..`."""
    from foveatrack.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    _daemon(tmp_path / "sub", "loop://", rec_dir="../out/runs")      # writes sub/d.toml
    # no lidar in this test: the run ends with exit status 3 ("no lidar data arrived")
    assert main(["daemon", "--config", "sub/d.toml", "--duration-s", "0.2", "--no-status"]) == 3
    err = capsys.readouterr().err
    printed = err.split("; recording ", 1)[1].split()[0]
    assert Path(printed).is_absolute() and ".." not in Path(printed).parts, err
    assert Path(printed).parent == (tmp_path / "out" / "runs").resolve() and Path(printed).is_file()


def test_a_silent_lidar_is_said_on_stderr_while_it_runs_not_only_at_its_end(tmp_path, capsys):
    # before: with stderr not a terminal (systemd's journal, a file) there is no status line, and a
    # daemon listening on the wrong broadcast port ran 10 minutes in silence; the reason came at exit
    d = _daemon(tmp_path, "loop://", sensor_ip="127.0.0.2")
    from foveatrack.daemon.watchdog import WatchdogState

    d._open()
    try:
        d.started_mono, d.watchdog = 1000.0, WatchdogState()
        for now in (1005.0, 1010.05, 1030.0, 1070.1, 1075.0):
            d._watch_lidar(now)
        err = capsys.readouterr().err
    finally:
        d.client.close()
        d.head.close()
        d.recorder.close()
    notes = [ln for ln in err.splitlines() if "no lidar data arrived" in ln]
    assert len(notes) == 2, err
    assert notes[0].startswith("foveatrack daemon: WARNING: no lidar data arrived from [lidar] sensor_ip 127.0.0.2 "
                               "in 10 s so far (data port ")
    assert "in 70 s so far" in notes[1] and "nothing arrived at all" in notes[1]


def test_a_status_line_note_stands_on_its_own_line_above_the_status():
    import io

    from foveatrack.daemon.support import StatusLine

    tty = io.StringIO()
    s = StatusLine(tty, enabled=True)
    s.show("10.0 Hz")
    s.note("WARNING: x")
    s.show("0.0 Hz")
    assert tty.getvalue() == "\r10.0 Hz\x1b[K\r\x1b[KWARNING: x\n\r0.0 Hz\x1b[K"
    plain = io.StringIO()
    s = StatusLine(plain, enabled=False)
    s.show("10.0 Hz")
    s.note("WARNING: x")
    assert plain.getvalue() == "WARNING: x\n"


def _denied(url, **kwargs):
    """pyserial's open of a device this user may not open (root's opens are never refused, so the
    permission error is raised here, as pyserial raises it for a user outside the device's group)."""
    import errno

    import serial

    raise serial.SerialException(errno.EACCES, f"could not open port {url}: [Errno 13] Permission denied: {url!r}")


def _serial_group() -> tuple[int, str]:
    """A group other than root's for the fake device, and its name as the message gives it: dialout
    (a USB adapter's group on Debian and Fedora), else any other group the system has (Arch names it
    uucp), else a number no group has (named by its number)."""
    import grp

    for g in [e for e in grp.getgrall() if e.gr_name == "dialout"] + [e for e in grp.getgrall() if e.gr_gid != 0]:
        return g.gr_gid, g.gr_name
    return 4242, "4242"


@pytest.mark.parametrize("group", ["root", "serial"])
def test_a_head_port_this_user_may_not_open_says_so_and_what_to_do(tmp_path, monkeypatch, group):
    """A non-root user's /dev/ttyUSB0 without the dialout group was told to give a device "that exists
    now" or to start 'foveatrack gimbal serve': the port exists, the user may not open it."""
    import os

    import serial

    gid, name = (0, "root") if group == "root" else _serial_group()
    port = tmp_path / "ttyUSB0"
    port.write_text("")
    os.chown(port, 0, gid)
    port.chmod(0o660 if group != "root" else 0o600)
    monkeypatch.setattr(serial, "serial_for_url", _denied)
    d = _daemon(tmp_path, port)
    with pytest.raises(UserError) as exc:
        d._open()
    msg = str(exc.value)
    assert "[head]" in msg and repr(str(port)) in msg and "this user may not open it" in msg, msg
    assert "Permission denied" in msg and "gimbal serve" not in msg, msg
    if group == "serial":
        assert f"group {name}" in msg and f"usermod -aG {name} " in msg, msg
    else:
        assert "mode 600" in msg and "udev rule" in msg and 'GROUP="dialout"' in msg, msg
    assert not (tmp_path / "runs").exists()


def test_a_serial_option_port_this_user_may_not_open_is_not_blamed_on_the_config(tmp_path, monkeypatch):
    """A head port given by --serial that the user may not open was blamed on the config file
    ("d.toml [head]: port ..."), whose port was right; the message said "[Errno 13]" twice and
    formatted owner, group and mode by hand (review).  It names --serial, says the reason once and
    who may open the device in the words of every other permission message (errors.access_text)."""
    import serial

    from foveatrack.errors import access_text
    from foveatrack.live_devices import open_head

    port = tmp_path / "ttyUSB1"
    port.write_text("")
    port.chmod(0o600)
    monkeypatch.setattr(serial, "serial_for_url", _denied)
    config = _daemon(tmp_path, "/dev/ttyUSB0").cfg.with_head_port(str(port), "--serial")
    with pytest.raises(UserError) as exc:
        open_head(config)
    msg = str(exc.value)
    assert msg.startswith(f"--serial {str(port)!r} exists but this user may not open it"), msg
    assert str(config.path) not in msg and "[head]" not in msg and "/dev/ttyUSB0" not in msg, msg
    assert "Permission denied" in msg and "Errno" not in msg, msg
    assert f"is {access_text(port)}" in msg and "udev rule" in msg, msg


def test_a_refused_pyserial_url_gets_no_device_advice(tmp_path, monkeypatch):
    """A socket:// or rfc2217:// head port refused with EACCES is no device node: no group to join, no
    udev rule to write (the review found the dialout/udev advice given for any port)."""
    import serial

    from foveatrack.live_devices import open_head

    monkeypatch.setattr(serial, "serial_for_url", _denied)
    config = _daemon(tmp_path, "socket://127.0.0.1:4001").cfg
    with pytest.raises(UserError) as exc:
        open_head(config)
    msg = str(exc.value)
    assert msg.startswith(f"{config.path} [head]: port 'socket://127.0.0.1:4001' was refused"), msg
    assert "Permission denied" in msg, msg
    assert "dialout" not in msg and "udev" not in msg and "usermod" not in msg and "gimbal serve" not in msg, msg
