"""End to end on a real pseudo-terminal: ``foveatrack gimbal serve`` driven by HeadClient.

Runs in CI (Linux, no root) in a few seconds.  Real time, so assertions leave room for scheduling
jitter; exact numbers are checked in virtual time elsewhere.
"""

import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from child_procs import dies_with_this_process
from gimbal.client import HeadClient
from gimbal.pts303h import PTS303H, HeadParams
from sim.virtual_head import VirtualHeadServer, read_truth

ROOT = Path(__file__).resolve().parents[2]
SEED = 3
TILT0 = 59.6


def _serve_cmd():
    """``python -m foveatrack gimbal serve`` once every command group of the CLI is present;
    on a branch where some group is missing, the gimbal group's own entry point."""
    try:
        from foveatrack.cli import build_parser

        build_parser()
        return [sys.executable, "-m", "foveatrack", "gimbal", "serve"]
    except ImportError:
        return [sys.executable, "-m", "foveatrack.cli.gimbal_cmd", "serve"]


def _readline(stream, timeout_s=20.0):
    r, _, _ = select.select([stream], [], [], timeout_s)
    assert r, "the server printed nothing"
    return stream.readline().strip()


@pytest.fixture
def served(tmp_path):
    truth = tmp_path / "truth.jsonl"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen(
        dies_with_this_process(_serve_cmd() + ["--unit-seed", str(SEED), "--feedback", "at-rest", "--truth",
                                               str(truth), "--truth-period-s", "0.01", "--tilt0-deg", str(TILT0)]),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
    )
    try:
        path = _readline(proc.stdout)
        info = _readline(proc.stderr)
        zero = float(info.split("time.monotonic() = ")[1].split(";")[0])
        yield proc, path, truth, zero
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _truth_between(rows, t0, t1):
    return [r for r in rows if t0 <= r["t_s"] <= t1]


@pytest.mark.slow
def test_client_drives_the_served_head_end_to_end(served):
    proc, path, truth_path, zero = served
    assert path.startswith("/dev/")
    unit = PTS303H(unit_seed=SEED)
    params = HeadParams()
    client = HeadClient(path, write_timeout_s=0.02, read_timeout_s=0.055)
    assert client.connected

    # at rest: the head answers with its true position
    pos = client.query_position()
    assert pos is not None
    assert pos[0] == pytest.approx(0.0, abs=0.006) and pos[1] == pytest.approx(TILT0, abs=0.006)

    # move left and up: tilt runs into its upper stop within ~0.3 s and must hold there
    t_cmd = time.monotonic() - zero
    assert client.send_speeds(+1, 0x30, +1, 0x3F)
    moving_answers = []
    time.sleep(0.15)
    for _ in range(8):
        t_a = time.monotonic() - zero
        ans = client.query_position()
        t_b = time.monotonic() - zero
        moving_answers.append((t_a, t_b, ans))
        time.sleep(0.08)
    time.sleep(0.4)
    t_stop = time.monotonic() - zero
    assert client.stop()
    time.sleep(0.7)  # dead time + deceleration (15 deg/s at 40 deg/s^2 < 0.4 s)
    rest = client.query_position()
    t_rest = time.monotonic() - zero

    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=10) == 0  # clean stop
    client.close()
    rows = read_truth(truth_path)
    json.loads(truth_path.read_text().splitlines()[-1])  # last line complete

    # the truth file shows the commanded motion at the unit's speed for byte 0x30
    v_true = unit.true_speed_deg_s("pan", 0x30)
    steady = [r for r in _truth_between(rows, t_cmd, t_stop)
              if abs(r["pan_speed_deg_s"] - v_true) < 0.05 * v_true]
    assert len(steady) > 20
    dt = steady[-1]["t_s"] - steady[0]["t_s"]
    assert (steady[-1]["pan_deg"] - steady[0]["pan_deg"]) / dt == pytest.approx(v_true, rel=0.02)
    # nothing moved before the command, pan moved left (angle up)
    assert all(r["pan_deg"] == 0.0 for r in _truth_between(rows, 0.0, t_cmd))
    assert max(r["pan_deg"] for r in rows) > 5.0
    # the tilt stop holds: once at the stop, exactly there with zero speed until the end
    at_stop = [r for r in rows if r["tilt_deg"] == params.tilt_max_deg]
    assert at_stop and all(r["tilt_deg"] <= params.tilt_max_deg for r in rows)
    after = [r for r in rows if r["t_s"] >= at_stop[0]["t_s"]]
    assert all(r["tilt_deg"] == params.tilt_max_deg and r["tilt_speed_deg_s"] == 0 for r in after)
    # a stop halts it: the last rows do not move
    final = _truth_between(rows, t_stop + 0.6, t_rest + 1.0)
    assert len(final) > 3 and len({r["pan_deg"] for r in final}) == 1
    assert all(r["pan_speed_deg_s"] == 0.0 for r in final)

    # while moving, never a valid position; at rest, the true one
    for t_a, t_b, ans in moving_answers:
        if ans is None:
            continue
        near = _truth_between(rows, t_a - 0.02, t_b + 0.02)
        assert near
        assert all(abs(ans[0] - r["pan_deg"]) > 1.0 or abs(ans[1] - r["tilt_deg"]) > 1.0
                   for r in near)
    assert client.stats.bad_replies + sum(a is not None for *_, a in moving_answers) > 0
    assert rest is not None
    assert rest[0] == pytest.approx(final[-1]["pan_deg"], abs=0.006)
    assert rest[1] == pytest.approx(params.tilt_max_deg, abs=0.006)


