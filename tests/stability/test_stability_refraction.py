"""Exact refraction at its hard edges: grazing incidence, just short of / just past total internal
reflection (TIR), and rotational symmetry, for the numba kernel and its numpy twin.

The kernel is :func:`sim.scan.kernels.trace_exact_kernel` (vector Snell, facts file
"Exact refraction"; paper Appendix B); the twin is ``tests/scan_twins.trace_exact_twin``.  A third,
instrumented reference here (:func:`_trace_margins`) also reports, per ray, how close it came to a
status boundary (smallest cos(theta_i) and smallest TIR radicand over its faces), so that the only
disagreements tolerated are the ones rounding can legitimately flip: a ray within 1e-12 of a
boundary.

Bounds asserted
---------------
* status is RAY_OK / RAY_TIR / RAY_GRAZING, never anything else; no NaN or inf ever comes out;
* a NaN or infinite prism angle: RAY_INVALID with a (0, 0, 0) direction; the rays beside it unchanged;
* valid rays are unit vectors to 1e-12; invalid rays are exactly (0, 0, 0);
* kernel and twin agree on the status of every ray farther than 1e-12 from a boundary, and on the
  direction to 1e-12 (4e-8 when the TIR radicand is below 1e-6, where sqrt amplifies rounding:
  sqrt(1e-15) = 3.2e-8);
* at one exit face with incidence alpha: Snell holds, |t x m| = n sin(alpha) to 1e-13; the exit
  direction tends continuously to the grazing direction as alpha -> alpha_c,
  angle <= asin(sqrt(k)) + (alpha_c - alpha) + 3e-8; one step past alpha_c (1e-12 rad) is TIR.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import assume, event, given
from hypothesis import strategies as st

from scan_twins import trace_exact_twin
from sim.scan import kernels
from sim.scan.kernels import RAY_GRAZING, RAY_INVALID, RAY_OK, RAY_TIR, trace_exact_kernel
from sim.scan.model import ScanModel
from sim.scan.optics import Prism, RisleyOptics
from stability_util import angle_between, examples

STATUSES = (RAY_OK, RAY_TIR, RAY_GRAZING)


def _run_kernel(revs_np, channel, incident, wedge_deg, index, exit_tilted):
    """Call the kernel with (N, P) revs; returns (direction (N,3) lidar frame, status (N,))."""
    n = revs_np.shape[0]
    out = np.empty((n, 3))
    status = np.empty(n, dtype=np.uint8)
    trace_exact_kernel(np.ascontiguousarray(revs_np.T), np.ascontiguousarray(channel, dtype=np.int64),
                       np.ascontiguousarray(incident), np.sin(np.radians(wedge_deg)),
                       np.cos(np.radians(wedge_deg)), np.asarray(index, float),
                       np.asarray(exit_tilted, bool), out, status)
    return out, status


def _run_twin(revs_np, channel, incident, wedge_deg, index, exit_tilted):
    return trace_exact_twin(revs_np, np.asarray(channel, np.int64), incident, np.sin(np.radians(wedge_deg)),
                            np.cos(np.radians(wedge_deg)), np.asarray(index, float), np.asarray(exit_tilted, bool))


def _trace_margins(revs_np, channel, incident, wedge_deg, index, exit_tilted):
    """Reference trace (optics frame) that also returns each ray's distance to a status boundary:
    min over faces of cos(theta_i) (grazing at <= 0) and of the radicand k (TIR at < 0), taken only
    over the faces the ray reached while still valid."""
    n, p_count = revs_np.shape
    d = incident[channel].astype(float)
    min_ci = np.full(n, np.inf)
    min_k = np.full(n, np.inf)
    alive = np.ones(n, bool)
    sa_all, ca_all = np.sin(np.radians(wedge_deg)), np.cos(np.radians(wedge_deg))
    for p in range(p_count):
        th = 2 * np.pi * revs_np[:, p]
        sa, ca = sa_all[p], ca_all[p]
        sign = -1.0 if exit_tilted[p] else 1.0
        tilted = np.column_stack([sign * sa * np.cos(th), sign * sa * np.sin(th), np.full(n, ca)])
        flat = np.tile([0.0, 0.0, 1.0], (n, 1))
        faces = [(flat, 1 / index[p]), (tilted, index[p])] if exit_tilted[p] else \
            [(tilted, 1 / index[p]), (flat, index[p])]
        for m, eta in faces:
            ci = np.einsum("ij,ij->i", d, m)
            k = 1 - eta * eta * (1 - ci * ci)
            min_ci = np.where(alive, np.minimum(min_ci, np.abs(ci)), min_ci)
            min_k = np.where(alive & (ci > 0), np.minimum(min_k, np.abs(k)), min_k)
            alive &= (ci > 0) & (k >= 0)
            d = eta * d - (eta * ci - np.sqrt(np.maximum(k, 0)))[:, None] * m
    return min_ci, min_k


def _incident(polar_deg, azim_deg):
    ph, ps = np.radians(polar_deg), np.radians(azim_deg)
    v = np.column_stack([np.sin(ph) * np.cos(ps), np.sin(ph) * np.sin(ps), np.cos(ph)])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


special_revs = st.sampled_from([0.0, 0.25, 0.5, 0.75, 1 - 2**-53, 2**-40])
revs_value = st.one_of(st.floats(0.0, 1.0, exclude_max=True), special_revs)


@st.composite
def prism_stacks(draw):
    p = draw(st.integers(1, 3))
    wedge = np.array(draw(st.lists(st.floats(0.5, 59.5), min_size=p, max_size=p)))
    index = np.array(draw(st.lists(st.floats(1.0001, 4.0), min_size=p, max_size=p)))
    tilted = np.array(draw(st.lists(st.booleans(), min_size=p, max_size=p)))
    channels = draw(st.integers(1, 3))
    polar = draw(st.lists(st.one_of(st.floats(0.0, 100.0), st.sampled_from([0.0, 89.999999, 90.0])),
                          min_size=channels, max_size=channels))
    azim = draw(st.lists(st.floats(-180.0, 180.0), min_size=channels, max_size=channels))
    n = 32
    revs = np.array(draw(st.lists(revs_value, min_size=n * p, max_size=n * p))).reshape(n, p)
    channel = np.array(draw(st.lists(st.integers(0, channels - 1), min_size=n, max_size=n)))
    incident = _incident(np.array(polar), np.array(azim))
    incident[np.array(polar) == 90.0, 2] = 0.0  # exactly in the face: grazing, not 6e-17
    return revs, channel, incident, wedge, index, tilted


@examples(150)
@given(prism_stacks())
def test_any_stack_status_norm_and_twin_agreement(stack):
    """Random stacks of 1-3 prisms (wedges up to 59.5 deg, n up to 4, incidence up to 100 deg off
    axis): valid rays are unit vectors, invalid ones zero, nothing is NaN, and kernel == twin away
    from the status boundaries."""
    revs, channel, incident, wedge, index, tilted = stack
    d_k, s_k = _run_kernel(revs, channel, incident, wedge, index, tilted)
    d_t, s_t = _run_twin(revs, channel, incident, wedge, index, tilted)
    min_ci, min_k = _trace_margins(revs, channel, incident, wedge, index, tilted)

    assert np.isin(s_k, STATUSES).all()
    event(f"statuses seen: {sorted(set(s_k.tolist()))}")
    event(f"rays within 1e-6 of TIR: {bool((min_k < 1e-6).any())}")
    assert np.isfinite(d_k).all() and np.isfinite(d_t).all()
    ok = s_k == RAY_OK
    assert np.all(np.abs(np.linalg.norm(d_k[ok], axis=1) - 1.0) <= 1e-12)
    assert np.all(d_k[~ok] == 0.0)

    near = (min_ci < 1e-12) | (min_k < 1e-12)
    assert np.array_equal(s_k[~near], s_t[~near]), (s_k[~near], s_t[~near])
    both = ok & (s_t == RAY_OK)
    tol = np.where(min_k[both] < 1e-6, 4e-8, 1e-12)
    assert np.all(np.max(np.abs(d_k[both] - d_t[both]), axis=1) <= tol)


@examples(100)
@given(st.floats(1.0001, 4.0), st.floats(0.0, 1.0, exclude_max=True),
       st.floats(-14.0, -1.0).map(lambda e: 10.0**e))
def test_tir_limit_at_one_exit_face(n, rev, delta):
    """One exit-tilted prism, normal incidence: the exit face sees incidence alpha = wedge.
    Just short of the critical angle the ray leaves, obeys Snell and approaches the grazing
    direction continuously; just past it the ray is TIR, with a zero direction."""
    alpha_c = math.asin(1.0 / n)
    assume(alpha_c + delta < math.radians(89.0))
    revs = np.array([[rev]])
    inc = np.array([[0.0, 0.0, 1.0]])
    ch = np.zeros(1, np.int64)

    def face(alpha):
        th = 2 * math.pi * rev
        return np.array([-math.sin(alpha) * math.cos(th), -math.sin(alpha) * math.sin(th), math.cos(alpha)])

    # just past: TIR (n sin(alpha) - 1 ~ n cos(alpha_c) delta >= 1e-14, far above rounding)
    for fn in (_run_kernel, _run_twin):
        d, s = fn(revs, ch, inc, np.array([math.degrees(alpha_c + max(delta, 1e-12))]), [n], [True])
        assert s[0] == RAY_TIR and np.all(d == 0.0)

    alpha = alpha_c - max(delta, 1e-12)
    wedge = np.array([math.degrees(alpha)])
    alpha = math.radians(wedge[0])  # the angle the kernel actually sees
    d_k, s_k = _run_kernel(revs, ch, inc, wedge, [n], [True])
    d_t, s_t = _run_twin(revs, ch, inc, wedge, [n], [True])
    assert s_k[0] == RAY_OK and s_t[0] == RAY_OK
    t = d_k[0][[1, 2, 0]]  # lidar (X, Y, Z) -> optics (x, y, z)
    m = face(alpha)
    assert abs(np.linalg.norm(t) - 1.0) <= 1e-12
    # Snell: sin(theta_t) = n sin(alpha)
    assert abs(np.linalg.norm(np.cross(t, m)) - n * math.sin(alpha)) <= 1e-13
    # Continuity toward the grazing exit direction at alpha_c (tangent to the face, in the plane of
    # incidence): the angle to it shrinks like sqrt(k) + (alpha_c - alpha).
    mc = face(alpha_c)
    z = np.array([0.0, 0.0, 1.0])
    g = z - mc * (z @ mc)
    g /= np.linalg.norm(g)
    k = max(1.0 - n * n * math.sin(alpha) ** 2, 0.0)
    bound = math.asin(math.sqrt(k)) + (alpha_c - alpha) + 3e-8
    assert angle_between(t, g)[0] <= bound
    assert np.max(np.abs(d_k - d_t)) <= (4e-8 if k < 1e-6 else 1e-12)


@examples(60)
@given(st.floats(0.0, 1e-3), st.floats(-180.0, 180.0), st.floats(1.0001, 4.0), st.booleans())
def test_grazing_incidence_on_the_first_face(dz, azim_deg, n, exit_tilted):
    """An incident beam in (dz = 0) or barely above the first face: dz = 0 is RAY_GRAZING with a zero
    direction; dz > 0 never produces NaN and is either a unit vector or a reported failure."""
    az = math.radians(azim_deg)
    v = np.array([[math.cos(az), math.sin(az), dz]])
    v /= np.linalg.norm(v)
    revs = np.array([[0.0], [0.3], [0.7]])
    ch = np.zeros(3, np.int64)
    wedge = np.array([10.0])
    incident = v
    if not exit_tilted:
        # the first face is the tilted one: put the beam in that face's plane (rev 0 -> normal
        # (sin a, 0, cos a)), so grazing is reached through the tilted normal instead
        a = math.radians(wedge[0])
        m = np.array([math.sin(a), 0.0, math.cos(a)])
        e1 = np.cross(m, [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        incident = (math.cos(az) * e1 + math.sin(az) * np.cross(m, e1) + dz * m)[None, :]
        incident /= np.linalg.norm(incident)
        revs = np.zeros((3, 1))
    d, s = _run_kernel(revs, ch, incident, wedge, [n], [exit_tilted])
    dt, stw = _run_twin(revs, ch, incident, wedge, [n], [exit_tilted])
    assert np.isfinite(d).all() and np.isfinite(dt).all()
    if dz == 0.0 and exit_tilted:
        assert np.all(s == RAY_GRAZING) and np.all(d == 0.0)
        assert np.all(stw == RAY_GRAZING)
    ok = s == RAY_OK
    assert np.all(np.abs(np.linalg.norm(d[ok], axis=1) - 1.0) <= 1e-12)
    assert np.all(d[~ok] == 0.0)


@examples(80)
@given(st.lists(revs_value, min_size=2, max_size=2), st.floats(0.0, 1.0, exclude_max=True),
       st.floats(20.0, 40.0), st.sampled_from([("exit", "entry"), ("exit", "exit"), ("entry", "entry")]))
def test_rotating_both_prisms_rotates_the_beam(revs2, shift, wedge, faces):
    """Rotational symmetry of a two-prism stack (paper Fig. 3): turning both prisms by the same angle
    keeps each ray's status and turns its direction about the optical axis by that angle (to 1e-12),
    also for wedges large enough (up to 40 deg, n = 1.51) that some relative phases are TIR."""
    wedges = np.array([wedge, wedge])
    idx = [1.51, 1.51]
    tilted = [f == "exit" for f in faces]
    revs = np.array([revs2])
    rot = (revs + shift) % 1.0
    inc = np.array([[0.0, 0.0, 1.0]])
    ch = np.zeros(1, np.int64)
    d0, s0 = _run_kernel(revs, ch, inc, wedges, idx, tilted)
    d1, s1 = _run_kernel(rot, ch, inc, wedges, idx, tilted)
    min_ci, min_k = _trace_margins(revs, ch, inc, wedges, idx, tilted)
    if min(min_ci[0], min_k[0]) < 1e-9:
        return  # a boundary ray: a 1e-16 rev rounding of the shift may flip it
    assert s0[0] == s1[0]
    if s0[0] != RAY_OK:
        assert np.all(d0 == 0) and np.all(d1 == 0)
        return
    a = 2 * math.pi * shift
    c, s = math.cos(a), math.sin(a)
    # lidar Y = optics x, Z = optics y: rotate (Y, Z) by +a
    expect = np.array([d0[0, 0], c * d0[0, 1] - s * d0[0, 2], s * d0[0, 1] + c * d0[0, 2]])
    tol = 4e-8 if min_k[0] < 1e-6 else 1e-12
    assert np.max(np.abs(d1[0] - expect)) <= tol


def test_scan_model_reports_tir_instead_of_nan():
    """A user-configurable stack (wedge 45 deg, n = 1.51: n sin 45 = 1.07 > 1) is TIR at every phase:
    ScanModel says so per ray (status RAY_TIR, zero direction, no NaN) and the FoV analysis refuses
    with a message instead of returning a number."""
    import pytest

    from sim.scan.fov import field_of_view_deg

    optics = RisleyOptics(prisms=(Prism(45.0, 1.51, "exit", 6000.0), Prism(45.0, 1.51, "entry", -4000.0)))
    chunk = ScanModel(optics).scan(0, 5000)
    assert np.all(chunk.status == kernels.RAY_TIR)
    assert np.all(chunk.direction == 0.0)
    with pytest.raises(ValueError, match="totally reflected"):
        field_of_view_deg(optics, samples=2000)


def test_mixed_stack_has_both_statuses_and_only_valid_rays_count():
    """Wedge 35 deg, n = 1.51, both exit faces tilted: some relative phases are TIR, others pass.  The
    valid fraction is strictly between 0 and 1 (measured 0.58), and the paraxial model (which has no
    TIR) stays valid everywhere."""
    optics = RisleyOptics(prisms=(Prism(35.0, 1.51, "exit", 6000.0), Prism(35.0, 1.51, "exit", -4100.0)))
    chunk = ScanModel(optics).scan(0, 20_000)
    frac = chunk.valid.mean()
    assert 0.3 < frac < 0.8
    assert set(np.unique(chunk.status)) <= {RAY_OK, RAY_TIR}
    assert np.all(np.abs(np.linalg.norm(chunk.direction[chunk.valid], axis=1) - 1) <= 1e-12)
    par = ScanModel(optics, model="paraxial").scan(0, 20_000)
    assert par.valid.all() and np.all(np.abs(np.linalg.norm(par.direction, axis=1) - 1) <= 1e-12)


# ------------------------------------------------------------------------------------------------
# prism angles that are not numbers


@examples(40)
@given(st.integers(0, 2**32 - 1), st.sampled_from([math.nan, math.inf, -math.inf]), st.booleans())
def test_non_finite_prism_angles_are_invalid_rays_not_ok_nans(seed, bad, second_prism):
    """A NaN or infinite prism angle gives RAY_INVALID and a (0, 0, 0) direction (802524f: RAY_OK with
    a NaN direction), in the kernel and its twin; the finite rays beside
    them are the same bits as when traced alone."""
    rng = np.random.default_rng(seed)
    n = 64
    revs = rng.uniform(0, 1, (n, 2))
    bad_rows = rng.random(n) < 0.3
    revs_bad = revs.copy()
    revs_bad[bad_rows, int(second_prism)] = bad
    args = (np.zeros(n, np.int64), np.array([[0.0, 0.0, 1.0]]), np.array([18.0, 18.0]), [1.51, 1.51],
            [True, False])
    d_k, s_k = _run_kernel(revs_bad, *args)
    with np.errstate(invalid="ignore"):     # numpy's cos and sin of the non-finite angles warn
        d_t, s_t = _run_twin(revs_bad, *args)
    assert np.all(s_k[bad_rows] == RAY_INVALID) and np.all(s_t[bad_rows] == RAY_INVALID)
    assert np.all(d_k[bad_rows] == 0.0) and np.all(d_t[bad_rows] == 0.0)
    assert np.all(np.isfinite(d_k)) and np.all(np.isfinite(d_t))
    d_ok, s_ok = _run_kernel(revs, *args)
    assert np.array_equal(d_k[~bad_rows].view(np.int64), d_ok[~bad_rows].view(np.int64))
    assert np.array_equal(s_k[~bad_rows], s_ok[~bad_rows])
