"""Trajectories: defining properties (derivatives, bounds, waypoints, determinism)."""

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
