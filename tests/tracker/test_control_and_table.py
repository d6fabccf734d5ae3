import json
import math

import numpy as np
import pytest

from foveatrack.control import (HeadCommand, deadband_p, head_errors_deg, lidar_errors_deg,
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