def _thread_server(link, head):
    stop = threading.Event()
    srv = VirtualHeadServer(head, time.monotonic, link_path=str(link))
    srv.open()
    th = threading.Thread(target=srv.run, args=(stop.is_set,), daemon=True)
    th.start()

    def shutdown():
        stop.set()
        th.join(5)
        srv.close()

    return srv, shutdown


def test_client_reconnects_after_the_port_disappears(tmp_path):
    link = tmp_path / "ttyPTS"
    head1 = PTS303H()
    _, shutdown1 = _thread_server(link, head1)
    client = HeadClient(str(link), reconnect_interval_s=0.05)
    try:
        assert client.send_speeds(1, 0x20, 0, 0)
        shutdown1()  # the port disappears
        assert not link.exists()
        failures = 0
        for _ in range(5):
            failures += not client.send_speeds(1, 0x20, 0, 0)
            time.sleep(0.06)
        assert failures == 5 and not client.connected
        assert client.stats.write_failures + client.stats.open_failures >= 2
        head2 = PTS303H()
        _, shutdown2 = _thread_server(link, head2)  # a new device under the same name
        try:
            time.sleep(0.06)
            assert client.send_speeds(1, 0x20, 0, 0)
            assert client.stats.reconnects == 1
            for _ in range(100):
                if head2.frames_received:
                    break
                time.sleep(0.01)
            assert head2.frames_received == 1
        finally:
            shutdown2()
    finally:
        client.close()


def test_missing_port_and_loopback_never_raise():
    c = HeadClient("/nonexistent/ttyUSB9", reconnect_interval_s=0.0)
    assert not c.connected and not c.stop() and c.query_position() is None
    assert c.stats.open_failures == 3
    loop = HeadClient("loop://")  # hears its own queries (like an RS-485 echo), no head behind
    assert loop.query_position() is None
    assert loop.stats.query_timeouts == 1 and loop.stats.bad_replies == 0


def _serve_link(link, *extra):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen(dies_with_this_process(_serve_cmd() + ["--link", str(link), *extra]), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)


