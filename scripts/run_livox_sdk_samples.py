"""Run the vendor's Livox SDK v1 samples against ``foveatrack lidar serve`` and print what they print.

    python scripts/run_livox_sdk_samples.py --sdk-bin DIR [--scene SCENE.toml] [--capture DIR]

``DIR`` holds the samples ``lidar_sample`` and ``lidar_lvx_sample`` of a Livox-SDK 2.3.0 you built
yourself, outside this tree, per its own README (this project ships none of its code, nor a recipe);
``LIVOX_SDK_BIN`` may name it instead.  Without them the script says so and exits 0 (CI has no SDK).

For each sample: start ``foveatrack lidar serve SCENE --log-control``, run the sample, stop the
serve, then print the sample's own lines (the SDK's log lines dropped, ``--verbose`` keeps them), the
serve's counters and the figures: packets and returns the unit sent against what the sample
received.  ``lidar_sample`` prints ``data_type T packet num N`` every 100 packets; a build of it
that prints ``COUNT data_type T packets N data_num M returns R`` at exit (a local counting patch)
gives exact counts.  ``LIVOX_RUN_S`` is passed on (that patch reads it as its run time; the stock
sample always runs 30 s).  ``lidar_lvx_sample -t 2`` runs in a temporary directory; the .lvx it
writes is then read by ``foveatrack replay``.

``--capture DIR`` keeps the serve's control logs (``sdk-<sample>-<preset>.jsonl``): the fixtures of
tests/livox/fixtures were made so.  Everything stays on 127.0.0.1 (the SDK sends commands to port
65000 of the address the broadcast came from; the serve binds 127.0.0.1:65000).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOVEATRACK = [sys.executable, "-m", "foveatrack"]


def start_serve(scene: Path, log: Path, duration_s: float) -> subprocess.Popen:
    p = subprocess.Popen(FOVEATRACK + ["lidar", "serve", str(scene), "--log-control", str(log),
                                       "--duration-s", str(duration_s)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    line = p.stdout.readline()
    if not line.startswith("READY"):
        p.kill()
        sys.exit(f"lidar serve did not start: {line!r} {p.stderr.read()}")
    return p


def stop_serve(p: subprocess.Popen) -> dict:
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=30)
    lines = [ln for ln in out.splitlines() if ln.startswith("{")]
    print("  serve:", err.strip().replace("\n", "\n  serve: "))
    return json.loads(lines[-1]) if lines else {}


def socket_drops(pid: int) -> int | None:
    """Datagrams the kernel dropped on the UDP sockets process ``pid`` holds (their receive buffers
    full: the process did not read fast enough), from ``/proc/net/udp`` and ``udp6``; None where
    /proc does not tell."""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return None
    inodes = set()
    for fd in fds:
        try:
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:          # closed meanwhile
            continue
        if link.startswith("socket:["):
            inodes.add(link[8:-1])
    total = 0
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        if os.path.exists(table):
            for line in open(table).read().splitlines()[1:]:
                f = line.split()
                if f[9] in inodes:
                    total += int(f[-1])
    return total


def run_sample(cmd: list[str], cwd: Path, timeout_s: float, verbose: bool) -> tuple[str, int | None]:
    """Run a sample; returns what it printed and the datagrams the kernel dropped on its sockets (read
    every 0.2 s while it runs, the last reading before it closed them: a count below 100 % received
    is then told apart into the sample's sockets overflowing and a tail it never read)."""
    t0 = time.monotonic()
    p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         env={**os.environ, "LIVOX_RUN_S": os.environ.get("LIVOX_RUN_S", "10")})
    drops = [None]

    def watch():
        while p.poll() is None:
            d = socket_drops(p.pid)
            if d is not None:
                drops[0] = d
            time.sleep(0.2)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        text, _ = p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        p.kill()
        text, _ = p.communicate()
    watcher.join(1.0)
    keep = [ln for ln in text.splitlines()
            if verbose or ("[console]" not in ln and "packet num" not in ln and "Finish save" not in ln)]
    print(f"  {Path(cmd[0]).name} exit {p.returncode} after {time.monotonic() - t0:.1f} s; it printed:")
    for ln in keep:
        print("    " + ln)
    return text, drops[0]


