import json
import math

import numpy as np
import pytest

from foveatrack.control import (HeadCommand, deadband_p, head_command, head_errors_deg, lidar_errors_deg,
                                limit_for_stops, speed_to_axis)
from foveatrack.errors import UserError
from foveatrack.speed_table import TURBO, AxisTable, SpeedEntry, SpeedTable


def test_sign_conventions_left_and_up_are_positive():
    # target at +Y (left) -> positive pan error -> pan_dir +1 (Pelco left, pan angle increases)
    e_pan, e_tilt = lidar_errors_deg([10.0, 1.0, -1.0])
    assert e_pan > 0 and e_tilt < 0
    table = SpeedTable.nominal()
    d, b, v = speed_to_axis(deadband_p(e_pan, 2.0, 2.0), table.pan)
    assert d == +1 and v > 0
    d, b, v = speed_to_axis(deadband_p(e_tilt, 2.0, 2.0), table.tilt)
    assert d == -1 and v < 0


def test_dead_band_edge():
    assert deadband_p(1.999999, 2.0, 3.0) == 0.0
    assert deadband_p(2.0, 2.0, 3.0) == 6.0          # |e| < db is quiet; on the edge it moves
    assert deadband_p(-2.0, 2.0, 3.0) == -6.0
    # the same through geometry: a point 2 deg +- 1e-6 off axis
    for ang, moves in ((2.0 - 1e-6, False), (2.0 + 1e-6, True)):
        e, _ = lidar_errors_deg([math.cos(math.radians(ang)), math.sin(math.radians(ang)), 0.0])
        assert (deadband_p(e, 2.0, 1.0) != 0.0) is moves


def test_behind_and_overhead_hand_cases():
    assert lidar_errors_deg([-1.0, 0.0, 0.0]) == (180.0, 0.0)    # behind: turn left at full speed
    e_pan, e_tilt = lidar_errors_deg([-1.0, -1.0, 0.0])
    assert e_pan == pytest.approx(-135.0)
    assert lidar_errors_deg([0.0, 0.0, 3.0]) == (0.0, 90.0)      # overhead: tilt up only
    # head-frame errors: lidar tilted up 30 deg, point straight up in the world
    p = [math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))]
    e_pan, e_tilt = head_errors_deg(p, 30.0)
    assert e_pan == pytest.approx(0.0, abs=1e-9) and e_tilt == pytest.approx(60.0)
    # at tilt 0, no offset, head errors == lidar errors
    q = [3.0, -2.0, 1.5]
    assert np.allclose(head_errors_deg(q, 0.0), lidar_errors_deg(q))
    # near the zenith the lidar azimuth understates the pan needed: head frame corrects by 1/cos(tilt)
    tilt = 70.0
    target_world_dir = [math.cos(math.radians(70)) * math.cos(math.radians(5)),
                        math.cos(math.radians(70)) * math.sin(math.radians(5)), math.sin(math.radians(70))]
    c, s = math.cos(math.radians(tilt)), math.sin(math.radians(tilt))
    p_lidar = [c * target_world_dir[0] + s * target_world_dir[2], target_world_dir[1],
               -s * target_world_dir[0] + c * target_world_dir[2]]
    assert head_errors_deg(p_lidar, tilt)[0] == pytest.approx(5.0)
    assert lidar_errors_deg(p_lidar)[0] == pytest.approx(5.0 * math.cos(math.radians(70)), rel=0.01)


def test_saturation_and_inverse():
    t = SpeedTable.nominal()
    d, b, v = speed_to_axis(1e6, t.pan)
    assert (d, b) == (1, 63) and v == pytest.approx(15.0)
    d, b, v = speed_to_axis(-1e6, t.pan, allow_turbo=True)
    assert (d, b) == (-1, TURBO)
    d, b, v = speed_to_axis(100.0, t.pan, max_speed_deg_s=5.0)
    assert t.pan.speed_deg_s(b) <= 5.0 and d == 1
    assert speed_to_axis(0.0, t.pan) == (0, 0, 0.0)
    # every byte's own speed inverts to itself on a strictly monotone table
    for b in range(64):
        assert t.pan.byte_for_speed(t.pan.speed_deg_s(b)) == b


def test_inverse_on_non_monotone_and_partial_tables():
    es = [SpeedEntry(0, 0.0, 0.01), SpeedEntry(10, 2.0, 0.1), SpeedEntry(20, 1.5, 0.1), SpeedEntry(30, 6.0, 0.2)]
    ax = AxisTable("tilt", tuple(es))
    assert ax.speed_deg_s(5) == pytest.approx(1.0)        # linear between knots
    assert ax.sigma_deg_s(5) == pytest.approx(0.1)        # larger neighbour
    assert math.isnan(ax.speed_deg_s(40))                 # beyond the knots: unknown
    assert ax.byte_for_speed(2.0) == 10                   # non-monotone: exact match found
    assert ax.speed_deg_s(ax.byte_for_speed(1.5)) == pytest.approx(1.5)
    assert ax.byte_for_speed(100.0) == 30                 # beyond the table: fastest known
    assert ax.byte_for_speed(1e-6) == 1                   # slowest byte that moves (>0)
    assert 40 in ax.unmeasured_bytes and 10 not in ax.unmeasured_bytes and 5 in ax.unmeasured_bytes


def test_stop_limit():
    v, lim = limit_for_stops(20.0, 50.0, 0.0, -30, 60, 3.0, 0.5)
    assert lim and v == pytest.approx((57 - 50) / 0.5)
    v, lim = limit_for_stops(10.0, 58.0, 0.0, -30, 60, 3.0, 0.5)
    assert lim and v == 0.0
    v, lim = limit_for_stops(-10.0, 58.0, 0.0, -30, 60, 3.0, 0.5)   # away from the stop is fine
    assert not lim and v == -10.0


