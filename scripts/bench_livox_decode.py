"""Benchmark: decoding Livox type-2 (extended Cartesian) packets, and recording a frame.

For a Horizon stream of 240 k points/s (single return) and 480 k points/s (dual return) this
decodes one second of packets in chunks the way the client sees them (one ``poll`` every
``--poll-ms``) and prints points/s, seconds of stream per CPU second, and CPU ms per 100 ms frame.
It also times writing one 100 ms frame to a recording (lz4 / zstd / none).

    python scripts/bench_livox_decode.py [--repeat 5] [--poll-ms 10]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from foveatrack.livox import protocol as P
from foveatrack.recording import RecordingWriter
from foveatrack.environment import describe  # noqa: E402


def make_stream(rate_hz: float, seconds: float, rng) -> list[bytes]:
    n = int(rate_hz * seconds)
    xyz = rng.uniform(-100, 100, (n, 3))
    xyz[rng.random(n) < 0.2] = 0.0  # some no-return slots
    return P.encode_data_packets(xyz, rng.integers(0, 256, n), 0, rate_hz, data_type=2)


def bench_decode(rate_hz: float, packets: list[bytes], poll_ms: float, repeat: int) -> dict:
    per_poll = max(1, int(round(rate_hz * poll_ms / 1000 / P.POINTS_PER_PACKET[2])))
    chunks = [packets[i : i + per_poll] for i in range(0, len(packets), per_poll)]
    best = np.inf
    n_points = 0
    for _ in range(repeat):
        dec = P.DataDecoder(rate_hz)
        t0 = time.process_time()
        for c in chunks:
            dec.decode(c)
        best = min(best, time.process_time() - t0)
        n_points = dec.counters["points"] + dec.counters["no_return_points"]
    stream_s = len(packets) * P.POINTS_PER_PACKET[2] / rate_hz
    return {
        "points_per_s": n_points / best,
        "stream_s_per_cpu_s": stream_s / best,
        "cpu_ms_per_100ms_frame": best / stream_s * 100.0,
        "packets_per_poll": per_poll,
    }


def bench_record(rate_hz: float, compression: str, repeat: int, rng) -> float:
    n = int(rate_hz * 0.1)
    xyz = rng.uniform(-100, 100, (n, 3))
    tp = np.arange(n, dtype=np.int64) * int(1e9 / rate_hz)
    refl = rng.integers(0, 256, n).astype(np.uint8)
    with tempfile.TemporaryDirectory() as d:
        with RecordingWriter(Path(d) / "b.mcap", {}, compression=compression) as w:
            times = []
            for k in range(repeat):
                t0 = time.process_time()
                w.write_points(10**9 + k, k, xyz, tp, refl)
                w.flush()
                times.append(time.process_time() - t0)
    return min(times) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--poll-ms", type=float, default=10.0)
    a = ap.parse_args()
    print(describe(), flush=True)   # versions, CPU and numba target: a figure without them says little
    rng = np.random.default_rng(0)
    print(f"type-2 decode, {a.poll_ms:g} ms of packets per decode call, best of {a.repeat} (CPU time)")
    for rate in (240_000.0, 480_000.0):
        r = bench_decode(rate, make_stream(rate, 1.0, rng), a.poll_ms, a.repeat)
        print(
            f"  {rate / 1e3:5.0f} k pts/s: {r['points_per_s'] / 1e6:6.2f} M pts/s decoded, "
            f"{r['stream_s_per_cpu_s']:6.1f} s of stream per CPU s, "
            f"{r['cpu_ms_per_100ms_frame']:5.2f} ms CPU per 100 ms frame ({r['packets_per_poll']} packets/call)"
        )
    print("recording one 100 ms frame (write_points + flush), CPU ms:")
    for rate in (240_000.0, 480_000.0):
        cells = [f"{c} {bench_record(rate, c, a.repeat, rng):6.2f}" for c in ("none", "lz4", "zstd")]
        print(f"  {rate / 1e3:5.0f} k pts/s: " + ", ".join(cells))


if __name__ == "__main__":
    main()
