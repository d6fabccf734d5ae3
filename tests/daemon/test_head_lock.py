"""One head, one driver (issue 26): a second daemon with its own lidar ports but the same ``[head]
port`` started and wrote a STOP every second into the head the first one drove.  The port is now
locked (flock, pyserial's ``exclusive``): the second is refused with an error naming the port, and
writes nothing."""

import json
import os

import pytest

from daemon_procs import event, free_udp_port, log_events, start, wait_for, write_config
from foveatrack.errors import UserError

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")


def _pty_head(tmp_path):
    master, slave = os.openpty()
    os.set_blocking(master, False)
    link = tmp_path / "head"
    os.symlink(os.ttyname(slave), link)
    return master, slave, link


def _read(master) -> bytes:
    got = bytearray()
    try:
        while True:
            got.extend(os.read(master, 4096))
    except (BlockingIOError, OSError):
        pass
    return bytes(got)


def test_a_second_client_of_a_locked_port_is_refused_naming_it(tmp_path):
    from gimbal.client import HeadClient

    master, slave, link = _pty_head(tmp_path)
    try:
        a = HeadClient(str(link))
        b = HeadClient(str(link))
        assert a.connected and not b.connected
        assert b.stats.open_locked == 1 and "in use by another process" in b.last_open_error
        assert str(link) in b.last_open_error
        b.reconnect_interval_s = 0.0
        assert not b.stop()                         # each try to write is a try to open: refused again
        assert b.stats.open_locked == 2 and _read(master) == b""
        a.close()                                   # released: the next one may drive it
        c = HeadClient(str(link))
        assert c.connected
        c.close()
        b.close()
    finally:
        os.close(master), os.close(slave)


def test_a_second_daemon_on_the_same_head_port_is_refused_and_writes_nothing(tmp_path):
    master, slave, link = _pty_head(tmp_path)
    cfg1 = write_config(tmp_path / "d1.toml", link, tmp_path / "rec1.mcap", free_udp_port())
    cfg2 = write_config(tmp_path / "d2.toml", link, tmp_path / "rec2.mcap", free_udp_port())
    log1, log2 = tmp_path / "d1.jsonl", tmp_path / "d2.jsonl"
    got = bytearray()
    d1 = start(["daemon", "--config", str(cfg1), "--log", str(log1)], tmp_path / "d1.out", tmp_path / "d1.err")
    d2 = None
    try:
        wait_for(lambda: event(log1, "start"), 60, "the first daemon to start", [d1])
        d2 = start(["daemon", "--config", str(cfg2), "--log", str(log2)], tmp_path / "d2.out", tmp_path / "d2.err")
        rc2 = d2.wait(60)
        # the first daemon goes on (STOP every second: no lidar) for 2 progress events more
        n = len([e for e in log_events(log1) if e["event"] == "progress"])
        wait_for(lambda: (got.extend(_read(master)),
                          len([e for e in log_events(log1) if e["event"] == "progress"]) >= n + 2)[1],
                 60, "the first daemon's progress", [d1])
        d1.kill()
        d1.wait(10)
        got.extend(_read(master))
    finally:
        for p in (d1, d2):
            if p is not None and p.poll() is None:
                p.kill()
        os.close(master), os.close(slave)
    err2 = (tmp_path / "d2.err").read_text()
    assert rc2 != 0 and "in use by another process" in err2 and str(link) in err2 and str(cfg2) in err2, err2
    assert event(log2, "start") is None and not (tmp_path / "rec2.mcap").exists()
    # every byte on the head's line is the first daemon's (its journal): none from the second
    journal = [json.loads(x) for x in (tmp_path / "rec1.mcap.commands.jsonl").read_text().splitlines()]
    sent = b"".join(bytes.fromhex(j["raw_hex"]) for j in journal)
    assert len(got) >= 14 and sent[:len(got)] == bytes(got), (len(sent), len(got))


def test_open_head_refuses_a_locked_port_with_a_one_line_error(tmp_path):
    from foveatrack.daemon import load_config
    from foveatrack.live_devices import open_head

    master, slave, link = _pty_head(tmp_path)
    cfg = write_config(tmp_path / "d.toml", link, tmp_path / "rec.mcap", free_udp_port())
    try:
        first = open_head(load_config(cfg))
        with pytest.raises(UserError) as e:
            open_head(load_config(cfg))
        msg = str(e.value)
        assert "\n" not in msg and str(cfg) in msg and "[head]" in msg and str(link) in msg
        assert "in use by another process" in msg
        first.close()
    finally:
        os.close(master), os.close(slave)