def _stop(*procs):
    for p in procs:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_a_second_server_on_a_live_link_is_refused_and_the_first_keeps_its_link(tmp_path):
    """A user's second 'gimbal serve --link /tmp/x' moved the link to its own pty without a word, and
    its exit removed it: the first head, still serving, had no link."""
    link = tmp_path / "tty"
    first = _serve_link(link)
    second = None
    try:
        assert _readline(first.stdout) == str(link)
        pty = os.readlink(link)
        second = _serve_link(link)
        try:
            code = second.wait(timeout=20)
        except subprocess.TimeoutExpired:       # it took the link: let it exit as a user would
            second.send_signal(signal.SIGINT)
            code = second.wait(timeout=10)
        err = second.stderr.read()
        assert code == 2, (code, err)
        assert f"--link {link} (-> {pty})" in err and f"process {first.pid} still serves" in err, err
        assert f"kill {first.pid}" in err and "another path" in err, err
        assert os.readlink(link) == pty and first.poll() is None and second.stdout.read() == ""
        _stops_and_leaves_nothing(first, link)
    finally:
        _stop(first, *([second] if second else []))


def _stops_and_leaves_nothing(server, link):
    """SIGINT stops a link's server with exit 0, and it removes its link and the link's lock file."""
    server.send_signal(signal.SIGINT)
    assert server.wait(timeout=10) == 0
    assert not os.path.lexists(link) and not os.path.lexists(f"{link}.lock")


def test_a_link_left_by_a_killed_server_is_taken_by_the_next(tmp_path):
    link = tmp_path / "tty"
    first = _serve_link(link)
    second = None
    try:
        assert _readline(first.stdout) == str(link)
        first.kill()                           # no clean exit: the link and the lock file stay
        first.wait(5)
        assert os.path.islink(link) and os.path.exists(f"{link}.lock")
        second = _serve_link(link)
        assert _readline(second.stdout) == str(link) and os.path.exists(os.readlink(link))
        with open(f"{link}.lock") as f:
            assert f.read().strip() == str(second.pid)
        _stops_and_leaves_nothing(second, link)
    finally:
        _stop(first, *([second] if second else []))


def test_a_server_removes_the_link_on_exit_only_while_it_points_to_its_own_pty(tmp_path):
    link = tmp_path / "tty"
    a = VirtualHeadServer(PTS303H(), time.monotonic, link_path=str(link))
    b = VirtualHeadServer(PTS303H(), time.monotonic, link_path=str(link))
    a.open()
    try:
        b.open()                               # in one process nothing refuses it: the link is b's now
        try:
            a.close()
            assert os.readlink(link) == b.path
        finally:
            b.close()
        assert not os.path.lexists(link)
    finally:
        a.close()


def test_sigint_stops_the_server_cleanly(tmp_path):
    truth = tmp_path / "t.jsonl"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen(dies_with_this_process(_serve_cmd() + ["--truth", str(truth), "--link", str(tmp_path / "tty")]),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        path = _readline(proc.stdout)
        assert path == str(tmp_path / "tty") and os.path.islink(path)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0
        assert not os.path.lexists(path)  # the link is removed
        assert read_truth(truth)[-1]["pan_deg"] == 0.0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_a_frame_the_port_took_is_sent_even_if_the_writer_was_descheduled(monkeypatch):
    # pyserial 3.5 raises SerialTimeoutException when its deadline passed during a write that took
    # every byte (this process descheduled for 20+ ms on a loaded machine): the command reached the
    # head, but was reported lost.  Our write counts the bytes the kernel took.
    master, slave = os.openpty()
    import tty

    tty.setraw(master)
    tty.setraw(slave)
    client = HeadClient(os.ttyname(slave), write_timeout_s=0.02)
    fd = client._ser.fd
    real_write = os.write

    def descheduled_write(f, data):
        n = real_write(f, data)
        if f == fd:
            time.sleep(0.05)          # well past the 20 ms deadline, after the kernel took the bytes
        return n

    monkeypatch.setattr(os, "write", descheduled_write)
    try:
        assert client.stop() is True
        assert client.send_speeds(+1, 0x20, 0, 0) is True
        assert client.stats.write_timeouts == 0 and client.stats.frames_sent == 2
        got = b""
        while len(got) < 14 and select.select([master], [], [], 1.0)[0]:
            got += os.read(master, 64)
        assert len(got) == 14 and got[:1] == b"\xff"        # both Pelco-D frames, whole
    finally:
        monkeypatch.undo()
        client.close()
        os.close(master)
        os.close(slave)
