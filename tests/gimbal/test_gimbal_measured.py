"""The head measured from the outside: bytes into the served pty, numbers out of the truth file.

The server runs on a :class:`ManualClock`, so the measurement is deterministic; the controller is
pyserial opening the pty path, exactly as a real tracker would.
"""

import pytest
import serial

from gimbal import pelco as P
from gimbal.pts303h import PTS303H
from sim.virtual_head import ManualClock, VirtualHeadServer, estimate_step_response, read_truth

BAUD = 9600


class Bench:
    def __init__(self, tmp_path, seed):
        self.clock = ManualClock()
        self.head = PTS303H(unit_seed=seed)
        self.truth_path = tmp_path / f"truth{seed}.jsonl"
        self.fh = open(self.truth_path, "w")
        self.server = VirtualHeadServer(self.head, self.clock, baud=BAUD, truth=self.fh,
                                        truth_period_s=0.005)
        self.path = self.server.open()
        self.port = serial.serial_for_url(self.path, BAUD, timeout=0.2)

    def write(self, frame):
        """Write now (virtual time frozen until the server has read the bytes)."""
        self.port.write(frame)
        self.port.flush()
        want = self.server.bytes_in + len(frame)
        for _ in range(200):
            self.server.step(0.05)  # real wait only until the bytes show up
            if self.server.bytes_in >= want:
                break
        assert self.server.bytes_in == want
        return self.clock.t + len(frame) * 10 / BAUD  # arrival of the last byte

    def run_until(self, t_end):
        while self.clock.t < t_end:
            self.clock.t = round(self.clock.t + 0.001, 9)
            self.server.step(0.0)

    def close(self):
        self.port.close()
        self.server.close()
        self.fh.close()


@pytest.mark.parametrize("seed", [0, 1])
def test_speed_curve_acceleration_and_dead_time_measured_from_outside(tmp_path, seed):
    b = Bench(tmp_path, seed)
    p = b.head.params
    try:
        results = []
        t = 0.2
        for byte in (0x01, 0x0C, 0x20, 0x3F, P.PAN_TURBO):
            b.run_until(t)
            t_arr = b.write(P.encode_pan_tilt(1, 1, byte, 0, 0))
            b.run_until(t + 2.0)
            rows = [r for r in read_truth(b.truth_path) if t <= r["t_s"]]
            results.append((byte, t_arr, rows))
            b.run_until(t + 2.1)
            b.write(P.encode_stop(1))
            t += 3.0
            b.run_until(t)
    finally:
        b.close()
    for byte, t_arr, rows in results:
        m = estimate_step_response(rows, t_arr, "pan", window_s=0.8)
        truth = b.head.true_speed_deg_s("pan", byte)
        if truth == 0:  # dead zone: no motion at all
            assert m["speed_deg_s"] == 0.0
            continue
        assert m["speed_deg_s"] == pytest.approx(truth, rel=0.01)
        if truth > 3.0:  # enough ramp samples at 5 ms
            assert m["accel_deg_s2"] == pytest.approx(p.pan_accel_deg_s2, rel=0.06)
        assert p.dead_time_s < m["dead_time_s"] <= p.dead_time_s + 0.005  # one truth period
        if truth > 3.0:
            assert m["ramp_dead_time_s"] == pytest.approx(p.dead_time_s, abs=0.01)


def test_tilt_step_from_outside(tmp_path):
    b = Bench(tmp_path, 2)
    try:
        b.run_until(0.1)
        t_arr = b.write(P.encode_pan_tilt(1, 0, 0, -1, 0x3F))
        b.run_until(2.5)
    finally:
        b.close()
    m = estimate_step_response(read_truth(b.truth_path), t_arr, "tilt", window_s=1.0)
    assert m["speed_deg_s"] == pytest.approx(-b.head.true_speed_deg_s("tilt", 0x3F), rel=0.01)
    assert m["accel_deg_s2"] == pytest.approx(b.head.params.tilt_accel_deg_s2, rel=0.1)
    dead = b.head.params.dead_time_s
    assert dead < m["dead_time_s"] <= dead + 0.005
    assert m["ramp_dead_time_s"] == pytest.approx(dead, abs=0.02)
