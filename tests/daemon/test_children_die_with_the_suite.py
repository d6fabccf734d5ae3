"""The daemon tests' processes die with the pytest that started them (daemon_procs.dies_with_this_process).

A pytest killed in the middle of a test (a CI time limit, a developer's kill: SIGTERM or SIGKILL, no
``finally`` runs) left the test's daemon, lidar and head running in their own sessions for as long as
the machine ran.  Here a stand-in for pytest starts ``foveatrack gimbal serve`` as the tests do
(daemon_procs.start) and is killed with SIGKILL: the head must be gone within seconds."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from daemon_procs import HERE, ROOT, env, wait_for

PARENT = """
import sys
from pathlib import Path
sys.path.insert(0, {here!r})
from daemon_procs import start
d = Path(sys.argv[1])
p = start(["gimbal", "serve", "--link", str(d / "head")], d / "head.out", d / "head.err")
print(p.pid, flush=True)
sys.stdin.read()        # until killed
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie is gone for this purpose (it runs nothing; its parent, init, reaps it)
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_a_daemon_tests_child_dies_when_pytest_is_killed(tmp_path):
    parent = subprocess.Popen([sys.executable, "-c", PARENT.format(here=str(HERE)), str(tmp_path)], cwd=ROOT, env=env(),
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
        # the head is up: its pty's path is its first line
        wait_for(lambda: (tmp_path / "head.out").exists() and (tmp_path / "head.out").read_text().strip(), 30,
                 "the head's pty", [parent])
        assert _alive(child)
        with open(f"/proc/{child}/cmdline", "rb") as f:      # the command itself, not a wrapper around it
            assert f.read().split(b"\0")[1:5] == [b"-m", b"foveatrack", b"gimbal", b"serve"]
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
        end = time.monotonic() + 15
        while _alive(child) and time.monotonic() < end:
            time.sleep(0.05)
        assert not _alive(child), "the head outlived the process that started it"
    finally:
        if parent.poll() is None:
            parent.kill()
        try:
            os.kill(child, signal.SIGKILL)
        except (ProcessLookupError, NameError, UnboundLocalError):
            pass
