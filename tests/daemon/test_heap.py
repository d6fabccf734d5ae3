"""Freed frame memory goes back to the system in the daemon's process (:mod:`foveatrack.daemon.heap`):
with glibc's adaptive threshold an 8 MB block freed once makes later large arrays heap memory that
stays in the process; with the daemon's fixed threshold it leaves.  Each case in a fresh interpreter
(the setting is for the whole process)."""

import subprocess
import sys

import pytest

CHILD = r"""
import sys, numpy as np
from foveatrack.daemon.heap import return_freed_memory
def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
if sys.argv[1] == "fixed":
    assert return_freed_memory()
r0 = rss_mb()
kept = []
for i in range(3):
    a = np.ones(1_000_000)       # 8 MB: a backlog's worth
    b = np.ones(150_000)         # 1.2 MB: one 48 k-point frame's x, y, z
    del a, b
    kept.append(rss_mb() - r0)
print(max(kept[1:]))
"""


def _kept_mb(mode: str) -> float:
    out = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return float(out.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_freed_frames_leave_the_process_with_the_fixed_threshold():
    default, fixed = _kept_mb("default"), _kept_mb("fixed")
    print(f"kept after freeing: {default:.1f} MB with glibc's adaptive threshold, {fixed:.1f} MB fixed")
    assert default > 5.0        # what the daemon's RSS did at every backlog (the soak: +31 MB/hour)
    assert fixed < 1.0

