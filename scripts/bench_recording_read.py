"""Reading speed of a recording (the undamaged fast path of :class:`foveatrack.recording.RecordingReader`).

Writes one large recording (default 400 frames of 20 000 points, float64, lz4, one chunk per frame,
with a detection, a command, a head estimate and a metric per frame, as the daemon writes them:
~340 MB) unless it exists, then times once each:

* ``channels()``: every record of the file walked (chunks decompressed and CRC-checked), nothing decoded;
* ``points()``: every lidar frame decoded to arrays;
* ``records('commands')``: one small JSON channel (still reads every chunk).

Usage: python scripts/bench_recording_read.py [FILE.mcap] [--frames N] [--points N]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from foveatrack.recording import RecordingReader, RecordingWriter
from foveatrack.environment import describe  # noqa: E402


def write(path: Path, frames: int, points: int) -> None:
    rng = np.random.default_rng(0)
    with RecordingWriter(path, {"bench": True}) as w:
        for k in range(frames):
            t = 1_000_000_000 + k * 50_000_000
            xyz = rng.normal(0, 30, (points, 3))
            tp = t - 50_000_000 + np.sort(rng.integers(0, 50_000_000, points))
            w.write_points(t, k, xyz, tp, rng.integers(0, 256, points).astype(np.uint8))
            w.write_detection(t, k, True, xyz_m=[12.0, 1.0, 0.5], n_points=40)
            w.write_command(t + 1_000_000, b"\xff\x01\x00\x04\x20\x00\x25", frame_id=k, source="tracker")
            w.write_head_estimate(t, 0.1 * k, 0.0, frame_id=k)
            w.write_metric(t, "processing_ms", 3.0, frame_id=k)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?")
    ap.add_argument("--frames", type=int, default=400)
    ap.add_argument("--points", type=int, default=20_000)
    a = ap.parse_args()
    print(describe(), flush=True)   # versions, CPU and numba target: a figure without them says little
    path = Path(a.file) if a.file else Path(tempfile.gettempdir()) / f"bench_read_{a.frames}x{a.points}.mcap"
    if not path.exists():
        t0 = time.perf_counter()
        write(path, a.frames, a.points)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.2f} s")
    size_mb = os.path.getsize(path) / 1e6
    r = RecordingReader(path)
    t0 = time.perf_counter()
    counts = r.channels()
    t1 = time.perf_counter()
    n = sum(len(f) for f in r.points())
    t2 = time.perf_counter()
    cmds = r.records("commands")
    t3 = time.perf_counter()
    print(f"{path.name}: {size_mb:.1f} MB, {counts.get('points', 0)} frames, {n} points, {len(cmds)} commands")
    print(f"  channels()          {t1 - t0:6.3f} s  ({size_mb / (t1 - t0):7.1f} MB/s)")
    print(f"  points() decoded    {t2 - t1:6.3f} s  ({size_mb / (t2 - t1):7.1f} MB/s)")
    print(f"  records('commands') {t3 - t2:6.3f} s  ({size_mb / (t3 - t2):7.1f} MB/s)")
    print(f"  complete={r.complete} problem={r.problem}")


if __name__ == "__main__":
    main()
