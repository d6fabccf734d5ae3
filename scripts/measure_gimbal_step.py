"""Measure the virtual PTS-303H from the outside and print measured vs. model numbers.

Pelco-D step commands go through a pyserial port into the pty-served head, run on a manual
(virtual) clock; speed, acceleration and dead time are read back from the truth file.  Also
prints the step-size independence of the exact dynamics and the cost of ``angles_at``.

    python scripts/measure_gimbal_step.py [seed ...]
"""

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import serial

from gimbal import pelco as P
from gimbal.pts303h import PTS303H
from sim.virtual_head import ManualClock, VirtualHeadServer, estimate_step_response, read_truth

BAUD = 9600


def measure(seed: int, tmp: Path) -> None:
    clock = ManualClock()
    head = PTS303H(unit_seed=seed)
    truth = tmp / f"truth{seed}.jsonl"
    with open(truth, "w") as fh:
        srv = VirtualHeadServer(head, clock, baud=BAUD, truth=fh, truth_period_s=0.005)
        port = serial.serial_for_url(srv.open(), BAUD)

        def write(frame):
            port.write(frame)
            want = srv.bytes_in + len(frame)
            while srv.bytes_in < want:
                srv.step(0.05)
            return clock.t + len(frame) * 10 / BAUD

        def run_until(t_end):
            while clock.t < t_end:
                clock.t = round(clock.t + 0.001, 9)
                srv.step(0.0)

        p = head.params
        print(f"unit seed {seed}: dead time {p.dead_time_s * 1e3:.1f} ms, "
              f"pan accel {p.pan_accel_deg_s2:.1f} deg/s^2")
        print("  byte  model_deg_s  measured_deg_s  accel_deg_s2  dead_time_ms(first moving row)")
        t = 0.2
        for byte in (0x01, 0x04, 0x08, 0x10, 0x20, 0x30, 0x3F, P.PAN_TURBO):
            run_until(t)
            t_arr = write(P.encode_pan_tilt(1, 1, byte, 0, 0))
            run_until(t + 2.0)
            rows = [r for r in read_truth(truth) if r["t_s"] >= t]
            m = estimate_step_response(rows, t_arr, "pan", window_s=0.8)
            print(f"  0x{byte:02X}  {head.true_speed_deg_s('pan', byte):11.4f}  "
                  f"{m['speed_deg_s']:14.4f}  {m['accel_deg_s2']:12.2f}  "
                  f"{m['dead_time_s'] * 1e3:8.1f}")
            write(P.encode_stop(1))
            t += 3.0
        run_until(t)
        port.close()
        srv.close()


def exactness() -> None:
    def run(step):
        h = PTS303H(tilt0_deg=58.0)
        cmds = [(0.1, P.encode_pan_tilt(1, 1, 0x3F, 1, 0x3F)),
                (1.3, P.encode_pan_tilt(1, -1, 0xFF, 1, 0x3F)),
                (2.2, P.encode_pan_tilt(1, 1, 0x08, -1, 0x3F))]
        t, out = 0.0, []
        for tc, f in cmds:
            while t + step <= tc:
                t += step
                out.append(h.state_at(t))
            h.receive(f, tc)
        grid = np.linspace(2.3, 4.0, 50)
        return np.array(h.angles_at(grid))

    ref = run(1.0)
    for step in (0.1, 0.01, 0.001):
        print(f"  advance step {step:6.3f} s: max |angle - coarse| = "
              f"{np.max(np.abs(run(step) - ref)):.2e} deg")
    h = PTS303H()
    h.receive(P.encode_pan_tilt(1, 1, 0x30, 1, 0x20), 0.0)
    for k in range(1, 11):
        h.receive(P.encode_pan_tilt(1, 1, 0x20 + k, 1, 0x20), 0.1 * k)
    t = np.sort(np.random.default_rng(0).uniform(1.0, 1.1, 10_000))
    h.angles_at(t)
    t0 = time.perf_counter()
    for _ in range(20):
        h.angles_at(t)
    print(f"  angles_at(10^4 times): {(time.perf_counter() - t0) / 20 * 1e3:.2f} ms per call")


if __name__ == "__main__":
    seeds = [int(s) for s in sys.argv[1:]] or [0, 1]
    with tempfile.TemporaryDirectory() as d:
        for s in seeds:
            measure(s, Path(d))
    print("exact dynamics:")
    exactness()
