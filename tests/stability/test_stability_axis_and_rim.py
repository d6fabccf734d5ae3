"""The two singular places of the rosette: the optical axis (density singularity at r = 0, paper
eq. 4 / Fig. 5) and the rim of the FoV (r = 2R, the other divergence of eq. 4).

Bounds asserted
---------------
* prisms exactly opposed (relative phase 1/2 rev) cancel: the exact beam is on axis to 1e-12 rad,
  the paraxial one to 1e-15, and both are unit vectors (no 0/0 in the paraxial sin(g)/g);
* prisms aligned put the beam on the rim: the same off-axis angle at every common phase (1e-12),
  and no random phase pair exceeds it; for the prototype it is the facts file's 19.22 deg;
* the eq. (4) bin fraction of the first bin [0, e] is finite and within
  [e / (pi R), e / (2R)] (the density diverges, its integral does not); the last bin before the rim
  is <= (2/pi) acos(1 - d / 2R) (d = bin width, plus 2 ulp of the argument: asin's slope is
  infinite at 1); all fractions sum to 1;
* the simulated radial density of a short scan is finite in every bin, including the first.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from sim.scan.density import analytic_bin_fraction, radial_density
from sim.scan.model import ScanModel
from sim.scan.optics import Prism, RisleyOptics
from sim.scan.presets import PROTOTYPE
from stability_util import examples

_EXACT = ScanModel(PROTOTYPE)
_PARAXIAL = ScanModel(PROTOTYPE, model="paraxial")


def _off_axis_rad(direction):
    d = np.atleast_2d(direction)
    return np.arctan2(np.hypot(d[:, 1], d[:, 2]), d[:, 0])


@examples(100)
@given(st.lists(st.floats(0.0, 1.0, exclude_max=True), min_size=1, max_size=64))
def test_opposed_prisms_put_the_beam_exactly_on_axis(phases):
    """Identical prisms with facing tilted faces, turned half a revolution apart: the second prism's
    tilted face is parallel to the first's, so the beam leaves along the axis (the fovea centre)."""
    r1 = np.array(phases)
    revs = np.column_stack([r1, (r1 + 0.5) % 1.0])
    ch = np.zeros(len(r1), np.int64)
    for model, tol in ((_EXACT, 1e-12), (_PARAXIAL, 1e-15)):
        d, status = model.directions_from_revs(revs, ch)
        assert np.all(status == 0)
        assert np.isfinite(d).all()
        assert np.all(np.abs(np.linalg.norm(d, axis=1) - 1.0) <= 1e-15 + tol)
        assert np.all(_off_axis_rad(d) <= tol)


def test_paraxial_exact_zero_deviation_is_the_axis():
    """Paraxial g = 0 exactly (sin g / g would be 0/0): the kernel's branch returns (1, 0, 0)."""
    d, _ = _PARAXIAL.directions_from_revs(np.array([[0.0, 0.5], [0.25, 0.75]]), np.zeros(2, np.int64))
    assert np.array_equal(d, np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))


@examples(60)
@given(st.lists(st.floats(0.0, 1.0, exclude_max=True), min_size=2, max_size=64),
       st.integers(0, 2**32 - 1))
def test_aligned_prisms_put_the_beam_on_the_rim(phases, seed):
    """Aligned prisms (equal phases) give the largest deflection, the same at every common phase
    (rotational symmetry); random phase pairs never exceed it.  Prototype: 19.22 deg (facts)."""
    r = np.array(phases)
    d, status = _EXACT.directions_from_revs(np.column_stack([r, r]), np.zeros(len(r), np.int64))
    assert np.all(status == 0)
    rim = _off_axis_rad(d)
    assert np.ptp(rim) <= 1e-12
    assert abs(math.degrees(rim[0]) - 19.22) < 0.01
    other = np.random.default_rng(seed).random((2000, 2))
    d2, s2 = _EXACT.directions_from_revs(other, np.zeros(2000, np.int64))
    assert np.all(s2 == 0)
    assert np.all(_off_axis_rad(d2) <= rim.max() + 1e-12)


@examples(100)
@given(st.floats(1e-300, 1.0), st.floats(0.01, 60.0))
def test_first_bin_fraction_is_finite_and_bounded(first_edge_frac, r_scale):
    """The density diverges like 1/r at r = 0 but its integral over [0, e] is (2/pi) asin(e/2R):
    finite and between e/(pi R) and e/(2R) (asin x is between x and pi x / 2 on [0, 1])."""
    e = first_edge_frac * 2.0 * r_scale
    edges = np.array([0.0, e, 2.0 * r_scale])
    f = analytic_bin_fraction(edges, r_scale)
    assert np.isfinite(f).all() and np.all(f >= 0)
    lo, hi = e / (math.pi * r_scale), e / (2.0 * r_scale)
    assert lo * (1 - 1e-12) <= f[0] <= hi * (1 + 1e-12)
    assert abs(f.sum() - 1.0) <= 1e-12


@examples(100)
@given(st.floats(1e-12, 0.5), st.floats(0.01, 60.0), st.integers(2, 400))
def test_rim_bin_fraction_is_finite_and_bounded(width_frac, r_scale, bins):
    """The other divergence of eq. (4), at r = 2R: the last bin's fraction is finite and at most
    (2/pi) acos(1 - d/2R); bins beyond the rim (the simulated histogram pads 6 %) hold exactly 0."""
    rim = 2.0 * r_scale
    d = width_frac * rim
    edges = np.concatenate([np.linspace(0.0, rim - d, bins), [rim, rim * 1.03, rim * 1.06]])
    f = analytic_bin_fraction(edges, r_scale)
    assert np.isfinite(f).all() and np.all(f >= 0)
    # the bound on the edges as stored (rim - d rounds), plus 2 ulp for the division r / 2R: asin's
    # slope is infinite at 1, so an ulp of its argument is worth 1e-16 / sqrt(2 d / rim) here
    d_act = rim - edges[-4]
    assert f[-3] <= 2.0 / math.pi * math.acos(1.0 - (d_act / rim + 4.5e-16)) * (1 + 1e-12)
    assert np.all(f[-2:] == 0.0)
    assert abs(f.sum() - 1.0) <= 1e-12


def test_simulated_density_is_finite_at_the_centre_and_rim():
    """A short scan (20 ms, 2000 points) histogrammed from r = 0: every bin finite, first included."""
    for model in (_EXACT, _PARAXIAL):
        rd = radial_density(model, 0.02, bins=30)
        assert rd.points == 2000
        assert np.isfinite(rd.simulated).all() and np.isfinite(rd.analytic).all()
        assert rd.analytic[0] > 0 and np.isfinite(rd.analytic[0])


def test_unequal_prisms_leave_a_hole_not_a_nan():
    """Unequal deviations leave a central blind cone (facts: half-angle ~ |d1 - d2|): opposed prisms
    give the hole's edge, a finite non-zero off-axis angle, not a NaN or a zero."""
    optics = RisleyOptics(prisms=(Prism(18.0, 1.51, "exit", 7294.0), Prism(15.0, 1.51, "entry", -4664.0)))
    d, s = ScanModel(optics).directions_from_revs(np.array([[0.1, 0.6]]), np.zeros(1, np.int64))
    hole = math.degrees(_off_axis_rad(d)[0])
    thin = (1.51 - 1) * 3.0
    assert s[0] == 0 and 0.5 * thin < hole < 2.0 * thin
