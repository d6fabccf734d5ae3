"""Recording cost on the thread that writes: one 10 k-point frame (points on the Livox mm grid as the
simulator and a Livox's Cartesian output give them, per-point times at 100 k points/s, reflectivity)
with its detection, head estimate, command and truth records, then the chunk flush
(``flush_every_frames = 1``, as ``simulate --out`` and the daemon write).

    python scripts/bench_recording_write.py [--points 10000] [--frames 200] [--old PATH_TO_OLD_WRITER_PY]
            [--scene scenes/fig12-tracking.toml] [--gyro] [--levels]

``--gyro`` runs the scene's variant with the lidar's IMU on the head and ``attitude = "gyro"``, whose
gyro samples are recorded too (``/imu``).

Prints the calling thread's CPU time per frame [ms] (with the writer process,
:mod:`foveatrack.recording.writer_process`, the encoding and writing run in a child: what is left
is the hand-over) and bytes per frame.  ``--old`` times a format-1 writer
module (e.g. ``git show d76062b:foveatrack/recording/writer.py > /tmp/old_writer.py``) for the
before/after figures of docs/recordings.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from foveatrack.livox.protocol import quantise_to_mm_grid
from foveatrack.recording import RecordingWriter
from foveatrack.recording.writer_process import RecordingProcess
from foveatrack.recording.records import CommandRecord, DetectionRecord, HeadEstimateRecord, TruthRecord, write_record


def writer_process(path, meta, **kw) -> RecordingProcess:
    """A writer process, started and ready before the clock starts (``simulate`` starts it before its
    own set-up), opened on ``path``."""
    w = RecordingProcess()
    w.wait_ready()
    return w.open(path, meta, **kw)


def run(writer_cls, n_points: int, n_frames: int, path: Path, off_grid: bool = False, imu: bool = False,
        **kw) -> tuple[np.ndarray, int]:
    rng = np.random.default_rng(1)
    # lidar-like points: 5-130 m along a narrow cone, on the mm grid (off_grid: full float64 mantissas)
    r = rng.uniform(5, 130, n_points)
    xyz = np.stack([r, rng.normal(0, 0.1, n_points) * r, rng.normal(0, 0.1, n_points) * r], axis=1)
    refl = rng.integers(0, 256, n_points).astype(np.uint8)
    t_imu = np.arange(20) / 200.0 + 0.9
    gyro = rng.normal(0, 0.01, (50, 20, 3))
    cpu = []
    with writer_cls(path, {"seed": 1}, overwrite=True, **kw) as w:
        for k in range(n_frames):
            t = 1_000_000_000 + k * 100_000_000
            tp = t - 100_000_000 + np.arange(n_points, dtype=np.int64) * (100_000_000 // n_points)
            pts = xyz + rng.normal(0, 0.02, xyz.shape)
            if not off_grid:
                pts = quantise_to_mm_grid(pts)
            c0 = time.thread_time()
            w.write_points(t, k, pts, tp, refl)
            write_record(w, DetectionRecord(t, k, True, (12.0, 0.1, 0.2), 40, t * 1e-9, 0.5, 0.9, "tracking", 0.1, 0.2))
            write_record(w, HeadEstimateRecord(t, k, 0.1 * k, 1.0, 0.01, 0.01, (12.0, 0.2, 1.0), 0.05))
            write_record(w, CommandRecord(t + 5_000_000, b"\xff\x01\x00\x04\x20\x00\x25", 1, 32, 0, 0, frame_id=k))
            write_record(w, TruthRecord(t, k, 0.1 * k, 1.0, (12.0, 0.2, 1.0), 0.3, 40))
            if imu:     # a 200 Hz gyro's 20 samples of the frame (as attitude = "gyro" records them)
                w.write_imu(t, k, t_imu + k * 0.1, gyro[k % 50])
            w.flush()
            cpu.append(time.thread_time() - c0)
    return np.asarray(cpu) * 1e3, path.stat().st_size


def load(scene_path: str, gyro: bool = False):
    """The scene, or with ``gyro`` its variant with the lidar's IMU on the head and ``[tracker]
    attitude = "gyro"`` (sim.attitude_study.scene_variant: 200 Hz, ~20 samples a frame)."""
    from sim.attitude_study import scene_variant
    from sim.scene import load_scene

    return scene_variant(scene_path, "gyro") if gyro else load_scene(scene_path)


def closed_loop(scene_path: str, in_process: bool, old=None, gyro: bool = False,
                **wkw) -> tuple[float, float, float, int]:
    """fig12 as ``simulate --out`` runs it: (frame hook CPU ms per frame on the loop's thread, wall s of
    the run without recording, wall s with it, file bytes)."""
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta

    scene = load(scene_path, gyro)
    ClosedLoop(scene).run()                       # warm: numba cache, first calls
    t = time.perf_counter()
    ClosedLoop(scene).run()
    wall_plain = time.perf_counter() - t
    cls = RecordingWriter if old is None else old
    if in_process:      # started and ready before the clock starts, as simulate's set-up covers its start
        child = RecordingProcess()
        child.wait_ready()
        cls = child.open
    kw = dict(wkw)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "run.mcap"
        hook_s = []
        t = time.perf_counter()
        loop = ClosedLoop(scene)
        with cls(path, recording_meta(scene, loop), overwrite=True, **kw) as w:
            rec = SimRecorder(w)

            def hook(frame, out, lp):
                c = time.thread_time()
                rec(frame, out, lp)
                hook_s.append(time.thread_time() - c)
            loop.frame_hook = hook
            loop.run()
        wall_rec = time.perf_counter() - t
        return float(np.mean(hook_s[1:]) * 1e3), wall_plain, wall_rec, path.stat().st_size


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--old", help="a format-1 writer module to time beside the current one")
    ap.add_argument("--scene", help="also run this scene's closed loop (e.g. scenes/fig12-tracking.toml) without "
                                    "and with recording")
    ap.add_argument("--gyro", action="store_true", help="with --scene: its variant with the lidar's IMU on the "
                                                        "head and attitude = \"gyro\" (the gyro samples recorded)")
    ap.add_argument("--levels", action="store_true", help="with --scene: the compressions and levels on the "
                                                          "loop's thread (size and CPU of each)")
    a = ap.parse_args()
    cases = [("format 4, zstd 1 (default)", RecordingWriter, {}),
             ("format 4, zstd 3", RecordingWriter, {"compression_level": 3}),
             ("format 4, lz4", RecordingWriter, {"compression": "lz4"}),
             ("format 4, none", RecordingWriter, {"compression": "none"}),
             ("format 4, zstd 1, points off the mm grid (float64)", RecordingWriter, {"off_grid": True}),
             ("format 4, zstd 1, from a writer process", writer_process, {}),
             ("format 4, zstd 1, + 20 IMU samples a frame", RecordingWriter, {"imu": True}),
             ("format 4, zstd 1, + 20 IMU samples, writer process", writer_process, {"imu": True})]
    if a.old:
        spec = importlib.util.spec_from_file_location("old_writer", a.old)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        cases.insert(0, ("python mcap writer (format 1, JSON + base64, lz4)", mod.RecordingWriter, {}))
    print(f"{a.frames} frames of {a.points} points, CPU ms per frame on the writing thread (os.cpu_count() = "
          f"{os.cpu_count()}):")
    old_cls = cases[0][1] if a.old else None
    with tempfile.TemporaryDirectory() as d:
        for name, cls, kw in cases:
            ms, size = run(cls, a.points, a.frames, Path(d) / "r.mcap", **kw)
            ms = ms[5:]     # first frames: imports, schemas
            print(f"  {name:52s} p50 {np.percentile(ms, 50):6.3f}  p95 {np.percentile(ms, 95):6.3f}  "
                  f"mean {ms.mean():6.3f} ms; {size / a.frames / 1e3:7.1f} kB per frame")
    if a.scene:
        scene_report(a.scene, old_cls, a.levels, a.gyro)


def scene_report(scene: str, old_cls, levels: bool = False, gyro: bool = False) -> None:
    runs = [("format 4, zstd 1, on the loop's thread (--one-thread)", False, None, {}),
            ("format 4, zstd 1, from a writer process (simulate --out)", True, None, {})]
    if levels:
        runs += [(f"format 3, {c} {lv}, on the loop's thread", False, None, {"compression": c, "compression_level": lv})
                 for c, lv in (("lz4", 0), ("zstd", 2), ("zstd", 3), ("zstd", 4), ("zstd", 6))]
        runs.append(("format 4, none, on the loop's thread", False, None, {"compression": "none"}))
    if old_cls is not None:
        runs.insert(0, ("python mcap writer (format 1, lz4)", False, old_cls, {}))
    print(f"{scene}{' (gyro variant)' if gyro else ''}: closed loop without / with the recording")
    for name, in_process, cls, wkw in runs:
        hook_ms, plain, rec, size = closed_loop(scene, in_process, cls, gyro, **wkw)
        print(f"  {name:56s} hook {hook_ms:6.3f} ms/frame on the loop's thread; wall {plain:5.2f} s -> "
              f"{rec:5.2f} s with it; {size / 1e6:6.2f} MB")


if __name__ == "__main__":
    main()
