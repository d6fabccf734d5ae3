"""A head whose pty's other side goes away between the write and the drain (a killed head server):
termios.tcdrain raises termios.error, which is no OSError; it escaped HeadClient.send_frame and ended
the daemon (seen in tests/daemon/test_faults.py fault4).  It is a lost link like any other."""

import os
import termios

import pytest

from gimbal.client import HeadClient

pytestmark = pytest.mark.skipif(not hasattr(os, "openpty"), reason="needs a pty")


def test_a_drain_error_is_a_failed_write_and_a_dropped_port(tmp_path):
    master, slave = os.openpty()
    try:
        c = HeadClient(os.ttyname(slave))
        assert c.connected

        def drain_fails():
            raise termios.error(5, "Input/output error")

        c._ser.flush = drain_fails
        assert c.stop() is False
        assert c.stats.write_failures == 1 and not c.connected
        c.close()
    finally:
        os.close(master), os.close(slave)