def test_head_command_validation():
    HeadCommand(1, TURBO, -1, 63)
    for bad in ((2, 0, 0, 0), (1, 64, 0, 0), (0, 0, 1, TURBO), (0, 5, 0, 0)):
        with pytest.raises(ValueError):
            HeadCommand(*bad)


def test_table_roundtrip_and_errors(tmp_path):
    t = SpeedTable.nominal()
    p = tmp_path / "t.json"
    t.save(p)
    u = SpeedTable.load(p)
    assert np.allclose(u.pan.speeds_array()[0], t.pan.speeds_array()[0], equal_nan=True)
    assert u.pan.unmeasured_bytes == t.pan.unmeasured_bytes
    d = t.to_dict()
    d["unit"] = "rad/s"
    p.write_text(json.dumps(d))
    assert SpeedTable.load(p).pan.speed_deg_s(63) == pytest.approx(15.0 * 180 / math.pi)
    # the accelerations are named in deg/s^2 and stay so whatever the speeds' unit (they loaded x57)
    d["accel_deg_s2"] = 40.0
    d["axes"]["tilt"]["accel_deg_s2"] = 9.3
    p.write_text(json.dumps(d))
    u = SpeedTable.load(p)
    assert u.accel_deg_s2 == 40.0 and u.tilt.accel_deg_s2 == 9.3
    cases = [
        ("{", "not valid JSON"),
        (json.dumps({**t.to_dict(), "unit": "rpm"}), "unit must be one of"),
        (json.dumps({**t.to_dict(), "color": 1}), "unknown key"),
        (json.dumps({**t.to_dict(), "axes": {"pan": {"entries": []}}}), "exactly the keys"),
    ]
    bad_byte = t.to_dict()
    bad_byte["axes"]["tilt"]["entries"][0]["byte"] = "turbo"
    cases.append((json.dumps(bad_byte), "tilt.entries\\[0\\].byte"))
    neg = t.to_dict()
    neg["axes"]["pan"]["entries"][3]["speed"] = -1
    cases.append((json.dumps(neg), "speed must be >= 0"))
    for text, msg in cases:
        p.write_text(text)
        with pytest.raises(UserError, match=msg) as ei:
            SpeedTable.load(p)
        assert str(p) in str(ei.value)
    with pytest.raises(UserError, match="cannot read"):
        SpeedTable.load(tmp_path / "missing.json")


def _random_axis_table(rng, axis):
    """Tables with repeated speeds (rounded), gaps (NaN), zeros and (pan) a turbo entry."""
    n = int(rng.integers(1, 12))
    bytes_ = sorted(rng.choice(64, size=n, replace=False).tolist())
    speeds = np.round(rng.uniform(0.0, 10.0, n), int(rng.integers(0, 3)))
    speeds[rng.random(n) < 0.1] = 0.0
    es = [SpeedEntry(int(b), float(s), 0.1) for b, s in zip(bytes_, speeds)]
    if axis == "pan" and rng.random() < 0.7:
        es.append(SpeedEntry(TURBO, float(rng.choice([speeds.max(), round(rng.uniform(0, 12), 1)])), 0.1))
    return AxisTable(axis, tuple(es))


def test_byte_for_speed_bisection_equals_the_scan():
    """The per-frame inverse (bisection in sorted candidates) picks the scan's byte: nearest,
    ties within 1e-12 to the slower, equal speeds to the first byte, beyond the table the fastest."""
    rng = np.random.default_rng(7)
    n_checked = 0
    for _ in range(40):
        tab = _random_axis_table(rng, str(rng.choice(["pan", "tilt"])))
        for turbo in (False, True):
            b, s = tab._candidates(turbo)
            if b.size == 0:
                with pytest.raises(UserError):
                    tab.byte_for_speed(1.0, allow_turbo=turbo)
                continue
            assert tab.max_speed_deg_s(turbo) == float(s.max())
            if not turbo:
                assert tab.min_speed_deg_s() == float(s.min())
            ss = np.sort(s)
            mids = (ss[:-1] + ss[1:]) / 2
            targets = np.concatenate([s, s + 1e-12, s - 1e-12, s + 2e-12, mids, mids + 5e-13, -s,
                                      rng.uniform(-15, 15, 20), [0.0, 1e17, -np.inf, np.inf]])
            for v in targets:
                assert tab.byte_for_speed(v, allow_turbo=turbo) == tab._byte_for_speed_scan(v, allow_turbo=turbo)
                n_checked += 1
    assert n_checked > 3000
    with pytest.raises(ValueError):
        SpeedTable.nominal().pan.byte_for_speed(float("nan"))   # as the scan: no nearest byte


def test_speed_lookup_equals_the_arrays():
    tab = SpeedTable.nominal()
    for ax in (tab.pan, tab.tilt):
        speed, _ = ax.speeds_array()
        for b in list(range(64)) + [TURBO]:
            got = ax.speed_deg_s(b)
            ref = float(speed[64 if b == TURBO else b])
            assert type(got) is float and (got == ref or (math.isnan(got) and math.isnan(ref)))


def test_head_command_shares_one_validated_instance_per_value():
    a = head_command(1, 5, -1, 3)
    assert a == HeadCommand(1, 5, -1, 3) and head_command(1, 5, -1, 3) is a
    assert head_command(0, 0, 0, 0) == HeadCommand()
    with pytest.raises(ValueError):
        head_command(0, 5, 0, 0)
