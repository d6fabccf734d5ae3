"""The tests' long-running children die with the pytest that started them (child_procs.dies_with_this_process,
used by the daemon, gimbal, livox and recording tests).

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
from pathlib import Path

import pytest

from daemon_procs import HERE, ROOT, env, wait_for

PARENT = """
import sys
from pathlib import Path
sys.path[:0] = [{here!r}, {tests!r}]
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
    parent = subprocess.Popen([sys.executable, "-c", PARENT.format(here=str(HERE), tests=str(HERE.parent)), str(tmp_path)], cwd=ROOT, env=env(),
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


def test_every_child_the_tests_start_goes_through_the_wrapper():
    # A child started with a bare Popen outlives a killed pytest; the stand-in above is the one
    # exception (it is the process killed, and its stdin's end stops it).
    import ast

    bare = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "Popen"
                    and not (node.args and isinstance(node.args[0], ast.Call)
                             and getattr(node.args[0].func, "id", None) == "dies_with_this_process")):
                bare.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    me = Path(__file__)
    stand_in = next(i for i, ln in enumerate(me.read_text().splitlines(), 1)
                    if ln.startswith("    parent = subprocess.Popen("))
    assert bare == [f"tests/daemon/{me.name}:{stand_in}"], bare