def received(text: str) -> dict:
    """Packets (and returns, with the counting build) per data type the sample reports."""
    out = {}
    for m in re.finditer(r"COUNT data_type (\d+) packets (\d+) data_num (\d+) returns (\d+)", text):
        out[int(m[1])] = {"packets": int(m[2]), "returns": int(m[4])}
    if not out:
        for m in re.finditer(r"data_type (\d+) packet num (\d+)", text):
            out[int(m[1])] = {"packets": int(m[2]), "returns": None}  # floor to 100 packets
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sdk-bin", default=os.environ.get("LIVOX_SDK_BIN"),
                    help="directory with lidar_sample and lidar_lvx_sample (or LIVOX_SDK_BIN)")
    ap.add_argument("--scene", action="append", type=Path,
                    help="scene(s) to serve (default scenes/fig12-tracking.toml)")
    ap.add_argument("--capture", type=Path, help="keep the control logs here")
    ap.add_argument("--lvx-time-s", type=int, default=2)
    ap.add_argument("--verbose", action="store_true", help="also print the SDK's own log lines")
    a = ap.parse_args(argv)
    if not a.sdk_bin or not Path(a.sdk_bin).is_dir():
        print("no Livox SDK samples (give --sdk-bin DIR or LIVOX_SDK_BIN); nothing run")
        return 0
    binp = Path(a.sdk_bin)
    scenes = a.scene or [ROOT / "scenes" / "fig12-tracking.toml"]
    work = Path(tempfile.mkdtemp(prefix="livox-sdk-run-"))
    if a.capture:
        a.capture.mkdir(parents=True, exist_ok=True)
    run_s = float(os.environ.get("LIVOX_RUN_S", "10"))
    for scene in scenes:
        preset = re.search(r'^preset\s*=\s*"([^"]+)"', scene.read_text(), re.M)
        preset = preset[1] if preset else "?"
        for sample, args, serve_s in (("lidar_sample", [], run_s + 40), ("lidar_lvx_sample", ["-t", str(a.lvx_time_s)], 60)):
            exe = binp / sample
            if not exe.exists():
                print(f"{sample}: not in {binp}; skipped")
                continue
            print(f"== {sample} {' '.join(args)} against lidar serve {scene.name} (preset {preset})")
            log = work / f"sdk-{sample}-{preset}.jsonl"
            cwd = work / f"{sample}-{preset}"
            cwd.mkdir(exist_ok=True)
            serve = start_serve(scene, log, serve_s)
            try:
                text, drops = run_sample([str(exe)] + args, cwd, 120, a.verbose)
            finally:
                time.sleep(1.0)
                counters = stop_serve(serve)
            print("  serve counters:", json.dumps(counters))
            if sample == "lidar_sample":
                rx = received(text)
                sent_pk = counters.get("packets_sent", 0) + counters.get("imu_packets_sent", 0)
                got_pk = sum(v["packets"] for v in rx.values())
                print(f"  packets: sent {sent_pk}, received {got_pk} ({100.0 * got_pk / max(sent_pk, 1):.2f} %)"
                      f" by data type {json.dumps({k: v['packets'] for k, v in rx.items()})}")
                print(f"  datagrams the kernel dropped on the sample's sockets (its receive buffers full): "
                      f"{'unknown' if drops is None else drops}; the rest of any shortfall is the tail sent "
                      f"after the sample stopped reading")
                if all(v["returns"] is not None for v in rx.values()) and rx:
                    got = sum(v["returns"] for v in rx.values())
                    sent = counters.get("points_sent", 0)
                    print(f"  returns (points): sent {sent}, received {got} ({100.0 * got / max(sent, 1):.2f} %)")
                fw = re.search(r"firm ver: ([\d.]+)", text)
                print(f"  firmware the sample printed: {fw[1] if fw else 'none'}")
            else:
                lvx = sorted(cwd.glob("*.lvx"))
                if not lvx:
                    print("  no .lvx written")
                else:
                    print(f"  wrote {lvx[-1].name} ({lvx[-1].stat().st_size} bytes); foveatrack replay says:")
                    r = subprocess.run(FOVEATRACK + ["replay", str(lvx[-1]), "--tracker-config",
                                                    str(ROOT / "examples" / "daemon-virtual.toml")], capture_output=True, text=True,
                                       cwd=ROOT, timeout=600)
                    for ln in (r.stdout + r.stderr).strip().splitlines()[:6]:
                        print("    " + ln)
                    print(f"    (exit {r.returncode})")
            if a.capture:
                shutil.copy(log, a.capture / log.name)
            time.sleep(4.0)  # the port and the SDK's link timeout (3 s) before the next run
    print(f"work files in {work}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
