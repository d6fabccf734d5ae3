"""Trajectories: defining properties (derivatives, bounds, waypoints, determinism)."""

import contextlib
import math

import numpy as np

from sim.world import trajectories as tr


def _numeric_velocity(traj, t, h=1e-5):
    return (traj.position(t + h) - traj.position(t - h)) / (2 * h)


def test_velocity_is_the_derivative_of_position_for_every_kind():
    t = np.linspace(0.5, 9.5, 50)
    kinds = [
        tr.Straight((10, 2, 1), (0, -3, 0.5)),
        tr.Circle((0, 0, 20), 50.0, 12.0, 30.0),
        tr.FigureEight((30, 0, 10), 5.0, 8.0),
        tr.Waypoints(((10, 0, 2), (12, 5, 3), (15, 2, 4), (20, -3, 2)), 4.0),
        tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 10.0, seed=3),
    ]
    for traj in kinds:
        np.testing.assert_allclose(traj.velocity(t), _numeric_velocity(traj, t), atol=1e-4, err_msg=type(traj).__name__)


def test_manual_flight_is_bounded_seeded_and_deterministic():
    a = tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 60.0, seed=9)
    b = tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 60.0, seed=9)
    c = tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 60.0, seed=10)
    t = np.linspace(0, 60, 3001)
    assert np.array_equal(a.position(t), b.position(t))
    assert not np.allclose(a.position(t), c.position(t))
    speed = np.linalg.norm(a.velocity(t), axis=1)
    assert speed.max() <= 15.0 * 1.02  # spline between clipped 20 ms samples
    assert np.linalg.norm(a.position(t) - np.array([20, 0, 5]), axis=1).max() < 10.0 + 15.0**2 / (2 * 5.0) + 0.5


def test_waypoints_are_passed_and_held_at_the_end():
    pts = ((10, 0, 2), (12, 5, 3), (15, 2, 4))
    w = tr.Waypoints(pts, 2.0)
    seg = np.linalg.norm(np.diff(np.array(pts, float), axis=0), axis=1)
    times = np.concatenate([[0], np.cumsum(seg / 2.0)])
    np.testing.assert_allclose(w.position(times), pts, atol=1e-9)
    np.testing.assert_allclose(w.position(np.array([times[-1] + 5])), [pts[-1]], atol=1e-9)
    assert np.all(w.velocity(np.array([times[-1] + 5])) == 0)


def test_circle_speed_and_heading():
    c = tr.Circle((0, 0, 0), 20.0, 5.0)
    t = np.linspace(0, 30, 100)
    np.testing.assert_allclose(np.linalg.norm(c.velocity(t), axis=1), 5.0)
    np.testing.assert_allclose(np.linalg.norm(c.position(t)[:, :2], axis=1), 20.0)
    yaw = tr.heading_rad(c.velocity(np.array([0.0])))
    assert abs(yaw[0] - np.pi / 2) < 1e-12  # counter-clockwise: heading +y at angle 0


def _wrap_deg(a):
    return (np.degrees(a) + 180.0) % 360.0 - 180.0


def test_a_body_that_stops_keeps_its_heading():
    """A waypoint flight heading +y slows to rest at its last waypoint: the body's yaw stays near 90 deg
    through the stop and while it hovers (it snapped to 0 below 1e-4 m/s: a 90 deg turn in one step)."""
    w = tr.Waypoints(((10, -5, 2), (10, 5, 2)), 2.0)           # along +y, clamped: v = 0 at both ends
    t = np.linspace(-1.0, w._t_end + 10.0, 4001)
    yaw = tr.body_yaw_rad(w, t)
    assert np.all(np.abs(_wrap_deg(yaw) - 90.0) < 1e-6)       # before the start too: the heading it will have
    assert np.max(np.abs(_wrap_deg(np.diff(yaw)))) < 1e-6


def test_body_yaw_is_a_function_of_the_time_alone():
    """However the run is cut into frames, each point's yaw is the same (hover lookup on absolute times)."""
    m = tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 6.0, seed=3)    # flies 6 s, then hovers
    t = np.sort(np.random.default_rng(1).uniform(0.0, 12.0, 3000))
    whole = tr.body_yaw_rad(m, t)
    pieces = np.concatenate([tr.body_yaw_rad(m, c) for c in np.array_split(t, 37)])
    assert np.array_equal(whole, pieces)
    moving = np.linalg.norm(m.velocity(t)[:, :2], axis=1) > 1e-4
    assert np.array_equal(whole[moving], tr.heading_rad(m.velocity(t[moving])))   # moving: the old heading, bit for bit
    hover = t > 6.0
    assert np.ptp(whole[hover]) == 0.0      # one heading while it hovers


