"""Helpers for the multi-process daemon tests: free ports, subprocesses of ``foveatrack``, log reading."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from child_procs import dies_with_this_process

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
SCENE = HERE / "scene_track.toml"


def free_udp_port(ip: str = "127.0.0.1") -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((ip, 0))
    port = s.getsockname()[1]
    s.close()
    return port


def silent_lidar_table(sensor_ip: str = "127.0.0.1", data_port: int = 0) -> str:
    """A daemon config's ``[lidar]`` table for a test with no lidar: no broadcast, and the handshake
    sent to a free port nothing listens on (with 65000 named, a virtual or real unit serving there
    on this machine answered it and streamed into tests that expected silence)."""
    return (f'[lidar]\nsensor_ip = "{sensor_ip}"\nhost_ip = "127.0.0.1"\ncmd_port = 0\ndata_port = {data_port}\n'
            f"broadcast_port = false\nsensor_cmd_port = {free_udp_port()}\n")


def loop_head_daemon(tmp_path: Path, rec_path=None, extra: str = "", **daemon_kw):
    """An in-process daemon for a test with no devices: no lidar (:func:`silent_lidar_table`), the
    head on pyserial's ``loop://``, recording to ``rec_path`` (default: a new file per start under
    ``tmp_path/runs``); ``extra``: more ``[recording]`` keys."""
    from foveatrack.daemon import Daemon, load_config

    rec = rec_path if rec_path is not None else f"{tmp_path}/runs/run-{{time}}.mcap"
    cfg = tmp_path / "d.toml"
    cfg.write_text(f'''
{silent_lidar_table()}[head]
port = "loop://"
[recording]
path = "{rec}"
make_dirs = true
{extra}
''')
    daemon_kw.setdefault("status", False)
    daemon_kw.setdefault("install_signals", False)
    return Daemon(load_config(cfg), **daemon_kw)


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    e["PYTHONUNBUFFERED"] = "1"
    return e


def start(args: list[str], out: Path, err: Path) -> subprocess.Popen:
    return subprocess.Popen(dies_with_this_process([sys.executable, "-m", "foveatrack", *args]), cwd=ROOT,
                            env=env(), stdout=open(out, "w"), stderr=open(err, "w"), start_new_session=True)


def wait_for(pred, timeout_s: float, what: str, procs=()):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        for p in procs:
            if p.poll() is not None:
                raise AssertionError(f"a process exited (rc {p.returncode}) while waiting for {what}")
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")



def head_clock_zero(err: Path) -> str | None:
    """The monotonic time of head time 0, from ``gimbal serve``'s banner on stderr (None until it is there)."""
    import re

    try:
        m = re.search(r"time\.monotonic\(\) = ([0-9.]+)", err.read_text())
    except OSError:
        return None
    return m.group(1) if m else None


def start_head_and_lidar(d: Path, head_args: list[str], scene, bport: int, procs: list,
                         lidar_timeout_s: float = 120.0) -> None:
    """``gimbal serve`` on a pty linked at ``d/head`` (truth in ``d/truth.jsonl``), then ``lidar serve
    SCENE`` following that truth, each appended to ``procs`` as it starts (so the caller's cleanup
    stops whatever did start).  The head's clock zero is given to the lidar: estimated, it shifts the
    pose the lidar sees whenever a truth line is read sooner than before, and a shift during a leg
    reads as speed (seen: a tilt rate 3 % high on a loaded machine); a real head and lidar have no
    such link."""
    link, truth = d / "head", d / "truth.jsonl"
    procs.append(start(["gimbal", "serve", "--link", str(link), "--truth", str(truth), *head_args],
                       d / "head.out", d / "head.err"))
    zero = wait_for(lambda: head_clock_zero(d / "head.err"), 20, "the head's pty and clock zero", procs)
    procs.append(start(["lidar", "serve", str(scene), "--cmd-port", "0", "--broadcast-port", str(bport),
                        "--head-truth", str(truth), "--head-clock-zero", zero], d / "l.out", d / "l.err"))
    wait_for(lambda: first_line(d / "l.out"), lidar_timeout_s, "the virtual lidar", procs)

def first_line(path: Path) -> str | None:
    try:
        txt = path.read_text()
    except OSError:
        return None
    return txt.split("\n", 1)[0] if "\n" in txt else None


def log_events(path: Path) -> list[dict]:
    out = []
    try:
        for line in path.read_text().splitlines():
            try:
                out.append(json.loads(line))
            except ValueError:
                pass
    except OSError:
        pass
    return out


def event(path: Path, name: str) -> dict | None:
    return next((e for e in log_events(path) if e["event"] == name), None)


def stop_all(procs: dict) -> None:
    """SIGTERM every process still running, then wait for each (killing one that does not stop in 10 s)."""
    for p in procs.values():
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs.values():
        try:
            p.wait(10)
        except Exception:  # noqa: BLE001
            p.kill()


def terminate(p: subprocess.Popen, timeout_s: float = 10.0) -> int:
    if p.poll() is None:
        p.send_signal(signal.SIGTERM)
    try:
        return p.wait(timeout_s)
    except subprocess.TimeoutExpired:
        p.kill()
        p.wait()
        raise AssertionError(f"{p.args} did not stop within {timeout_s} s of SIGTERM")


def write_config(path: Path, head_link: Path, recording: Path, broadcast_port: int, cmd_port: int = 0,
                 data_port: int = 0, watchdog_s: float = 2.0, speed_table: str = "nominal",
                 head_extra: str = "", recording_extra: str = "", tracker_extra: str = "") -> Path:
    """A daemon config for the virtual devices.  ``watchdog_s`` is 2 s, not the shipped 0.5 s: on a busy
    2-core machine the virtual lidar (a Python process ray-casting its batches) can pause for more than
    0.5 s, and a test about something else must not see a watchdog trip for it.  ``tracker_extra``: tables
    after ``[tracker.space]`` (``[tracker.sky]``)."""
    path.write_text(f"""
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
cmd_port = {cmd_port}
data_port = {data_port}
broadcast_port = {broadcast_port}

[head]
port = "{head_link}"
speed_table = "{speed_table}"
{head_extra}

[tracker]
deadband_deg = 2.0
gain_1_s = 2.0

[tracker.space]
kind = "box"
frame = "world"
min_xyz = [1.0, -60.0, -0.7]
max_xyz = [60.0, 60.0, 40.0]
{tracker_extra}
[recording]
path = "{recording}"
{recording_extra}

[daemon]
watchdog_s = {watchdog_s}
""")
    return path


def device_config(path: Path, head_link, broadcast_port: int, watchdog_s: float, head: dict | None = None,
                  lidar: dict | None = None) -> Path:
    """A daemon config with what the calibration commands read: the virtual devices on loopback, the
    head's port and the ``[head]`` / ``[lidar]`` keys given (values written as JSON, which TOML reads)."""
    def keys(d):
        return "".join(f"{k} = {json.dumps(v)}\n" for k, v in (d or {}).items())

    path.write_text(f"""
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
cmd_port = 0
data_port = 0
broadcast_port = {broadcast_port}
{keys(lidar)}[head]
port = "{head_link}"
{keys(head)}[daemon]
watchdog_s = {watchdog_s}
""")
    return path
