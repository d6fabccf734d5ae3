"""spline_rows_kernel (sim.world.kernels) against its twin: the clip, scipy's own evaluation of the
spline and its derivative, and the mask of the held ends (sim.world.trajectories.spline_rows under
numpy_paths), bit for bit, on the three kinds of cubic path and on the edges of their times."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from sim.world import trajectories as tr
from sim.world.kernels import spline_rows_kernel
from sim.world.sky import crown_sway


def _paths():
    manual = tr.Manual((20, 0, 5), 10.0, 15.0, 5.0, 10.0, seed=3)
    waypoints = tr.Waypoints(((10, 0, 2), (12, 5, 3), (15, 2, 4), (20, -3, 2)), 4.0)
    crown = crown_sway(np.random.default_rng(4), (30.0, 5.0, 8.0), 0.3, 0.1, 0.4, 20.0, 10.0)
    return [(manual, manual._spline, manual.duration_s), (waypoints, waypoints._spline, waypoints._t_end),
            (crown, crown._spline, crown.duration_s)]


def _times(spline, t_end, rng):
    x = spline.x
    edges = [0.0, -0.0, t_end, np.nextafter(t_end, np.inf), np.nextafter(t_end, -np.inf), np.nextafter(0.0, 1.0),
             -1e-300, -1.0, t_end + 5.0, np.nan, np.inf, -np.inf, float(x[-1]), float(x[1]), float(x[-2])]
    knots = x[rng.integers(0, x.size, 50)]          # on the breakpoints, and one ulp either side
    return [np.array([4.321]), np.array(edges), np.concatenate([knots, np.nextafter(knots, np.inf),
                                                                 np.nextafter(knots, -np.inf)]),
            rng.uniform(-1.0, t_end + 1.0, 2000), np.linspace(0.0, t_end, 997), np.zeros(0)]


def _same(a, b):
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("k", [0, 1, 2])
def test_the_kernel_gives_the_clip_scipy_and_the_mask_to_the_bit(k):
    path, spline, t_end = _paths()[k]
    rng = np.random.default_rng(17 + k)
    for t in _times(spline, t_end, rng):
        with tr.numpy_paths():
            want_p, want_v = tr.spline_rows(spline, t_end, t, True, True)
        # the twin is the code it replaces: the clip, scipy's call and the mask
        held = np.clip(t, 0.0, t_end)
        assert _same(want_p, spline(held)) and _same(want_v, np.where(((t < 0) | (t > t_end))[:, None], 0.0,
                                                                      spline(held, 1)))
        got_p, got_v = tr.spline_rows(spline, t_end, t, True, True)
        assert _same(got_p, want_p) and _same(got_v, want_v)
        # one of the two asked for
        assert _same(tr.spline_rows(spline, t_end, t, True, False)[0], want_p)
        assert _same(tr.spline_rows(spline, t_end, t, False, True)[1], want_v)
        # the paths' methods, kernel and numpy alike
        for plain in (False, True):
            with tr.numpy_paths() if plain else _nothing():
                assert _same(path.position(t), want_p) and _same(path.velocity(t), want_v)
                p, v = tr.position_velocity(path, t)
                assert _same(p, want_p) and _same(v, want_v)


def test_the_kernel_on_random_splines_and_a_clip_inside_or_past_the_last_breakpoint():
    """Random coefficients (signs, magnitudes, zeros) and a hold time before or after the last
    breakpoint (past it the last piece extrapolates, as scipy's evaluation does)."""
    rng = np.random.default_rng(5)
    for trial in range(40):
        n = int(rng.integers(2, 40))
        x = np.cumsum(rng.uniform(1e-3, 2.0, n)) - rng.uniform(0.0, 0.5)
        x[0] = min(x[0], 0.0) if trial % 2 else x[0]
        y = rng.normal(0.0, 10.0 ** rng.uniform(-3, 3), (n, 3))
        if trial % 5 == 0:
            y[:, 1] = 0.0
        spline = CubicSpline(x, y, axis=0, bc_type="clamped" if trial % 3 == 0 else "not-a-knot")
        t_end = float(x[-1] + rng.uniform(-0.5, 0.5))
        t = np.concatenate([rng.uniform(x[0] - 1.0, x[-1] + 1.0, 300), x, [np.nan, -0.0, t_end]])
        want_p = spline(np.clip(t, 0.0, t_end))
        want_v = spline(np.clip(t, 0.0, t_end), 1)
        want_v[(t < 0) | (t > t_end)] = 0.0
        p = np.empty((t.size, 3))
        v = np.empty((t.size, 3))
        spline_rows_kernel(spline._c, spline._x, t, t_end, p, v)
        assert _same(p, want_p) and _same(v, want_v), trial


class _nothing:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False
