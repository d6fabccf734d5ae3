"""The shortest revisit gaps the head's speed allows (sim.sky_bounds.head_allows_revisit_s): what
part of a long gap is the PTS-303H's (tilt at 2 deg/s) and what part the fovea's schedule (issue 28)."""

import numpy as np
import pytest

from sim.sky_bounds import head_allows_revisit_s

T = np.round(0.1 * np.arange(1, 121), 10)      # frame end times of a 12 s run
LIMITS = (15.0, 2.0, 40.0, 10.0)               # pan, tilt top speeds [deg/s]; accelerations [deg/s^2]
HALF = 3.0


def _at(pan_deg, tilt_deg, r=30.0):
    p, t = np.radians(pan_deg), np.radians(tilt_deg)
    return np.stack([r * np.cos(t) * np.cos(p), r * np.cos(t) * np.sin(p), r * np.sin(t)], axis=-1)


def _drone(pan_deg, tilt_deg, first_s=0.1, present=None):
    xyz = np.repeat(_at(pan_deg, tilt_deg)[None, :], T.size, axis=0)
    field = np.ones(T.size, bool) if present is None else present
    xyz[~field] = np.nan
    return {"xyz_m": xyz, "in_field": field, "first_s": first_s}


def _bound(drones, pan0=0.0, tilt0=0.0):
    return head_allows_revisit_s(T, np.full(T.size, pan0), np.full(T.size, tilt0), drones, LIMITS, HALF)


def test_a_drone_on_the_axis_costs_nothing():
    b = _bound({"a": _drone(1.0, 1.0)})
    assert b["acquire_s"]["a"] == 0.0 and b["bound_s"] == 0.0 and b["pairs"] == {}


def test_the_tilt_at_2_deg_s_takes_3_5_s_to_bring_a_drone_10_deg_up_into_the_fovea():
    # (10 - 3) deg at 2 deg/s = 3.5 s: the first frame the tilt could have got there
    b = _bound({"a": _drone(0.0, 10.0)})
    assert b["acquire_s"]["a"] == pytest.approx(3.5)
    # the pan turns 7.5 times faster: 17 deg (20 less the fovea's 3 at the horizon) take 1.13 s
    assert _bound({"a": _drone(20.0, 0.0)})["acquire_s"]["a"] == pytest.approx(1.2)


def test_a_drone_the_head_cannot_reach_before_it_leaves_counts_its_whole_stay():
    present = T <= 2.0 + 1e-9
    b = _bound({"a": _drone(0.0, 10.0, present=present)})
    assert b["acquire_s"]["a"] == pytest.approx(2.0)     # frames 0.1 .. 2.0 all out of the fovea


def test_two_drones_30_deg_apart_in_pan_cannot_both_be_revisited_within_3_s():
    # 30 - 2 x 3.004 = 24.0 deg each way, from or to a stop: 24.0 / 15 + 15 / 80 = 1.79 s, there and
    # back 3.57 s; less the frame the sampling may hide, the longer of the two gaps is 3.5 s at least
    b = _bound({"a": _drone(-15.0, 0.0), "b": _drone(15.0, 0.0)})
    assert b["pairs"][("a", "b")] == pytest.approx(3.5)
    assert b["bound_s"] == pytest.approx(3.5)


def test_a_pair_seen_together_briefly_binds_only_as_far_as_its_stay():
    # 3 s together: a schedule need not go there and back within it; windows of 2 G + 2 frames fit
    # up to G = 1.4 s, so that is all the pair can bound
    present = (T > 1.0) & (T <= 4.0 + 1e-9)
    b = _bound({"a": _drone(-15.0, 0.0, first_s=1.1, present=present),
                "b": _drone(15.0, 0.0, first_s=1.1, present=present)})
    assert b["pairs"][("a", "b")] == pytest.approx(1.5)


def test_two_drones_the_fovea_holds_at_once_bind_nothing():
    b = _bound({"a": _drone(-2.0, 0.0), "b": _drone(2.0, 1.0)})
    assert b["pairs"][("a", "b")] == 0.0


def test_the_slow_tilt_binds_where_the_pan_would_not():
    # 10 deg apart in tilt: 4 deg each way beyond the fovea at 2 deg/s, 10 deg/s^2: 2.1 s, 4.2 s both
    b = _bound({"a": _drone(0.0, 0.0), "b": _drone(0.0, 10.0)})
    assert b["pairs"][("a", "b")] == pytest.approx(4.1)


def test_a_drone_never_confirmed_has_no_gap_to_bound():
    b = _bound({"a": _drone(0.0, 10.0, first_s=None), "b": _drone(0.0, 0.0)})
    assert "a" not in b["acquire_s"] and b["pairs"] == {}


def test_the_pair_bound_counts_its_smallest_window():
    # a trip there and back of 5 s in every window: even the smallest window (two frames) breaks
    # "twice the trip within G", so the bound is one frame, not none
    from sim.sky_bounds import _pair_bound_s

    for n in (2, 3, 4, 40):
        assert _pair_bound_s(np.full(n, 5.0), 0.1) >= 0.1 - 1e-12
    assert _pair_bound_s(np.full(1, 5.0), 0.1) == 0.0        # one frame: no window at all
    assert _pair_bound_s(np.zeros(10), 0.1) == 0.0           # no trip needed: no bound