def test_near_zero_and_zero_speed_give_a_steady_yaw():
    for v in ((0.0, 0.0, 0.0), (0.0, 1e-5, 0.0), (0.0, 0.0, 0.3)):    # at rest, creeping, climbing
        yaw = tr.body_yaw_rad(tr.Straight((10, 0, 2), v), np.linspace(0, 20, 400))
        assert np.all(yaw == 0.0) and np.all(np.isfinite(yaw))


def test_circle_columns_are_the_stacked_forms_to_the_bit():
    """Circle builds its (N, 3) arrays column by column: each element as numpy's stacked form,
    ``centre + radius * [cos, sin, 0]`` and ``speed * [-sin, cos, 0]``, and ``position_velocity``
    gives the two at once, the same bits."""
    t = np.concatenate([np.random.default_rng(4).uniform(-10.0, 200.0, 1000), [0.0, -0.0, 1e9]])
    for c in (tr.Circle((40.0, 0.0, 6.0), 12.0, 8.0), tr.Circle((0, -3, -0.0), 50, -12.5, 30.0),
              tr.Circle((1.5, 2.5, 3.5), 0.7, 3.0, -400.0), tr.Circle((-0.0, 1.0, 2.0), -3.0, 0.0, 10.0)):
        ph = math.radians(c.start_deg) + t.reshape(-1, 1) * (c.speed_m_s / c.radius_m)
        p = np.asarray(c.centre_m) + c.radius_m * np.hstack([np.cos(ph), np.sin(ph), np.zeros_like(ph)])
        v = c.speed_m_s * np.hstack([-np.sin(ph), np.cos(ph), np.zeros_like(ph)])
        for plain in (False, True):        # circle_rows_kernel, and numpy's columns
            with tr.numpy_paths() if plain else contextlib.nullcontext():
                both = c.position_velocity(t)
                for got, want in ((c.position(t), p), (c.velocity(t), v), (both[0], p), (both[1], v)):
                    assert got.shape == want.shape and np.array_equal(got.view(np.int64), want.view(np.int64))
    s = tr.Straight((10, 2, 1), (0, -3, 0.5))      # no position_velocity of its own: the two calls
    pv = tr.position_velocity(s, t)
    assert np.array_equal(pv[0], s.position(t)) and np.array_equal(pv[1], s.velocity(t))


def test_straight_velocity_fills_every_row_either_way():
    """Few rows take one broadcast, many take three column fills: every row is the velocity."""
    s = tr.Straight((10, 2, 1), (0.25, -3.0, -0.0))
    for n in (0, 1, tr._ROWS_BROADCAST_MAX, tr._ROWS_BROADCAST_MAX + 1, 5000):
        v = s.velocity(np.linspace(0.0, 1.0, n))
        assert v.shape == (n, 3) and np.array_equal(v.view(np.int64), np.tile(s._velocity, (n, 1)).view(np.int64))


def test_spline_paths_evaluate_as_the_spline_call_to_the_bit():
    """spline_at (scipy's evaluation without the call's wrapping) gives the call's bits, position and
    velocity, inside the path, at its ends, past them and on one time or many."""
    from sim.world.sky import crown_sway

    manual = tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 10.0, seed=3)
    waypoints = tr.Waypoints(((10, 0, 2), (12, 5, 3), (15, 2, 4), (20, -3, 2)), 4.0)
    crown = crown_sway(np.random.default_rng(4), (30.0, 5.0, 8.0), 0.3, 0.1, 0.4, 20.0, 10.0)
    times = [np.array([4.321]), np.linspace(-1.0, 12.0, 997), np.array([0.0, 10.0, 0.02, 3.3])]
    for spline in (manual._spline, waypoints._spline, crown._spline):
        for t in times:
            for nu in (0, 1):
                got, want = tr.spline_at(spline, t, nu), spline(t, nu)
                assert got.shape == want.shape and got.dtype == want.dtype
                assert got.tobytes() == want.tobytes()
    for t in times:     # a manual path's position and velocity in one evaluation: the two calls' bits
        p, v = tr.position_velocity(manual, t)
        assert p.tobytes() == manual.position(t).tobytes() and v.tobytes() == manual.velocity(t).tobytes()
        assert tr.body_yaw_rad(manual, t, v).tobytes() == tr.body_yaw_rad(manual, t).tobytes()
