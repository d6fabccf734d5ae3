"""Soak of the real daemon at 480 k points/s (Horizon, dual return, both returns filled) with
recording (issue 26): latency p50 / p99 / max and the daemon's RSS per minute.

The daemon runs as ``foveatrack daemon`` in its own process, exactly as shipped, against a virtual
Horizon (``sim.virtual_lidar.VirtualLivox``, data type 4, IMU at 200 Hz) on loopback and a bare pty
for the head (drained, never answered).  The lidar's returns are one second of a Horizon scene
(a quadrotor at 12 m, ground, a wall 40 m ahead: every beam returns) ray-cast once and streamed in a
loop, each with a second return 0.3 m behind, so the sender costs little next to the daemon.

Latency is the daemon's own ``latency_ms`` (host time of a frame's last point -> command written),
read from its recording, grouped by minute of the run; RSS is sampled from ``/proc/PID/status``
every 5 s (the value at each minute's end; growth per minute from minute 2 on).

    python scripts/bench_daemon_soak.py [--minutes 5] [--no-record] [--out DIR]
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


def cpu_s(pid: int) -> float | None:
    """User + system CPU time the process used so far [s]."""
    try:
        f = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
        return (int(f[11]) + int(f[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=5.0)
    ap.add_argument("--no-record", action="store_true", help="run without a recording")
    ap.add_argument("--out", default=None, help="directory for the config, log and recording (default: a temp dir)")
    args = ap.parse_args()
    from foveatrack.livox import protocol as P
    from foveatrack.recording import RecordingReader
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
    if rec.exists():
        rec.unlink()
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
{"" if args.no_record else f'[recording]{chr(10)}path = "{rec}"{chr(10)}overwrite = true'}
[daemon]
watchdog_s = 2.0
""")
    log = out / "soak.jsonl"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    daemon = subprocess.Popen([sys.executable, "-m", "foveatrack", "daemon", "--config", str(cfg), "--log", str(log)],
                              env=env, stdout=subprocess.DEVNULL, stderr=open(out / "soak.err", "w"), cwd=ROOT)
    lidar.start()
    rss: list[tuple[float, float]] = []
    cpu: list[tuple[float, float]] = []     # (run time, the daemon's CPU time so far) [s]
    loads: list[float] = []
    t0 = None
    try:
        while t0 is None:
            if daemon.poll() is not None:
                raise SystemExit(f"the daemon exited ({daemon.returncode}): {(out / 'soak.err').read_text()}")
            if lidar.sampling:
                t0 = time.monotonic()
            time.sleep(0.05)
        print(f"streaming {2 * RATE_HZ / 1e3:.0f} k points/s for {args.minutes:g} min "
              f"({'no recording' if args.no_record else 'recording ' + str(rec)}) ...", flush=True)
        end = t0 + args.minutes * 60.0
        next_minute = t0 + 60.0
        while time.monotonic() < end:
            time.sleep(5.0)
            now = time.monotonic()
            r = rss_mb(daemon.pid)
            if r is not None:
                rss.append((now - t0, r))
                cpu.append((now - t0, cpu_s(daemon.pid)))
            loads.append(os.getloadavg()[0])
            if now >= next_minute:
                print(f"  minute {int((now - t0) // 60)}: RSS {r:.1f} MB, load {os.getloadavg()[0]:.2f}", flush=True)
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
    # latency by minute of the lidar's stream (its clock starts at 0 with the run): frames are skipped
    # when the daemon falls behind, so frame numbers do not count minutes
    t_s, lat = [], []
    if not args.no_record:
        for m in RecordingReader(rec).messages("metrics"):
            if m.record.get("name") == "latency_ms":
                t_s.append(m.t_ns * 1e-9)
                lat.append(float(m.record["value"]))
    t_s, lat = np.array(t_s), np.array(lat)
    minutes = int(np.ceil(args.minutes))
    print("\n| minute | frames processed (of 600) | latency p50 [ms] | p99 [ms] | max [ms] | RSS at end [MB] | daemon CPU [% of a core] |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for k in range(minutes):
        sel = (t_s >= k * 60.0) & (t_s < (k + 1) * 60.0)
        r_end = [r for t, r in rss if t <= (k + 1) * 60.0]
        row = [f"{k + 1}", f"{int(sel.sum())}"]
        if sel.any():
            x = lat[sel]
            row += [f"{np.percentile(x, 50):.1f}", f"{np.percentile(x, 99):.1f}", f"{x.max():.1f}"]
        else:
            row += ["-", "-", "-"]
        row.append(f"{r_end[-1]:.1f}" if r_end else "-")
        c = [(t, x) for t, x in cpu if k * 60.0 - 5.0 < t <= (k + 1) * 60.0 + 1e-6 and x is not None]
        row.append(f"{100.0 * (c[-1][1] - c[0][1]) / (c[-1][0] - c[0][0]):.0f}" if len(c) >= 2 else "-")
        print("| " + " | ".join(row) + " |")
    after = [(t, r) for t, r in rss if t >= 60.0]
    if len(after) >= 2:
        tt, rr = np.array(after).T
        slope = np.polyfit(tt / 60.0, rr, 1)[0]
        print(f"\nRSS growth from minute 1 on: {slope:+.2f} MB/min (least squares over {len(after)} samples)")
    print(f"load average over the run: mean {np.mean(loads):.2f}, max {np.max(loads):.2f} (1-min, sampled every 5 s)")
    keys = ("frames", "frames_skipped", "frames_stale", "queue_dropped_points", "recording_dropped",
            "lidar_lost_slots", "lidar_duplicate_points", "lidar_clock_jumps", "lidar_imu_packets_unused")
    print("daemon counters: " + ", ".join(f"{k} {stats.get(k, 0)}" for k in keys))
    return 0


if __name__ == "__main__":
    sys.exit(main())
