"""Memory a recording writer keeps per MCAP chunk (issue 26: the daemon's RSS grew for hours).

Writes small frames (50 points, two metrics, one command) with :class:`RecordingWriter` as the daemon
does (a chunk per frame: ``flush_every_frames = 1``) in one file and in segments of 3000 frames
(``[recording] segment_minutes = 5``), then with a chunk every 10 frames, and without a file (the live
view's writer), and prints the RSS growth per frame after a warm-up.  The growth per
chunk is native memory of the Foxglove SDK's MCAP writer (Python's own allocations do not grow:
tracemalloc), kept until the file is closed for the summary it writes then; at the daemon's 10 frames
a second it is ~10 MB an hour.

    python scripts/bench_recording_memory.py [--frames 30000]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import sys, numpy as np
sys.path.insert(0, sys.argv[1])
from foveatrack.recording import RecordingWriter
from foveatrack.recording.segments import segment_path
def rss_mb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
path = None if sys.argv[2] == "-" else sys.argv[2]
w = RecordingWriter(path, {}, overwrite=True, flush_every_frames=int(sys.argv[3]))
xyz = np.random.default_rng(0).normal(0, 10, (50, 3))
tn = np.arange(50, dtype=np.int64)
seg = int(sys.argv[5])
def frame(k):
    t = k * 100_000_000
    if seg and k and k % seg == 0:
        w.next_segment(segment_path(path, k // seg))
    w.write_points(t, k, xyz, t + tn)
    w.write_metric(t, "processing_ms", 1.0, frame_id=k)
    w.write_metric(t, "latency_ms", 2.0, frame_id=k)
    w.write("commands", t, {"raw_hex": "ff01000000", "frame_id": k})
for k in range(2000):
    frame(k)
r0 = rss_mb()
n = int(sys.argv[4])
for k in range(2000, 2000 + n):
    frame(k)
print((rss_mb() - r0) * 1e6 / n)
w.close()
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=30_000)
    args = ap.parse_args()
    out = Path(tempfile.mkdtemp(prefix="recmem-")) / "m.mcap"
    print(f"{args.frames} frames after 2000 of warm-up, each case in a fresh process; load "
          f"{os.getloadavg()[0]:.2f}")
    print("\n| writer | RSS growth [bytes/frame] | at 10 frames/s [MB/hour] |\n|---|---:|---:|")
    for name, path, every, seg in (("file, a chunk per frame, one file", str(out), 1, 0),
                                   ("file, a chunk per frame, a new segment every 3000 frames (5 min; the "
                                    "daemon's segment_minutes)", str(out), 1, 3000),
                                   ("file, a chunk every 10 frames", str(out), 10, 0),
                                   ("no file (live view only)", "-", 1, 0)):
        r = subprocess.run([sys.executable, "-c", CHILD, str(ROOT), path, str(every), str(args.frames), str(seg)],
                           capture_output=True, text=True, check=True)
        b = float(r.stdout.split()[-1])
        print(f"| {name} | {b:.0f} | {b * 36000 / 1e6:.2f} |")
    for p in out.parent.iterdir():
        p.unlink()
    return 0


if __name__ == "__main__":
    sys.exit(main())
