"""Virtual UART: baud timing, serialisation, effects, and drawing no random numbers when off."""

import numpy as np
import pytest

from gimbal import pelco as P
from gimbal.framing import PelcoDParser
from gimbal.pts303h import PTS303H
from sim.virtual_uart import VirtualUart, join_arrivals


class CountingRng:
    """Wraps a Generator and counts every call that draws numbers."""

    def __init__(self, seed=0):
        self._g = np.random.default_rng(seed)
        self.calls = 0

    def __getattr__(self, name):
        attr = getattr(self._g, name)
        if callable(attr):
            def counted(*a, **k):
                self.calls += 1
                return attr(*a, **k)
            return counted
        return attr


def test_a_pelco_d_frame_takes_7_29_ms_at_9600_baud():
    u = VirtualUart(9600)
    arr = u.send(P.encode_stop(1), 1.0)
    assert len(arr) == 7
    assert arr[-1][0] - 1.0 == pytest.approx(7 * 10 / 9600)  # 7.29 ms
    assert np.allclose(np.diff([t for t, _ in arr]), 10 / 9600)
    assert b"".join(b for _, b in arr) == P.encode_stop(1)


def test_bytes_queue_behind_bytes_still_on_the_wire():
    u = VirtualUart(2400)
    a = u.send(b"\x01\x02", 0.0)
    b = u.send(b"\x03", 0.001)  # line busy until 8.33 ms
    assert b[0][0] == pytest.approx(a[-1][0] + 10 / 2400)
    c = u.send(b"\x04", 1.0)  # line idle again
    assert c[0][0] == pytest.approx(1.0 + 10 / 2400)


def test_disabled_effects_draw_no_random_numbers():
    rng = CountingRng()
    u = VirtualUart(9600, effects=frozenset(), rng=rng)
    for k in range(50):
        u.send(P.encode_pan_tilt(1, 1, 0x20, 0, 0), 0.01 * k)
    assert rng.calls == 0
    echo_only = VirtualUart(9600, effects={"echo"}, rng=rng)
    echo_only.send(b"\x00" * 10, 0.0)
    assert rng.calls == 0


def test_each_effect_draws_only_its_own_numbers():
    """Enabling 'drop' next to 'bit_errors' leaves the bit errors of every later frame untouched,
    and the other way round (802524f drew both from one stream: 0.1 % drops changed the bit errors
    of 49 of 50 frames)."""
    frames = [P.encode_pan_tilt(1, 1, k % 64, -1, (3 * k) % 64) for k in range(50)]
    for rate_name in ("drop", "bit_errors"):
        lines = [VirtualUart(9600, fx, rng=np.random.default_rng(5), bit_error_rate=0.01, drop_rate=0.02)
                 for fx in ({"bit_errors", "drop"} - {rate_name}, {"bit_errors", "drop"})]
        for k, f in enumerate(frames):
            alone, both = (line.send(f, 0.1 * k) for line in lines)
            if rate_name == "drop":   # the bit errors of the bytes both delivered: the same
                got = dict(both)
                assert all(got[t] == b for t, b in alone if t in got)
            else:                     # the same bytes dropped
                assert [t for t, _ in alone] == [t for t, _ in both]
        assert lines[1].bytes_dropped > 0 and lines[1].bits_flipped > 0


def test_each_effect_can_bring_its_own_stream():
    data = bytes(range(256)) * 4
    own = VirtualUart(9600, {"bit_errors", "drop"}, rngs={"bit_errors": np.random.default_rng(1),
                                                          "drop": np.random.default_rng(2)}, drop_rate=0.05)
    bits = VirtualUart(9600, {"bit_errors"}, rngs={"bit_errors": np.random.default_rng(1)})
    drops = VirtualUart(9600, {"drop"}, rngs={"drop": np.random.default_rng(2)}, drop_rate=0.05)
    got, b, d = own.send(data, 0.0), dict(bits.send(data, 0.0)), drops.send(data, 0.0)
    assert [t for t, _ in got] == [t for t, _ in d] and all(b[t] == x for t, x in got)
    with pytest.raises(ValueError, match="drop"):
        VirtualUart(effects={"bit_errors", "drop"}, rngs={"bit_errors": np.random.default_rng(1)})
    with pytest.raises(ValueError, match="either"):
        VirtualUart(effects={"drop"}, rng=np.random.default_rng(1), rngs={"drop": np.random.default_rng(1)})


def test_bit_error_and_drop_rates():
    n = 40000
    data = bytes(n)
    u = VirtualUart(9600, {"bit_errors"}, rng=np.random.default_rng(1), bit_error_rate=0.01)
    got = np.frombuffer(b"".join(b for _, b in u.send(data, 0.0)), dtype=np.uint8)
    flips = np.unpackbits(got).sum()
    expect = 8 * n * 0.01
    assert abs(flips - expect) < 5 * np.sqrt(expect) and flips == u.bits_flipped
    d = VirtualUart(9600, {"drop"}, rng=np.random.default_rng(2), drop_rate=0.05)
    arr = d.send(data, 0.0)
    lost = n - len(arr)
    assert abs(lost - 0.05 * n) < 5 * np.sqrt(0.05 * n) and lost == d.bytes_dropped
    # a dropped byte still took its time on the wire
    assert d.line_free_at_s == pytest.approx(n * 10 / 9600)


def test_rs485_echo_returns_the_senders_own_bytes():
    u = VirtualUart(9600, echo=True)
    f = P.encode_query_pan(1)
    far = u.send(f, 0.5)
    echo = u.pop_echo()
    assert echo == far and u.pop_echo() == []


def test_query_and_reply_through_two_lines_take_two_frames_plus_turnaround():
    head = PTS303H(feedback="always", pan0_deg=12.34)
    down, up = VirtualUart(9600), VirtualUart(9600)
    data, times = join_arrivals(down.send(P.encode_query_pan(1), 0.0))
    replies = head.receive(data, times)
    (t_send, frame), = replies
    back = up.send(frame, t_send)
    parser = PelcoDParser()
    d2, t2 = join_arrivals(back)
    (r,) = parser.feed(d2, t2)
    assert P.word_to_pan_deg(r.word) == pytest.approx(12.34)
    assert t2[-1] == pytest.approx(14 * 10 / 9600 + head.params.reply_delay_s)


def test_unknown_effects_and_missing_rng_are_errors():
    with pytest.raises(ValueError, match="allowed"):
        VirtualUart(effects={"lightning"})
    with pytest.raises(ValueError, match="rng"):
        VirtualUart(effects={"drop"})
