"""Children of the tests that run until told to stop (a daemon, a virtual lidar or head, a writer):
started through :func:`dies_with_this_process`, they end with the test process however it ends."""

from __future__ import annotations

import os
import sys

# A pytest killed before a test's ``finally`` (SIGTERM or SIGKILL: a CI time limit, a developer's
# kill) left such children running: the daemon tests' daemon, lidar and head ray-cast a quarter of
# a core each for an hour under every benchmark of a session.  A child in pytest's own session is
# no safer: only a Ctrl-C at the terminal reaches it.  Each child asks Linux for SIGTERM when the
# process that started it dies (PR_SET_PDEATHSIG, kept across exec; the pid check covers a parent
# gone before the call), then becomes the command itself: Popen's pid is the command's.  The signal
# follows the thread that started the child, and the tests start them on their main thread.
# Elsewhere than Linux the command runs as it is.
_DIE_WITH_PARENT = (
    "import ctypes, os, signal, sys\n"
    "if sys.platform.startswith('linux'):\n"
    "    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)\n"   # 1: PR_SET_PDEATHSIG
    "    if os.getppid() != int(sys.argv[1]):\n"
    "        sys.exit(0)\n"
    "os.execv(sys.executable, [sys.executable, *sys.argv[2:]])\n")


def dies_with_this_process(argv: list[str]) -> list[str]:
    """``argv`` (a Python command: ``[sys.executable, ...]``) run so that it gets SIGTERM when this
    process dies (module comment above)."""
    assert argv[0] == sys.executable, argv
    return [sys.executable, "-c", _DIE_WITH_PARENT, str(os.getpid()), *argv[1:]]
