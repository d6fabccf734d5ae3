"""The head at its edges: pan wrap-around at +-180 deg, tilt at its stops, and the speed table's
inverse between, beyond and across non-monotone entries (paper Appendix D.3-D.4; the PTS-303H model
in ``gimbal.pts303h``, dead reckoning in ``foveatrack.reconstruction``).

Conventions: pan positive = LEFT (CCW from above), wrapped to (-180, 180]; tilt positive = UP.

Bounds asserted
---------------
* pan crossing +-180 (device model and reconstruction): every reported pan is in (-180, 180]; the
  motion is the same as an identical one far from the wrap, shifted, to 1e-9 deg; the rotation
  matrix changes by no more than the angle turned (+1e-12) between samples;
* Pelco position words round-trip any pan to 0.005 deg (half a word step) and +-180 to one word;
* tilt driven into a stop: the device model pins at exactly the stop (never past it by > 1e-9 deg)
  with zero speed, and leaves it when commanded away; the reconstruction clamps the same way;
* reversals near a stop (random command bursts 5-600 ms apart starting within the braking distance,
  reversals during the braking that carries the head into the stop): device model and reconstruction
  (the unit's own table, no ripple) agree to 1e-6 deg; with ripple, a reversed head is above the stop
  two seconds later by at least the slowest turn-round and ramp-up allow;
* ``limit_for_stops`` never lets the estimate + 2 sigma + speed x lookahead pass the margin, and
  never speeds up or reverses a command; over a closed run with the target parked above the upper
  stop, the tracker never drives the (simulated) head into it;
* ``byte_for_speed`` returns a byte with a known speed > 0 that is nearest to the request among all
  such bytes (ties -> slower) on any table, non-monotone and sparse ones included; beyond the
  table, including 1e300 and inf, the fastest; ``speed_to_axis`` never exceeds a cap or, in floor
  mode, the request, and never returns a byte of unknown speed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from foveatrack.control import HeadCommand, limit_for_stops, speed_to_axis
from foveatrack.reconstruction import Reconstructor, rotation_matrix
from foveatrack.speed_table import TURBO, AxisTable, SpeedEntry, SpeedTable
from foveatrack.tracker import Tracker, TrackerConfig
from foveatrack.frames import Frame
from gimbal.pelco import encode_pan_tilt, pan_deg_to_word, word_to_pan_deg
from gimbal.pts303h import PTS303H, HeadParams
from sim.loop import truth_speed_table
from stability_util import deg_diff, examples

# ------------------------------------------------------------------------------------------------
# pan wrap-around


@examples(25)
@given(st.floats(-180.0, 180.0), st.integers(5, 63), st.sampled_from([1, -1]), st.integers(0, 1000))
def test_device_pan_crosses_the_wrap_like_anywhere_else(offset_deg, byte, direction, seed):
    """Two identical units, one starting at pan 0 and one at 179.9 (left) / -179.9 (right): the
    second crosses +-180 within the run; the difference stays 179.9 (mod 360) to 1e-9 deg."""
    start = 179.9 * direction
    heads = [PTS303H(unit_seed=seed, pan0_deg=p0) for p0 in (0.0, start)]
    frame = encode_pan_tilt(1, direction, byte, 0, 0)
    for h in heads:
        h.receive(frame, 0.0)
    t = np.linspace(0.0, 4.0, 401)
    pans = [h.angles_at(t)[0] for h in heads]
    for p in pans:
        assert np.all((p > -180.0) & (p <= 180.0))
    d = np.array([deg_diff(b, a) for a, b in zip(*pans)])
    assert np.max(np.abs(d - start)) <= 1e-9
    unwrapped = np.degrees(np.unwrap(np.radians(pans[1])))
    crossed = np.any(np.abs(unwrapped) > 180.0)
    assert crossed or heads[1].true_speed_deg_s("pan", byte) * 4.0 < 0.2


@examples(60)
@given(st.floats(170.0, 180.0), st.integers(1, 63), st.sampled_from([1, -1]),
       st.one_of(st.none(), st.floats(5.0, 100.0)), st.floats(0.0, 0.1))
def test_reconstruction_is_continuous_across_the_wrap(pan0_abs, byte, direction, accel, dead_time):
    """Dead reckoning from pan0 near +-180 toward the wrap equals the same reckoning from 0,
    shifted by pan0 (mod 360), to 1e-9 deg; its rotation matrix moves no faster than the angle."""
    pan0 = pan0_abs * direction
    table = SpeedTable.nominal()
    recs = [Reconstructor(table, pan0_deg=p0, accel_deg_s2=accel, dead_time_s=dead_time) for p0 in (0.0, pan0)]
    for r in recs:
        r.on_command(0.0, HeadCommand(direction, byte, 0, 0))
    t = np.linspace(0.0, 30.0, 301)
    a = np.array([recs[0].angles_at(x)[0] for x in t])
    b = np.array([recs[1].angles_at(x)[0] for x in t])
    assert np.all((b > -180.0) & (b <= 180.0))
    from foveatrack.detection import wrap_deg
    assert max(abs(deg_diff(bb, wrap_deg(aa + pan0))) for aa, bb in zip(a, b)) <= 1e-9
    R = [recs[1].rotation_at(x) for x in t]
    for i in range(len(t) - 1):
        turned = abs(math.radians(deg_diff(b[i + 1], b[i])))
        assert np.linalg.norm(R[i + 1] - R[i], 2) <= turned + 1e-12


@examples(200)
@given(st.floats(-1e4, 1e4))
def test_pan_word_round_trip_including_the_wrap(pan_deg):
    from foveatrack.detection import wrap_deg

    back = word_to_pan_deg(pan_deg_to_word(pan_deg))
    assert -180.0 < back <= 180.0
    assert abs(deg_diff(back, wrap_deg(pan_deg))) <= 0.005 + 1e-9


def test_pan_words_at_the_wrap():
    assert word_to_pan_deg(pan_deg_to_word(180.0)) == 180.0
    assert word_to_pan_deg(pan_deg_to_word(-180.0)) == 180.0
    assert word_to_pan_deg(pan_deg_to_word(-179.99)) == -179.99
    assert word_to_pan_deg(pan_deg_to_word(179.99)) == 179.99


# ------------------------------------------------------------------------------------------------
# tilt at its stops


@examples(30)
@given(st.floats(-29.0, 59.0), st.integers(10, 63), st.sampled_from([1, -1]), st.floats(0.0, 60.0),
       st.integers(0, 1000))
def test_device_pins_at_the_stop_and_leaves_it(tilt0, byte, direction, extra_s, seed):
    p = HeadParams()
    head = PTS303H(p, unit_seed=seed, tilt0_deg=tilt0)
    stop = p.tilt_max_deg if direction > 0 else p.tilt_min_deg
    v = head.true_speed_deg_s("tilt", byte)
    assume(v > 0.05)
    head.receive(encode_pan_tilt(1, 0, 0, direction, byte), 0.0)
    travel_s = abs(stop - tilt0) / (v * (1 - p.ripple_rel)) + v / p.tilt_accel_deg_s2 + p.dead_time_s + 0.1
    t_end = travel_s + extra_s
    t = np.linspace(0.0, t_end, 2001)
    tilt = head.angles_at(t)[1]
    assert np.all(tilt <= p.tilt_max_deg + 1e-9) and np.all(tilt >= p.tilt_min_deg - 1e-9)
    assert tilt[-1] == stop
    assert head.rates_at([t_end])[1][0] == 0.0
    # commanded away: it leaves the stop in the commanded direction
    head.receive(encode_pan_tilt(1, 0, 0, -direction, byte), t_end)
    later = head.angles_at([t_end + p.dead_time_s + 2.0])[1][0]
    assert (later - stop) * direction < 0


@examples(60)
@given(st.floats(-29.0, 59.0), st.integers(1, 63), st.sampled_from([1, -1]), st.floats(1.0, 600.0),
       st.one_of(st.none(), st.floats(1.0, 50.0)))
def test_reconstruction_clamps_at_the_stops(tilt0, byte, direction, hold_s, accel):
    limits = (-30.0, 60.0)
    rec = Reconstructor(SpeedTable.nominal(), tilt0_deg=tilt0, tilt_limits_deg=limits, accel_deg_s2=accel)
    rec.on_command(0.0, HeadCommand(0, 0, direction, byte))
    ts = np.linspace(0.0, hold_s, 200)
    tilts = np.array([rec.angles_at(x)[1] for x in ts])
    assert np.all((tilts >= limits[0]) & (tilts <= limits[1]))
    stop = limits[1] if direction > 0 else limits[0]
    v = SpeedTable.nominal().tilt.speed_deg_s(byte)
    if abs(stop - tilt0) + (v * v / accel if accel else 0.0) < v * hold_s * 0.9:
        assert tilts[-1] == stop
        rec.on_command(hold_s, HeadCommand(0, 0, -direction, byte))
        after = rec.angles_at(hold_s + 1.0)[1]
        assert (after - stop) * direction < 0  # leaves from the stop, not from a wound-up angle


@examples(300)
@given(st.floats(-1e3, 1e3), st.floats(-90.0, 90.0), st.floats(0.0, 5.0), st.floats(0.0, 10.0),
       st.floats(0.01, 2.0))
def test_limit_for_stops_never_passes_the_margin(v, angle, sigma, margin, lookahead):
    lo, hi = -30.0, 60.0
    out, limited = limit_for_stops(v, angle, sigma, lo, hi, margin, lookahead)
    assert abs(out) <= abs(v) and (out == 0.0 or math.copysign(1, out) == math.copysign(1, v))
    if out > 0:
        assert angle + 2 * sigma + out * lookahead <= hi - margin + 1e-9
    if out < 0:
        assert angle - 2 * sigma + out * lookahead >= lo + margin - 1e-9
    assert limited == (out != v)


def _lidar_point(world, pan, tilt):
    return rotation_matrix(pan, tilt).T @ world


@examples(6)
@given(st.floats(62.0, 89.0), st.floats(-180.0, 180.0), st.floats(30.0, 55.0), st.integers(0, 100),
       st.sampled_from(["paper", "predictive"]))
def test_tracker_never_drives_the_head_into_the_upper_stop(el_deg, az_deg, tilt0, seed, controller):
    """Closed run (25 s at 10 Hz) of the tracker and the PTS-303H model (its true speed table, so the
    reconstruction is right up to the 2 % ripple) with the target parked above the tilt stop at
    60 deg: the true tilt comes within 4.5 deg of the stop (the tracker keeps a 3 deg margin) but
    stays 1 deg clear of it, and the head is never pinned (measured: 56.99 deg)."""
    p = HeadParams()
    head = PTS303H(p, unit_seed=seed, tilt0_deg=tilt0)
    from sim.loop import truth_speed_table

    table = truth_speed_table(head)
    cfg = TrackerConfig(tilt_limits_deg=(p.tilt_min_deg, p.tilt_max_deg), tilt0_deg=tilt0,
                        controller=controller, latency_s=0.0)
    tracker = Tracker(cfg, table)
    e, a = math.radians(el_deg), math.radians(az_deg)
    world = 200.0 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    max_tilt = -90.0
    for i in range(250):
        t0, t1 = i * 0.1, (i + 1) * 0.1
        tm = np.linspace(t0, t1, 5, endpoint=False) + 0.01
        pans, tilts = head.angles_at(tm)
        max_tilt = max(max_tilt, float(tilts.max()))
        pts = np.array([_lidar_point(world, pp, tt) for pp, tt in zip(pans, tilts)])
        out = tracker.process(Frame(t0, t1, pts, (tm * 1e9).astype(np.int64)))
        c = out.command
        head.receive(encode_pan_tilt(1, c.pan_dir, c.pan_byte, c.tilt_dir, c.tilt_byte), t1)
    tilts = head.angles_at(np.linspace(24.0, 25.0, 50))[1]
    max_tilt = max(max_tilt, float(tilts.max()))
    assert max_tilt < p.tilt_max_deg - 1.0
    assert max_tilt > p.tilt_max_deg - 4.5  # it did go up toward the target
    assert not head._tilt.segs[-1].pinned


# ------------------------------------------------------------------------------------------------
# reversals near a tilt stop


@st.composite
def commands_near_a_stop(draw):
    """A head (no ripple; drawn tilt acceleration) starting within about its braking distance of a
    tilt stop, driven toward it, reversed, then a burst of tilt commands 5-600 ms apart: reversals
    while the deceleration still carries it into the stop, reversals once pinned, stops, repeats."""
    accel = draw(st.floats(2.0, 20.0))
    lower = draw(st.booleans())
    p = HeadParams(ripple_rel=0.0, tilt_accel_deg_s2=accel)
    stop = p.tilt_min_deg if lower else p.tilt_max_deg
    gap = draw(st.floats(0.0, 0.5))
    tilt0 = stop + gap if lower else stop - gap
    into = -1 if lower else 1
    step = st.tuples(st.floats(0.005, 0.6), st.integers(-1, 1), st.integers(20, 63))
    first = draw(st.tuples(st.floats(0.005, 0.6), st.just(into), st.integers(20, 63)))
    second = draw(st.tuples(st.floats(0.005, 0.6), st.just(-into), st.integers(20, 63)))
    cmds = [first, second] + draw(st.lists(step, max_size=20))
    return p, draw(st.integers(0, 1000)), tilt0, cmds


@examples(60)
@given(commands_near_a_stop())
def test_reversals_near_a_stop_device_and_reconstruction_agree(case):
    """The PTS-303H model (stop hits by root finding on its segments) and the dead reckoning (closed
    form) with the unit's own table: a stop absorbs the speed and a reversed command moves the head
    away from it at once, whether the deceleration carried it into the stop or it was pinned.
    Bounds: tilt never past a stop by > 1e-9 deg; the two agree to 1e-6 deg at every check (on
    802524f the device dropped such reversals: 1.3 deg apart, the head held at the stop)."""
    p, seed, tilt0, cmds = case
    head = PTS303H(p, unit_seed=seed, tilt0_deg=tilt0)
    rec = Reconstructor(truth_speed_table(head), tilt0_deg=tilt0, latency_s=0.0, timing_sigma_s=0.0,
                        tilt_limits_deg=(p.tilt_min_deg, p.tilt_max_deg))
    t, worst = 0.0, 0.0
    for dt, direction, byte in cmds:
        b = byte if direction else 0
        head.receive(encode_pan_tilt(1, 0, 0, direction, b), t)
        rec.on_command(t, HeadCommand(0, 0, direction, b))
        checks = np.linspace(t, t + dt, 7)[1:]
        tilt = head.angles_at(checks)[1]
        assert np.all(tilt >= p.tilt_min_deg - 1e-9) and np.all(tilt <= p.tilt_max_deg + 1e-9)
        est = np.array([rec.angles_at(float(x))[1] for x in checks])
        worst = max(worst, float(np.max(np.abs(est - tilt))))
        t += dt
    assert worst <= 1e-6


@examples(20)
@given(st.floats(0.0, 0.3), st.floats(0.0, 0.4), st.integers(20, 63), st.integers(0, 1000))
def test_a_reversal_is_honoured_at_a_stop(gap, reverse_after_s, byte, seed):
    """Driven down toward the lower stop and reversed up: however the reversal falls against the
    stop hit (before it, during the deceleration that carries the head into it, once pinned), the
    head is above the stop two seconds later, by at least the ramp-up from rest it must have made
    (with the 2 % speed ripple on)."""
    p = HeadParams()
    head = PTS303H(p, unit_seed=seed, tilt0_deg=p.tilt_min_deg + gap)
    v = head.true_speed_deg_s("tilt", byte)
    assume(v > 0.1)
    head.receive(encode_pan_tilt(1, 0, 0, -1, byte), 0.0)
    head.receive(encode_pan_tilt(1, 0, 0, 1, byte), reverse_after_s)
    t_check = reverse_after_s + p.dead_time_s + 2.0
    t = np.linspace(0.0, t_check, 801)
    tilt = head.angles_at(t)[1]
    assert np.all(tilt >= p.tilt_min_deg - 1e-9)
    # slowest possible: turns round (at or above the stop) v / accel after the reversal takes effect,
    # then ramps up from rest to v and holds it; the ripple takes off at most 2 % of the speed
    ramp_s = v / p.tilt_accel_deg_s2
    least = (1 - p.ripple_rel) * (0.5 * v * ramp_s + v * (2.0 - 2.0 * ramp_s))
    assert tilt[-1] - p.tilt_min_deg >= least - 1e-9


# ------------------------------------------------------------------------------------------------
# speed table inversion


@st.composite
def axis_tables(draw):
    axis = draw(st.sampled_from(["pan", "tilt"]))
    bytes_ = draw(st.lists(st.integers(0, 63), min_size=1, max_size=20, unique=True))
    entries = []
    for b in bytes_:
        # measured speeds: 0 (dead zone), 1e-3..40 deg/s, or unknown (the inverse treats speeds within
        # 1e-12 deg/s as a tie, so sub-1e-12 speeds would be indistinguishable by design)
        sp = draw(st.one_of(st.just(0.0), st.floats(1e-3, 40.0), st.just(math.nan)))
        entries.append(SpeedEntry(b, sp, draw(st.floats(0.0, 1.0))))
    if axis == "pan" and draw(st.booleans()):
        entries.append(SpeedEntry(TURBO, draw(st.floats(1e-3, 60.0)), 0.1))
    table = AxisTable(axis, tuple(entries))
    speeds, _ = table.speeds_array()
    assume(np.any(np.isfinite(speeds[:64]) & (speeds[:64] > 0)))
    return table


requests = st.one_of(st.floats(0.0, 100.0), st.floats(-100.0, 0.0),
                     st.sampled_from([0.0, 1e-300, 1e17, 1e300, math.inf, -math.inf]))


@examples(300)
@given(axis_tables(), requests, st.booleans())
def test_inverse_returns_the_nearest_known_byte(table, request, allow_turbo):
    allow_turbo = allow_turbo and table.axis == "pan"
    speeds, _ = table.speeds_array()
    idx = np.arange(65 if allow_turbo else 64)
    cand = idx[np.isfinite(speeds[idx]) & (speeds[idx] > 0)]
    assume(cand.size)
    b = table.byte_for_speed(request, allow_turbo=allow_turbo)
    i = 64 if b == TURBO else b
    assert i in cand  # never an unknown (NaN) or zero-speed byte
    s = speeds[i]
    target = abs(request)
    if target >= speeds[cand].max():
        assert s >= speeds[cand].max() - 1e-12  # beyond the table: the fastest (within the tie width)
    else:
        best = np.min(np.abs(speeds[cand] - target))
        assert abs(s - target) <= best + 1e-12
        ties = cand[np.abs(speeds[cand] - target) <= best + 1e-12]
        assert s == speeds[ties].min()  # ties: the slower


def test_inverse_of_nan_is_an_error_not_a_byte():
    table = SpeedTable.nominal().pan
    with pytest.raises((ValueError, ArithmeticError)):
        table.byte_for_speed(math.nan)


@examples(300)
@given(axis_tables(), st.one_of(st.floats(-200.0, 200.0), st.sampled_from([math.nan, math.inf, -math.inf, 0.0])),
       st.one_of(st.none(), st.floats(0.01, 50.0)), st.booleans(), st.booleans())
def test_speed_to_axis_respects_caps_and_known_bytes(table, v, cap, allow_turbo, floor):
    allow_turbo = allow_turbo and table.axis == "pan"
    d, b, sv = speed_to_axis(v, table, max_speed_deg_s=cap, allow_turbo=allow_turbo, floor=floor)
    assert d in (-1, 0, 1)
    if d == 0:
        assert b == 0 and sv == 0.0
        return
    assert math.isfinite(v) and d == (1 if v > 0 else -1)
    s = table.speed_deg_s(b)
    assert math.isfinite(s) and s > 0 and sv == d * s
    if cap is not None:
        assert s <= cap + 1e-12
    if floor:
        assert s <= abs(v) + 1e-12
    if b == TURBO:
        assert allow_turbo


@pytest.mark.parametrize("speed, sigma", [(-1.0, 0.1), (-math.inf, 0.1), (1.0, -0.1), (-0.0, -1e-300)])
def test_axis_table_refuses_what_a_table_file_refuses(speed, sigma):
    """A negative speed (a magnitude: the direction is the command's) or sigma is refused when the
    table is built in code too, as SpeedTable.from_dict refuses it in a file (802524f took it); NaN
    still means unknown."""
    from foveatrack.errors import UserError

    with pytest.raises(UserError, match="must be >= 0"):
        AxisTable("tilt", (SpeedEntry(5, 1.0, 0.1), SpeedEntry(9, speed, sigma)))
    AxisTable("tilt", (SpeedEntry(5, 1.0, 0.1), SpeedEntry(9, math.nan, math.nan)))
