"""Config gaps of issue 16 (item 7), each with its message: no silent defaults for addresses and the
head's port, a recording directory that must exist, ``--check`` that opens the devices, and a run
without lidar data that exits non-zero."""

import os
import socket
import subprocess
import sys

import pytest

from child_procs import dies_with_this_process
from daemon_procs import ROOT, env
from foveatrack.daemon import Daemon, load_config
from foveatrack.errors import UserError

FULL = {
    "lidar": 'sensor_ip = "127.0.0.1"\nhost_ip = "127.0.0.1"\ncmd_port = 0\ndata_port = 0\nbroadcast_port = false\n'
             'sensor_cmd_port = 65000',
    "head": 'port = "loop://"',
}


def _write(tmp_path, lidar=None, head=None, recording=""):
    p = tmp_path / "d.toml"
    p.write_text(f"[lidar]\n{FULL['lidar'] if lidar is None else lidar}\n[head]\n{FULL['head'] if head is None else head}\n"
                 + (f"[recording]\n{recording}\n" if recording else ""))
    return p


def _cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "foveatrack", *args], cwd=ROOT, env=env(), capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.parametrize("key", ["sensor_ip", "host_ip"])
def test_a_missing_lidar_address_is_an_error_naming_file_and_key(tmp_path, key):
    lidar = "\n".join(line for line in FULL["lidar"].splitlines() if not line.startswith(key))
    p = _write(tmp_path, lidar=lidar)
    with pytest.raises(UserError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert str(p) in msg and "[lidar]" in msg and f"{key} is required" in msg and "192.168.1." in msg


def test_a_missing_head_port_is_an_error_naming_the_key_not_a_default_device(tmp_path):
    p = _write(tmp_path, head='baud = 9600')
    with pytest.raises(UserError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert str(p) in msg and "[head]: port is required" in msg and "/dev/serial/by-id/" in msg


def test_a_recording_directory_that_does_not_exist_is_refused_unless_asked(tmp_path):
    typo = tmp_path / "runz"
    p = _write(tmp_path, recording=f'path = "{typo}/run-{{time}}.mcap"')
    d = Daemon(load_config(p), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    with pytest.raises(UserError) as exc:
        d._open()
    msg = str(exc.value)
    assert "[recording] path" in msg and str(typo) in msg and "does not exist" in msg and "make_dirs" in msg
    assert not typo.exists()
    p = _write(tmp_path, recording=f'path = "{typo}/run-{{time}}.mcap"\nmake_dirs = true')
    d = Daemon(load_config(p), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    d._open()
    try:
        assert typo.is_dir()
    finally:
        d.recorder.close()
        d.client.close()
        d.head.close()


def test_check_opens_the_head_port_and_binds_the_lidar_sockets(tmp_path):
    p = _write(tmp_path, head=f'port = "{tmp_path / "no-such-adapter"}"')
    r = _cli("daemon", "--config", str(p), "--check")
    assert r.returncode == 2 and "[head]" in r.stderr and "no-such-adapter" in r.stderr and "cannot be opened" in r.stderr
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        busy = s.getsockname()[1]
        p = _write(tmp_path, lidar=FULL["lidar"].replace("data_port = 0", f"data_port = {busy}"))
        r = _cli("daemon", "--config", str(p), "--check")
    assert r.returncode == 2 and "Address already in use" in r.stderr and str(busy) in r.stderr, r.stderr
    assert "[lidar] data_port" in r.stderr, r.stderr      # the key to change (a user's clash did not say)
    r = _cli("daemon", "--config", str(_write(tmp_path)), "--check")
    assert r.returncode == 0 and "head port 'loop://' opened" in r.stderr and "lidar sockets bound" in r.stderr


@pytest.mark.parametrize("ports, keys, value", [
    ("cmd_port = 56101\ndata_port = 56101\nbroadcast_port = false", "cmd_port and data_port", 56101),
    ("cmd_port = 0\ndata_port = 56100\nbroadcast_port = 56100", "data_port and broadcast_port", 56100),
    ("cmd_port = 55000\ndata_port = 0\nbroadcast_port = 55000", "cmd_port and broadcast_port", 55000),
    ("data_port = 56001\nbroadcast_port = false", "cmd_port (its default) and data_port", 56001),
])
def test_a_lidar_port_repeated_in_the_table_is_refused_at_load_naming_both_keys(tmp_path, ports, keys, value):
    """A user's data_port equal to its cmd_port failed at bind as 'Address already in use' on
    cmd_port, and one equal to broadcast_port blamed 'another process' (a second daemon?)."""
    p = _write(tmp_path, lidar='sensor_ip = "127.0.0.1"\nhost_ip = "127.0.0.1"\nsensor_cmd_port = 65000\n' + ports)
    with pytest.raises(UserError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert str(p) in msg and f"[lidar]: {keys} are both {value}" in msg and "a port of its own" in msg, msg


def test_lidar_ports_of_0_may_repeat_each_is_any_free_port(tmp_path):
    p = _write(tmp_path, lidar='sensor_ip = "127.0.0.1"\nhost_ip = "127.0.0.1"\ncmd_port = 0\ndata_port = 0\n'
                               'broadcast_port = 0')
    assert (load_config(p).lidar.cmd_port, load_config(p).lidar.data_port) == (0, 0)


@pytest.mark.slow
def test_a_run_without_lidar_data_exits_non_zero_and_says_so(tmp_path):
    p = _write(tmp_path)
    r = _cli("daemon", "--config", str(p), "--duration-s", "1.5", "--no-status")
    assert r.returncode == 3, (r.returncode, r.stderr)
    assert "no lidar data arrived" in r.stderr and "no frame processed" in r.stderr and "nan" not in r.stderr


def test_the_discovery_port_is_exclusive_and_a_second_holder_is_told(tmp_path):
    """Two hosts, one lidar (issue 16, item 9): the discovery socket was shared (SO_REUSEADDR), so a
    second process bound to the port silently took most broadcasts."""
    from foveatrack.livox.client import LivoxClient
    from daemon_procs import free_udp_port

    port = free_udp_port()
    first = LivoxClient("127.0.0.1", "127.0.0.1", cmd_port=0, data_port=0, broadcast_port=port)
    try:
        with pytest.raises(UserError) as exc:
            LivoxClient("127.0.0.1", "127.0.0.1", cmd_port=0, data_port=0, broadcast_port=port)
        msg = str(exc.value)
        assert f"discovery port {port}" in msg and "another process" in msg and "broadcast_port = false" in msg
        # nor may anyone else share it behind the client's back
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        with pytest.raises(OSError):
            s.bind(("", port))
        s.close()
    finally:
        first.close()


@pytest.mark.parametrize("sky, warned", [("[tracker.sky]\n", True), ("[tracker.sky]\nfield_half_angle_deg = 19.2\n", False),
                                         ("", False)])
def test_a_sky_table_without_the_lidars_field_is_a_warning(tmp_path, sky, warned):
    p = _write(tmp_path)
    p.write_text(p.read_text() + sky)
    w = [x for x in load_config(p).warnings() if "field_half_angle_deg" in x]
    assert bool(w) == warned
    if warned:
        assert "[tracker.sky]" in w[0] and "19.2" in w[0]


def test_the_status_line_counts_the_sky_trackers_tracks(tmp_path):
    # one drone (0.2 m) seen for a second through the daemon's own controller: the status names its tracks
    import numpy as np

    from foveatrack.frames import Frame

    p = _write(tmp_path)
    p.write_text(p.read_text() + "[tracker.sky]\nwarmup_s = 0.0\nfield_half_angle_deg = 19.2\n")
    d = Daemon(load_config(p), log_path=str(tmp_path / "d.jsonl"), status=False, install_signals=False)
    assert not any(n.startswith("tracks") for n in d.status_notes())
    rng = np.random.default_rng(1)
    for k in range(10):
        t0 = k * 0.1
        c = np.array([20.0, 2.0 - 0.1 * k, 1.0])
        xyz = c + rng.normal(0, 0.03, (20, 3))
        t_ns = np.sort(rng.integers(int(t0 * 1e9), int((t0 + 0.1) * 1e9), 20)).astype(np.int64)
        d.tracker.process(Frame(t0, t0 + 0.1, xyz, t_ns), t0 + 0.1)
    note = next(n for n in d.status_notes() if n.startswith("tracks"))
    assert note.startswith("tracks 1 (") and "fovea on" in note, note
    d.tracker.pin(next(v.track_id for v in d.tracker.last_output.sky.tracks if v.confirmed))
    d.tracker.process(Frame(1.0, 1.1, xyz, t_ns + 100_000_000), 1.1)
    assert "pinned" in next(n for n in d.status_notes() if n.startswith("tracks"))


@pytest.mark.slow
def test_a_ctrl_c_before_the_lidar_could_announce_itself_is_no_lidar_fault(tmp_path):
    # A user's SIGTERM 0.8 s after the start got "no lidar data arrived ... is the lidar on and on this
    # network" and exit 3: a Livox announces itself once a second, so nothing had had time to arrive.
    import signal
    import subprocess
    import sys
    import time

    p = _write(tmp_path)
    log = tmp_path / "d.jsonl"
    proc = subprocess.Popen(dies_with_this_process([sys.executable, "-m", "foveatrack", "daemon", "--config", str(p),
                                                    "--no-status", "--log", str(log)]),
                            cwd=ROOT, env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
        if log.exists() and '"start"' in log.read_text():
            break
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "stopped by a signal" in err and "no lidar fault" in err and "is the lidar on" not in err, err


def test_check_refuses_a_recording_path_the_start_would_refuse(tmp_path):
    # --check passed an existing recording (the start then refused to overwrite it) and a directory
    keep = tmp_path / "keep.mcap"
    keep.write_bytes(b"the user's recording")
    r = _cli("daemon", "--config", str(_write(tmp_path, recording=f'path = "{keep}"')), "--check")
    assert r.returncode == 2 and "[recording] path" in r.stderr and "already exists" in r.stderr, r.stderr
    r = _cli("daemon", "--config", str(_write(tmp_path, recording=f'path = "{tmp_path}"\noverwrite = true')), "--check")
    assert r.returncode == 2 and "is a directory" in r.stderr, r.stderr
    assert keep.read_bytes() == b"the user's recording"


def test_check_names_the_bytes_a_supplied_speed_table_steers_wrong(tmp_path):
    # a user's table with two rows swapped and no tilt speed above byte 24: it runs (not refused), and
    # `daemon --check` (as the start) says so, naming the file's key and the bytes
    import json

    d = json.loads((ROOT / "examples" / "pts303h-unit3-speed-table.json").read_text())
    pan = d["axes"]["pan"]["entries"]
    i16, i20 = [k for k, e in enumerate(pan) if e["byte"] in (16, 20)]
    pan[i16]["speed"], pan[i20]["speed"] = pan[i20]["speed"], pan[i16]["speed"]
    d["axes"]["tilt"]["entries"] = [e for e in d["axes"]["tilt"]["entries"] if e["byte"] <= 24]
    (tmp_path / "table.json").write_text(json.dumps(d))
    p = _write(tmp_path, head=FULL["head"] + '\nspeed_table = "table.json"')
    r = _cli("daemon", "--config", str(p), "--check")
    assert r.returncode == 0, r.stderr
    said = [line for line in r.stderr.splitlines() if "WARNING" in line and "speed_table 'table.json'" in line]
    assert len(said) == 2, r.stderr
    assert "byte 20 (2.126 deg/s) is slower than byte 16 (2.799)" in said[0]
    assert "tilt bytes 25-63 have no speed" in said[1]
    # the example as shipped: nothing to say
    p = _write(tmp_path, head=FULL["head"] + f'\nspeed_table = "{ROOT / "examples" / "pts303h-unit3-speed-table.json"}"')
    r = _cli("daemon", "--config", str(p), "--check")
    assert r.returncode == 0 and "WARNING" not in r.stderr, r.stderr


def test_a_table_measured_under_the_configs_byte_limits_is_not_said_to_lack_the_bytes_above_them(tmp_path):
    # `calibrate --config` under [head] max_pan_byte = 40 measures no pan byte above 40 (its plan drops
    # them): every start and --check then warned that "pan bytes 41-63 have no speed ... never sent",
    # bytes this config forbids anyway (review).  Missing bytes are said only up to the limit.
    import json

    d = json.loads((ROOT / "examples" / "pts303h-unit3-speed-table.json").read_text())
    d["axes"]["pan"]["entries"] = [e for e in d["axes"]["pan"]["entries"] if e["byte"] != "turbo" and e["byte"] <= 40]
    (tmp_path / "table.json").write_text(json.dumps(d))
    warnings = load_config(_write(tmp_path, head=FULL["head"] + '\nspeed_table = "table.json"\nmax_pan_byte = 40'
                                  '\nallow_turbo = false')).warnings()
    assert not [w for w in warnings if "speed_table" in w], warnings
    # a limit above the table's highest byte: the bytes between are said, and only those
    warnings = load_config(_write(tmp_path, head=FULL["head"] + '\nspeed_table = "table.json"\nmax_pan_byte = 50'
                                  '\nallow_turbo = false')).warnings()
    said = [w for w in warnings if "speed_table" in w]
    assert len(said) == 1 and "pan bytes 41-50 have no speed (the highest listed is 40, the highest the head may " \
                              "be sent 50)" in said[0], said
