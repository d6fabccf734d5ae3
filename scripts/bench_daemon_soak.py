"""Soak of the real daemon at 480 k points/s (Horizon, dual return, both returns filled) with
recording (issue 26): latency p50 / p99 / max and the RSS of the daemon and of its recording writer
(a child process) per minute, and the RSS slopes after the warm-up.

The daemon runs as ``foveatrack daemon`` in its own process, exactly as shipped, against a virtual
Horizon (``sim.virtual_lidar.VirtualLivox``, data type 4, IMU at 200 Hz) on loopback and a bare pty
for the head (drained, never answered).  The lidar's returns are one second of a Horizon scene
(a quadrotor at 12 m, ground, a wall 40 m ahead: every beam returns) ray-cast once and streamed in a
loop, each with a second return 0.3 m behind, so the sender costs little next to the daemon.

Latency is the daemon's own ``latency_ms`` (host time of a frame's last point -> command written),
read from its recording, grouped by minute of the run, each minute's p99 also as a change from the
first minute's; RSS is sampled from ``/proc/PID/status`` every 5 s for the daemon and for each of its
child processes (the recording writer: ``foveatrack.recording.writer_process``); the table gives the
value at each minute's end.  The slopes are least-squares fits over the samples after
``--warmup-min`` (default 5) minutes, in MB/hour (the must-show of issue 26: under 1 MB/hour).

The recording is split into segments (``[recording] segment_minutes``, default here 5): the MCAP
writer keeps ~250 B per chunk (one chunk a frame) until its file closes.

    python scripts/bench_daemon_soak.py [--minutes 5] [--warmup-min 5] [--no-record] [--segment-minutes M] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from bench_daemon_frame import SCENE  # noqa: E402
from foveatrack.environment import describe  # noqa: E402

RATE_HZ = 240_000.0          # Horizon slots/s; two returns each: 480 k points/s
PERIOD_NS = 1_000_000_000    # the ray-cast second that is looped


def looped_source():
    """A VirtualLivox source: the returns of one ray-cast second of the scene, repeated, each slot
    with a second return 0.3 m behind its first (``[firsts; seconds]``: the first is rank 0)."""
    from sim.lidar_server import SceneSource
    from sim.scene import scene_from_mapping

    src = SceneSource(scene_from_mapping(SCENE))
    xyz, refl, t = src(0, PERIOD_NS)
    order = np.argsort(t, kind="stable")
    xyz, refl, t = np.asarray(xyz)[order], np.asarray(refl)[order], np.asarray(t, np.int64)[order]
    rng = np.linalg.norm(xyz, axis=1, keepdims=True)
    xyz2 = xyz * (1 + 0.3 / np.maximum(rng, 1e-9))

    def source(t0_ns: int, t1_ns: int):
        parts = []
        for k in range(t0_ns // PERIOD_NS, (t1_ns - 1) // PERIOD_NS + 1):
            a, b = np.searchsorted(t, [t0_ns - k * PERIOD_NS, t1_ns - k * PERIOD_NS])
            parts.append((a, b, k * PERIOD_NS))
        i = np.concatenate([np.arange(a, b) for a, b, _ in parts])
        tt = np.concatenate([t[a:b] + off for a, b, off in parts])
        return (np.concatenate([xyz[i], xyz2[i]]), np.concatenate([refl[i], refl[i]]), np.concatenate([tt, tt]))

    return source, int(t.size)


def rss_mb(pid: int) -> float | None:
    try:
        for line in open(f"/proc/{pid}/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def child_pids(pid: int) -> list[int]:
    """The direct children of ``pid`` (all its threads'), from /proc."""
    out = set()
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            try:
                out.update(int(x) for x in open(f"/proc/{pid}/task/{task}/children").read().split())
            except OSError:
                pass
    except OSError:
        pass
    return sorted(out)


def slope_mb_h(samples: list[tuple[float, float]], after_s: float) -> tuple[float, int] | None:
    """Least-squares RSS slope [MB/hour] of the ``(run time [s], RSS [MB])`` samples after ``after_s``."""
    pts = [(t, r) for t, r in samples if t >= after_s]
    if len(pts) < 3:
        return None
    tt, rr = np.array(pts).T
    return float(np.polyfit(tt / 3600.0, rr, 1)[0]), len(pts)


def cpu_s(pid: int) -> tuple[float, float, int] | None:
    """(user + system CPU time [s], system CPU time [s], minor page faults) of the process so far: a
    page re-faulted after memory went back to the system costs system time, not user time."""
    try:
        f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        tick = os.sysconf("SC_CLK_TCK")
        return (int(f[11]) + int(f[12])) / tick, int(f[12]) / tick, int(f[7])
    except (OSError, IndexError, ValueError):
        return None


def cpu_jiffies() -> tuple[int, int] | None:
    """(steal, all) of the machine's CPU time so far [clock ticks], from /proc/stat: the share the
    hypervisor gave to other guests, which slows every process here without showing in the load."""
    try:
        f = [int(x) for x in open("/proc/stat").readline().split()[1:]]
        return f[7], sum(f[:8])
    except (OSError, IndexError, ValueError):
        return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=5.0)
    ap.add_argument("--warmup-min", type=float, default=5.0,
                    help="the RSS slopes are fitted after this many minutes (default 5)")
    ap.add_argument("--no-record", action="store_true", help="run without a recording")
    ap.add_argument("--segment-minutes", type=float, default=5.0,
                    help="[recording] segment_minutes: a new file every this many minutes (default 5; 0: one "
                         "file for the run, whose MCAP chunk index grows ~10 MB an hour until it closes)")
    ap.add_argument("--out", default=None, help="directory for the config, log and recording (default: a temp dir)")
    args = ap.parse_args()
    from sim.livox_units import HORIZON
    from sim.virtual_lidar import VirtualLivox

    out = Path(args.out or tempfile.mkdtemp(prefix="soak-"))
    out.mkdir(parents=True, exist_ok=True)
    print(describe(), flush=True)
    print("ray-casting one second of the scene ...", flush=True)
    source, n_slots = looped_source()
    master, slave = os.openpty()
    link = out / "head"
    if link.is_symlink():
        link.unlink()
    os.symlink(os.ttyname(slave), link)
    stop = threading.Event()

    def drain():
        while not stop.is_set():
            try:
                os.read(master, 4096)
            except OSError:
                time.sleep(0.01)

    threading.Thread(target=drain, daemon=True).start()
    lidar = VirtualLivox(source, cmd_port=0, broadcast_addr=("127.0.0.1", 0), point_rate_hz=RATE_HZ,
                         packet_type=4, unit=HORIZON)
    # discovery: the daemon listens on a broadcast port we choose; the lidar broadcasts to it
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    bport = s.getsockname()[1]
    s.close()
    lidar.broadcast_addr = ("127.0.0.1", bport)
    rec = out / "soak.mcap"
    from foveatrack.recording.segments import following_segments, open_run

    for p in [rec, *following_segments(rec)]:     # a run before this one in the same directory
        p.unlink(missing_ok=True)
    seg = f"{chr(10)}segment_minutes = {args.segment_minutes}" if args.segment_minutes > 0 else ""
    cfg = out / "soak.toml"
    cfg.write_text(f"""
[lidar]
sensor_ip = "127.0.0.1"
host_ip = "127.0.0.1"
cmd_port = 0
data_port = 0
broadcast_port = {bport}
[head]
port = "{link}"
[tracker]
deadband_deg = 2.0
gain_1_s = 2.0
[tracker.space]
kind = "box"
frame = "world"
min_xyz = [1.0, -60.0, -0.7]
max_xyz = [30.0, 60.0, 40.0]
{"" if args.no_record else f'[recording]{chr(10)}path = "{rec}"{chr(10)}overwrite = true{seg}'}
[daemon]
watchdog_s = 2.0
""")
    log = out / "soak.jsonl"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    daemon = subprocess.Popen([sys.executable, "-m", "foveatrack", "daemon", "--config", str(cfg), "--log", str(log)],
                              env=env, stdout=subprocess.DEVNULL, stderr=open(out / "soak.err", "w"), cwd=ROOT)
    lidar.start()
    rss: list[tuple[float, float]] = []
    writer_rss: list[tuple[float, float]] = []   # the sum over the daemon's children (the writer)
    load_at: list[tuple[float, float]] = []
    cpu: list[tuple[float, tuple | None]] = []     # (run time, cpu_s(daemon)): CPU time, system time, faults
    steal: list[tuple[float, tuple[int, int] | None]] = []     # (run time, cpu_jiffies())
    loads: list[float] = []
    t0 = None
    # SIGTERM as Ctrl-C: the daemon is stopped and the minutes so far reported (a bare SIGTERM ended
    # this script at once and left the daemon running, orphaned)
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    try:
        while t0 is None:
            if daemon.poll() is not None:
                raise SystemExit(f"the daemon exited ({daemon.returncode}): {(out / 'soak.err').read_text()}")
            if lidar.sampling:
                t0 = time.monotonic()
            time.sleep(0.05)
        print(f"streaming {2 * RATE_HZ / 1e3:.0f} k points/s for {args.minutes:g} min "
              f"({'no recording' if args.no_record else 'recording ' + str(rec)}"
              f"{f', a new segment every {args.segment_minutes:g} min' if seg and not args.no_record else ''}) ...",
              flush=True)
        end = t0 + args.minutes * 60.0
        next_minute = t0 + 60.0
        while time.monotonic() < end:
            try:
                time.sleep(5.0)
            except KeyboardInterrupt:
                args.minutes = (time.monotonic() - t0) / 60.0
                print(f"interrupted after {args.minutes:.1f} min: the minutes so far", flush=True)
                break
            now = time.monotonic()
            r = rss_mb(daemon.pid)
            if r is not None:
                rss.append((now - t0, r))
                cpu.append((now - t0, cpu_s(daemon.pid)))
            kids = [x for x in (rss_mb(c) for c in child_pids(daemon.pid)) if x is not None]
            if kids:
                writer_rss.append((now - t0, sum(kids)))
            loads.append(os.getloadavg()[0])
            load_at.append((now - t0, loads[-1]))
            steal.append((now - t0, cpu_jiffies()))
            if now >= next_minute:
                w = f", writer RSS {writer_rss[-1][1]:.1f} MB" if kids else ""
                print(f"  minute {int((now - t0) // 60)}: daemon RSS {r:.1f} MB{w}, load {loads[-1]:.2f}", flush=True)
                next_minute += 60.0
            if daemon.poll() is not None:
                raise SystemExit(f"the daemon exited ({daemon.returncode}): {(out / 'soak.err').read_text()}")
    finally:
        daemon.send_signal(signal.SIGTERM)
        try:
            daemon.wait(60)
        except subprocess.TimeoutExpired:
            daemon.kill()
        lidar.stop()
        stop.set()
        os.close(master), os.close(slave)
    print(f"lidar sent {lidar.counters['packets_sent']} packets, {lidar.counters['points_sent']} points; "
          f"{n_slots} slots ray-cast once", flush=True)
    import json

    stats = next((json.loads(x)["stats"] for x in log.read_text().splitlines() if '"event": "stop"' in x), {})
    # latency by minute of the lidar's stream, from the first frame processed (the lidar's clock starts
    # when it does, before the daemon is ready when its kernels compile): frames are skipped when the
    # daemon falls behind, so frame numbers do not count minutes
    t_s, lat = [], []
    if not args.no_record:
        for m in open_run(rec).messages("metrics"):       # every segment, in order
            if m.record.get("name") == "latency_ms":
                t_s.append(m.t_ns * 1e-9)
                lat.append(float(m.record["value"]))
    t_s, lat = np.array(t_s), np.array(lat)
    if t_s.size:
        t_s = t_s - t_s.min()
    minutes = int(np.ceil(args.minutes))
    print("\n| minute | frames processed (of 600) | latency p50 [ms] | p99 [ms] | p99 vs minute 1 | max [ms] "
          "| daemon RSS [MB] | writer RSS [MB] | daemon CPU [% of a core] | of which system [%] "
          "| daemon minor faults [k/min] | load (1-min avg) | host steal [%] |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    p99_first = None
    over = []
    for k in range(minutes):
        sel = (t_s >= k * 60.0) & (t_s < (k + 1) * 60.0)
        row = [f"{k + 1}", f"{int(sel.sum())}"]
        if sel.any():
            x = lat[sel]
            p99 = float(np.percentile(x, 99))
            p99_first = p99 if p99_first is None else p99_first
            change = 100.0 * (p99 / p99_first - 1.0)
            if abs(change) > 20.0:
                over.append(k + 1)
            row += [f"{np.percentile(x, 50):.1f}", f"{p99:.1f}", f"{change:+.0f} %", f"{x.max():.1f}"]
        else:
            row += ["-", "-", "-", "-"]
        for series in (rss, writer_rss):
            r_end = [r for t, r in series if t <= (k + 1) * 60.0]
            row.append(f"{r_end[-1]:.1f}" if r_end else "-")
        def over_minute(series):    # the minute's samples and the one before it: its rate of change
            return [(t, x) for t, x in series if k * 60.0 - 5.0 < t <= (k + 1) * 60.0 + 1e-6 and x is not None]

        c = over_minute(cpu)
        if len(c) >= 2:
            span = c[-1][0] - c[0][0]
            row += [f"{100.0 * (c[-1][1][0] - c[0][1][0]) / span:.0f}",
                    f"{100.0 * (c[-1][1][1] - c[0][1][1]) / span:.0f}",
                    f"{60.0 * (c[-1][1][2] - c[0][1][2]) / span / 1e3:.1f}"]
        else:
            row += ["-", "-", "-"]
        ld = [x for t, x in load_at if k * 60.0 < t <= (k + 1) * 60.0 + 1e-6]
        row.append(f"{np.mean(ld):.2f}" if ld else "-")
        st = [x for _, x in over_minute(steal)]
        row.append(f"{100.0 * (st[-1][0] - st[0][0]) / max(st[-1][1] - st[0][1], 1):.1f}" if len(st) >= 2 else "-")
        print("| " + " | ".join(row) + " |")
    if p99_first is not None:
        print(f"\nlatency p99 within 20 % of minute 1's ({p99_first:.1f} ms): "
              + ("every minute" if not over else f"NOT in minute(s) {', '.join(map(str, over))}"))
    after_s = args.warmup_min * 60.0
    print(f"RSS slope after minute {args.warmup_min:g} (least squares over the 5 s samples; the must-show: "
          "under 1 MB/hour):")
    total = [(t, r + w) for (t, r), (t2, w) in zip(rss, writer_rss) if abs(t - t2) < 1.0] if writer_rss else []
    for name, series in (("daemon", rss), ("writer", writer_rss), ("daemon + writer", total)):
        fit = slope_mb_h(series, after_s)
        print(f"  {name:16s} " + ("- (too few samples)" if fit is None else
                                  f"{fit[0]:+.2f} MB/hour ({fit[0] / 60.0:+.4f} MB/min, {fit[1]} samples)"))
    print(f"load average over the run: mean {np.mean(loads):.2f}, max {np.max(loads):.2f} (1-min, sampled every 5 s)")
    keys = ("frames", "frames_skipped", "frames_stale", "queue_dropped_points", "recording_dropped",
            "lidar_lost_slots", "lidar_duplicate_points", "lidar_clock_jumps", "lidar_imu_packets_unused",
            "heap_trims", "heap_trim_ms")
    print("daemon counters: " + ", ".join(f"{k} {stats.get(k, 0)}" for k in keys))
    return 0


if __name__ == "__main__":
    sys.exit(main())
