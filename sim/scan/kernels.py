"""Numba kernels of the scan model: every hot loop of ``sim.scan`` and nothing else.

Each kernel takes arrays and scalars only, writes into caller-provided outputs, and has a plain-numpy
twin in ``tests/scan_twins.py``; the tests compare the two to 1e-12 (stumpy's layout, see
``shared/DESIGN.md``).  ``NUMBA_DISABLE_JIT=1`` runs them as Python so coverage can see inside.

Ray status codes (per ray, never a silent NaN):

* ``RAY_OK`` (0): the ray left the last prism; its direction is valid.
* ``RAY_TIR`` (1): total internal reflection at some face: the radicand
  :math:`1 - \\eta^2 (1 - \\cos^2\\theta_i)` was negative.  Direction is set to (0, 0, 0).
* ``RAY_GRAZING`` (2): the ray met a face at or past grazing incidence
  (:math:`\\cos\\theta_i \\le 0`): it does not reach that face from the right side.
* ``RAY_INVALID`` (3): the ray could not be traced: a prism angle (or an input) was NaN or infinite,
  so neither test above could decide.  Direction is set to (0, 0, 0), never NaN.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

RAY_OK = 0
RAY_TIR = 1
RAY_GRAZING = 2
RAY_INVALID = 3

TWO_PI = 2.0 * math.pi
_SPLIT_BITS = 26
_SPLIT_MASK = (1 << _SPLIT_BITS) - 1
_TWO_26 = float(1 << _SPLIT_BITS)


# Exact-arithmetic helpers pin ``fastmath=False``: numba lets a callee that leaves an option unset
# inherit it from its caller (``Flags.inherit_if_not_set("fastmath")``), so called from a fastmath
# kernel they would be compiled (and cached) with reassociation, which breaks the split products.
@njit(cache=True, fastmath=False)
def _frac(x):
    return x - np.floor(x)   # np.floor: a float, no int64 round trip (see _sincos_rev)


@njit(cache=True, inline="always", fastmath=False)
def _phase_rev_at(k, r_h1, r_h2, r_lo, phase0_rev):
    """One prism's exact fractional revolutions at point ``k`` (the body of :func:`phase_revs_kernel`)."""
    a = float(k >> _SPLIT_BITS)
    b = float(k & _SPLIT_MASK)
    kf = float(k)
    s = (
        _frac(a * r_h1 * _TWO_26)
        + _frac(a * r_h2 * _TWO_26)
        + _frac(b * r_h1)
        + _frac(b * r_h2)
        + kf * r_lo
        + phase0_rev
    )
    return _frac(s)


@njit(cache=True)
def phase_revs_kernel(k0, r_h1, r_h2, r_lo, phase0_rev, out):
    """Exact fractional revolutions of each prism at points ``k0 .. k0 + len(out) - 1``.

    .. math:: \\phi_p(k) = \\operatorname{frac}(\\phi_{0,p} + k\\,r_p), \\qquad
              r_p = \\frac{\\mathrm{rpm}_p}{60\\,f_\\mathrm{pt}}

    ``r_p`` arrives as a double-double ``r_h1 + r_h2 + r_lo``: ``r_h1`` holds 26 significant bits,
    ``r_h2`` the next 26, ``r_lo`` the rounding remainder of the exact rational.  ``k`` is split as
    ``a 2^26 + b`` with ``a, b < 2^26``, so every partial product ``a r_h1`` ... ``b r_h2`` is exact
    in float64 and only its fractional part is kept.  The phase error therefore stays ~1e-15 rev
    for any ``k < 2^52`` (over 400 years at 300 kHz), instead of growing like ``eps * omega * t``.

    Parameters
    ----------
    k0 : int >= 0            index of the first point
    r_h1, r_h2, r_lo : (P,) float64   split revolutions per point
    phase0_rev : (P,) float64          phase at k = 0 [rev]
    out : (P, N) float64               result in [0, 1) [rev], one row per prism
    """
    p_count, n = out.shape
    for p in range(p_count):
        for j in range(n):
            out[p, j] = _phase_rev_at(k0 + j, r_h1[p], r_h2[p], r_lo[p], phase0_rev[p])


# Kernels that trace rays are written as branch-free inner loops over a block of rays, one prism at a
# time, so LLVM turns them into SIMD code (AVX2: 4 rays per instruction, AVX-512: 8).  No fast-math:
# with contraction (FMA) or reassociation allowed, LLVM compiled the vector body and the scalar
# remainder of a loop differently, so a ray's direction changed by an ulp with its position in a call
# (chunking a scan changed bits on AVX-512) and with the CPU's vector width.  Strict IEEE arithmetic
# (+, *, /, sqrt, floor, all correctly rounded) gives every lane the same bits on any x86-64 target
# (tests/determinism) and cost nothing measurable: one 100 ms Mid-40 frame 0.105-0.120 ms with
# fast-math, 0.116-0.117 ms without (scripts/bench_scan.py, interleaved runs on a loaded machine).
_FASTMATH = False
_BLOCK = 256

# Taylor coefficients of sin and cos on [-pi/4, pi/4]: the first omitted term is < 1e-19.
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_S11, _S13, _S15, _S17 = -1.0 / 39916800.0, 1.0 / 6227020800.0, -1.0 / 1307674368000.0, 1.0 / 355687428096000.0
_C2, _C4, _C6, _C8 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0
_C10, _C12, _C14, _C16 = -1.0 / 3628800.0, 1.0 / 479001600.0, -1.0 / 87178291200.0, 1.0 / 20922789888000.0
_C18 = -1.0 / 6402373705728000.0
_HALF_PI = 0.5 * math.pi
# Ray status as float64 inside the SIMD loops (mixed-width integer selects would not vectorise).
_F_TIR = float(RAY_TIR)
_F_GRAZING = float(RAY_GRAZING)
_F_INVALID = float(RAY_INVALID)


@njit(cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
def _sincos_rev(rev):
    """``(sin, cos)`` of ``2 pi rev`` for an angle given in revolutions, branch-free.

    ``np.floor``, not ``math.floor``: in numba the latter returns an int64, and the float -> int ->
    float round trip (no AVX2 vector instruction for it) stopped the loop vectorising (2.5x slower,
    same bits).  The argument reduction is exact: ``4 rev`` is exact, its nearest integer ``q`` picks the quadrant
    and ``r = 4 rev - q`` in [-1/2, 1/2] is exact, so only ``r pi / 2`` rounds (1 ulp).  The
    polynomials are Taylor series to x^17 / x^18 (error < 1e-19 on [-pi/4, pi/4]).
    """
    u = 4.0 * rev
    q = np.floor(u + 0.5)
    a = (u - q) * _HALF_PI
    z = a * a
    s = a + a * z * (_S3 + z * (_S5 + z * (_S7 + z * (_S9 + z * (_S11 + z * (_S13 + z * (_S15 + z * _S17)))))))
    c = 1.0 + z * (_C2 + z * (_C4 + z * (_C6 + z * (_C8 + z * (_C10 + z * (_C12 + z * (_C14 + z * (_C16 + z * _C18))))))))
    # Quadrant q mod 4 in floating point (AVX2 has no vector float64 -> int64 conversion).
    qm = q - 4.0 * np.floor(0.25 * q)
    odd = qm - 2.0 * np.floor(0.5 * qm)
    sn = c if odd == 1.0 else s
    cn = s if odd == 1.0 else c
    sin_sign = -1.0 if qm >= 2.0 else 1.0
    cos_sign = -1.0 if (qm == 1.0 or qm == 2.0) else 1.0
    return sn * sin_sign, cn * cos_sign


@njit(cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
def _refract(dx, dy, dz, mx, my, mz, eta, st):
    """Vector Snell at a face with unit normal ``m`` pointing along the ray (N = -m).

    .. math:: \\cos\\theta_i = d\\cdot m, \\quad
              \\cos\\theta_t = \\sqrt{1 - \\eta^2 (1 - \\cos^2\\theta_i)}, \\quad
              t = \\eta d - (\\eta \\cos\\theta_i - \\cos\\theta_t)\\, m

    Branch-free: ``st`` (a float copy of the status code) keeps the first failure of the ray (grazing before TIR at one face); after
    a failure the direction is meaningless and is zeroed by the caller.
    """
    ci = dx * mx + dy * my + dz * mz
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    # a NaN (from a NaN prism angle) fails every comparison: invalid, not OK
    fail = _F_GRAZING if ci <= 0.0 else (_F_TIR if k < 0.0 else (0.0 if k >= 0.0 else _F_INVALID))
    st = fail if st == 0.0 else st
    g = eta * ci - math.sqrt(max(k, 0.0))
    return eta * dx - g * mx, eta * dy - g * my, eta * dz - g * mz, st


@njit(cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
def _refract_flat(dx, dy, dz, eta, st):
    """:func:`_refract` for the face perpendicular to the axis (m = +z), with the zeros folded in:
    ``t = (eta dx, eta dy, cos theta_t)``."""
    k = 1.0 - eta * eta * (1.0 - dz * dz)
    fail = _F_GRAZING if dz <= 0.0 else (_F_TIR if k < 0.0 else (0.0 if k >= 0.0 else _F_INVALID))
    st = fail if st == 0.0 else st
    return eta * dx, eta * dy, math.sqrt(max(k, 0.0)), st


@njit(cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
def _trace_prism(row, r0, m, bx, by, bz, bs, sa, ca, n_p, exit_tilted, flat_done):
    """Refract the block's rays ``bx/by/bz`` (status ``bs``) through one prism at the angles
    ``row[r0 + i]`` [rev]: flat face then tilted face, or the other way round; ``flat_done``: the
    flat entry face was already applied (it does not depend on the prism angle)."""
    inv_n = 1.0 / n_p
    if flat_done:
        for i in range(m):
            s_t, c_t = _sincos_rev(row[r0 + i])
            dx, dy, dz, st = _refract(bx[i], by[i], bz[i], -sa * c_t, -sa * s_t, ca, n_p, bs[i])
            bx[i] = dx
            by[i] = dy
            bz[i] = dz
            bs[i] = st
    elif exit_tilted:
        for i in range(m):
            s_t, c_t = _sincos_rev(row[r0 + i])
            dx, dy, dz, st = _refract_flat(bx[i], by[i], bz[i], inv_n, bs[i])
            dx, dy, dz, st = _refract(dx, dy, dz, -sa * c_t, -sa * s_t, ca, n_p, st)
            bx[i] = dx
            by[i] = dy
            bz[i] = dz
            bs[i] = st
    else:
        for i in range(m):
            s_t, c_t = _sincos_rev(row[r0 + i])
            dx, dy, dz, st = _refract(bx[i], by[i], bz[i], sa * c_t, sa * s_t, ca, inv_n, bs[i])
            dx, dy, dz, st = _refract_flat(dx, dy, dz, n_p, st)
            bx[i] = dx
            by[i] = dy
            bz[i] = dz
            bs[i] = st


@njit(cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
def _store_block(out_dir, status, j0, m, bx, by, bz, bs):
    """Optics frame (x, y, z along the axis) -> lidar frame (X fwd = z); failed rays zeroed."""
    # Rows written by flat index (rows end to end): LLVM vectorises the stride-3 stores then, not
    # as out_dir[i, c] (see sim.world.kernels._rows_to_xyz).
    out_blk = out_dir.reshape(-1)[3 * j0:3 * (j0 + m)]
    st_blk = status[j0:j0 + m]
    for i in range(m):
        keep = 1.0 if bs[i] == 0.0 else 0.0
        nan_free = bs[i] != _F_INVALID   # NaN * 0 is NaN: an invalid ray's zeros are selected
        out_blk[3 * i] = bz[i] * keep if nan_free else 0.0
        out_blk[3 * i + 1] = bx[i] * keep if nan_free else 0.0
        out_blk[3 * i + 2] = by[i] * keep if nan_free else 0.0
        st_blk[i] = np.uint8(bs[i])


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def trace_exact_kernel(revs, channel, incident, sin_wedge, cos_wedge, index, exit_tilted, out_dir, status):
    """Exact refraction of each ray through all prisms (direction only), paper Appendix B.

    Each prism is a flat face (normal +z) and a face tilted by the wedge angle ``alpha`` whose normal
    turns with the prism angle ``theta``:

    * exit face tilted:  ``m = (-sin a cos t, -sin a sin t, cos a)``
    * entry face tilted: ``m = (+sin a cos t, +sin a sin t, cos a)``

    Both signs make a single prism at ``theta = 0`` deflect toward ``+x``.  Air -> glass uses
    ``eta = 1/n``, glass -> air ``eta = n``.  Beam offset and prism thickness are dropped (far field),
    as in HELIOS++'s ``RisleyBeamDeflector``.

    Parameters
    ----------
    revs : (P, N) float64      prism angles [rev], one row per prism (C-contiguous)
    channel : (N,) int64       channel of each ray, indexes ``incident``
    incident : (C, 3) float64  unit incident direction of each channel (optics frame)
    sin_wedge, cos_wedge, index : (P,) float64
    exit_tilted : (P,) bool
    out_dir : (N, 3) float64   unit direction in the LIDAR frame (X fwd, Y left, Z up); 0 if invalid
    status : (N,) uint8        RAY_OK / RAY_TIR / RAY_GRAZING (the first failure along the ray)
    """
    p_count, n = revs.shape
    bx = np.empty(_BLOCK)
    by = np.empty(_BLOCK)
    bz = np.empty(_BLOCK)
    bs = np.empty(_BLOCK)
    for j0 in range(0, n, _BLOCK):
        m = min(_BLOCK, n - j0)
        for i in range(m):
            c = channel[j0 + i]
            bx[i] = incident[c, 0]
            by[i] = incident[c, 1]
            bz[i] = incident[c, 2]
            bs[i] = 0.0
        for p in range(p_count):
            _trace_prism(revs[p], j0, m, bx, by, bz, bs, sin_wedge[p], cos_wedge[p], index[p], exit_tilted[p],
                         False)
        _store_block(out_dir, status, j0, m, bx, by, bz, bs)


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")
def trace_paraxial_kernel(revs, channel, offset_rad, deviation_rad, out_dir):
    """First-order (paraxial) model: the beam's angular offset is the vector sum of the prisms'.

    .. math:: \\vec v = \\vec o_c + \\sum_p \\delta_p (\\cos\\theta_p, \\sin\\theta_p),
              \\qquad \\delta_p = (n_p - 1)\\alpha_p

    (paper Section III.A, Fig. 3), and the direction is the one at angle :math:`|\\vec v|` from the
    axis toward :math:`\\vec v`.  Always valid: the paraxial model has no total internal reflection.

    Parameters
    ----------
    revs : (P, N) float64          prism angles [rev]
    channel : (N,) int64
    offset_rad : (C, 2) float64    channel offsets [rad]
    deviation_rad : (P,) float64   thin-prism deviations [rad]
    out_dir : (N, 3) float64       unit direction, lidar frame
    """
    p_count, n = revs.shape
    for j in range(n):
        c = channel[j]
        vx = offset_rad[c, 0]
        vy = offset_rad[c, 1]
        for p in range(p_count):
            s_t, c_t = _sincos_rev(revs[p, j])
            vx += deviation_rad[p] * c_t
            vy += deviation_rad[p] * s_t
        g = math.sqrt(vx * vx + vy * vy)
        s = math.sin(g) / g if g > 0.0 else 1.0
        out_dir[j, 0] = math.cos(g)
        out_dir[j, 1] = vx * s
        out_dir[j, 2] = vy * s


@njit(cache=True)
def point_times_ns_kernel(k0, rate_hz, out):
    """Exact point times ``floor(k * 1e9 / rate)`` [ns] without int64 overflow for huge ``k``."""
    for j in range(out.shape[0]):
        k = k0 + j
        q = k // rate_hz
        r = k - q * rate_hz
        out[j] = q * 1_000_000_000 + (r * 1_000_000_000) // rate_hz


@njit(cache=True)
def first_hit_kernel(cell, k0, first_hit):
    """For each grid cell, the smallest point index that fell in it (coverage, paper Appendix C).

    ``cell`` holds a flat cell index per point, or -1 for points outside the grid; ``first_hit``
    holds -1 for cells not yet hit and is updated in place.  Returns how many cells were newly hit.
    """
    new = 0
    for j in range(cell.shape[0]):
        c = cell[j]
        if c >= 0 and first_hit[c] < 0:
            first_hit[c] = k0 + j
            new += 1
    return new


def split_revs_per_point(exact) -> tuple[float, float, float]:
    """Split an exact rational (``fractions.Fraction``) into ``(h1, h2, lo)`` for the phase kernel.

    ``h1 + h2`` is the float64 nearest to ``exact``, split (Veltkamp) so that ``h1`` and ``h2``
    each carry at most 26 significant bits; ``lo`` is the float64 nearest the remaining error.
    """
    from fractions import Fraction

    hi = float(exact)
    c = 134217729.0 * hi  # 2^27 + 1
    h1 = c - (c - hi)
    h2 = hi - h1
    lo = float(Fraction(exact) - Fraction(h1) - Fraction(h2))
    return h1, h2, lo


__all__ = [
    "RAY_OK",
    "RAY_TIR",
    "RAY_GRAZING",
    "RAY_INVALID",
    "phase_revs_kernel",
    "trace_exact_kernel",
    "scan_exact_kernel",
    "trace_paraxial_kernel",
    "point_times_ns_kernel",
    "first_hit_kernel",
    "split_revs_per_point",
]


@njit(cache=True, inline="always")
def _cells_within(c, half, lo, cell, n):
    """First and last index of the grid cells (``n`` of ``cell``, the first starting at ``lo``) whose
    centre lies within ``half`` of ``c`` along one axis (last < first: none)."""
    first = max(0, int(math.ceil((c - half - lo) / cell - 0.5)))
    last = min(n - 1, int(math.floor((c + half - lo) / cell - 0.5)))
    return first, last


@njit(cache=True)
def paint_footprint_kernel(az_deg, el_deg, k0, half_az_deg, half_el_deg, az_min, el_min, cell_deg, first_hit):
    """Paint each beam's elliptical footprint into a fine az/el grid (Livox's coverage definition).

    Ray ``j`` covers the cells whose centre lies inside the ellipse of semi-axes ``half_az_deg`` x
    ``half_el_deg`` around ``(az_deg[j], el_deg[j])``; a cell not yet painted records ``k0 + j``.
    ``first_hit`` is (n_el, n_az) int64, -1 where unpainted.  Returns how many cells were newly painted.
    """
    n_el, n_az = first_hit.shape
    new = 0
    inv_a2 = 1.0 / (half_az_deg * half_az_deg)
    inv_b2 = 1.0 / (half_el_deg * half_el_deg)
    for j in range(az_deg.shape[0]):
        a0 = az_deg[j]
        e0 = el_deg[j]
        i_lo, i_hi = _cells_within(a0, half_az_deg, az_min, cell_deg, n_az)
        r_lo, r_hi = _cells_within(e0, half_el_deg, el_min, cell_deg, n_el)
        for r in range(r_lo, r_hi + 1):
            de = el_min + (r + 0.5) * cell_deg - e0
            for i in range(i_lo, i_hi + 1):
                da = az_min + (i + 0.5) * cell_deg - a0
                if da * da * inv_a2 + de * de * inv_b2 <= 1.0 and first_hit[r, i] < 0:
                    first_hit[r, i] = k0 + j
                    new += 1
    return new


@njit(cache=True)
def paint_swath_kernel(u_deg, v_deg, k0, radius_deg, u_min, v_min, cell_deg, first_hit):
    """Paint a disc of radius ``radius_deg`` around each trajectory sample into a fine grid: with
    samples closer than ``radius_deg`` the union of the discs is the swath the beam sweeps, of width
    ``2 radius_deg`` across its path (Livox's FoV coverage, see ``sim.scan.coverage.swath_coverage``).

    u_deg, v_deg : (N,) float64 [deg] sample positions (azimuthal-equidistant projection about the axis)
    k0 : int, index of sample 0: a cell records the smallest ``k0 + j`` whose disc holds its centre
    first_hit : (n_v, n_u) int64, -1 where unpainted; cell (r, i) is centred at
        ``(u_min + (i + 0.5) cell, v_min + (r + 0.5) cell)``
    Returns how many cells were newly painted.  Keeping the smallest index (not the first painted)
    makes the result independent of the order of the calls: of how a trajectory is cut into chunks
    and of the order in which several channels' trajectories are painted.
    """
    n_v, n_u = first_hit.shape
    new = 0
    r2 = radius_deg * radius_deg
    for j in range(u_deg.shape[0]):
        u0 = u_deg[j]
        v0 = v_deg[j]
        i_lo, i_hi = _cells_within(u0, radius_deg, u_min, cell_deg, n_u)
        r_lo, r_hi = _cells_within(v0, radius_deg, v_min, cell_deg, n_v)
        for r in range(r_lo, r_hi + 1):
            dv = v_min + (r + 0.5) * cell_deg - v0
            for i in range(i_lo, i_hi + 1):
                du = u_min + (i + 0.5) * cell_deg - u0
                if du * du + dv * dv <= r2:
                    old = first_hit[r, i]
                    if old < 0:
                        first_hit[r, i] = k0 + j
                        new += 1
                    elif k0 + j < old:
                        first_hit[r, i] = k0 + j
    return new


@njit(cache=True)
def add_speed_noise_kernel(k0, rate_hz, segment_s, noise_cum, noise_eps, noise_seg0, rev_per_s, revs):
    """Add the phase error of piecewise-constant relative speed errors to ``revs`` (P, N) [rev].

    Point ``k0 + j`` is at ``t = (k0 + j) / rate``, in segment ``s = floor(t / T)``; its phase error
    is ``rev_per_s[p] * (noise_cum[s, p] + noise_eps[s, p] * (t - s T))`` (the integral of the
    relative error), wrapped back into [0, 1).  The tables hold segments from ``noise_seg0`` on (row
    ``s - noise_seg0``): older ones are dropped on long runs (:class:`sim.scan.model.ScanModel`).
    """
    p_count, n = revs.shape
    for j in range(n):
        t = (k0 + j) / rate_hz
        s = int(math.floor(t / segment_s))
        dt = t - s * segment_s
        for p in range(p_count):
            r = s - noise_seg0
            v = revs[p, j] + rev_per_s[p] * (noise_cum[r, p] + noise_eps[r, p] * dt)
            revs[p, j] = v - np.floor(v)


# ---- fused scan: phases + speed noise + times + channels + exact trace, one pass ---------------------
_RAMP = np.arange(_BLOCK, dtype=np.float64)  # 0.0, 1.0, ..., 255.0 (AVX2 cannot convert int64 -> f64)
_NS_PER_S = 1_000_000_000


@njit(cache=True, fastmath=False)
def _scan_block_setup(k, m, rate_hz, r_h1, r_h2, r_lo, phase0_rev, noise_on, segment_s, noise_cum,
                      noise_eps, noise_seg0, rev_per_s, channel_count, channel_pattern, revs, t_ns, channel, j0, tb):
    """Phases (with speed noise), times and channels of the ``m <= 256`` points ``k .. k + m - 1``.

    Explicitly not fastmath (``arcp`` would turn the divisions below into multiplications by a
    reciprocal, ``reassoc`` would regroup the double-double phase; an unset flag would be inherited
    from the fastmath caller).  Writes ``revs[:, :m]`` and ``t_ns`` / ``channel`` at ``j0 ..``;
    ``tb`` is a scratch block.

    Phase: the exact double-double phase :math:`\\phi_p(k)` (as in :func:`phase_revs_kernel`) at the
    block's anchor ``k`` (the multiple of 256 at or before the first point, so that chunking never
    changes a bit), then :math:`\\phi_p(k) + i\\,\\hat r_p` for ``i < 256`` in float64, where
    :math:`\\hat r_p = r_{h1} + r_{h2} + r_{lo}` rounded.  Against the exact :math:`\\phi_p(k+i)`
    this adds at most :math:`255\\,|\\hat r_p - r_p| + \\tfrac12\\mathrm{ulp}(255\\,r_p)
    \\le 255\\,|r_p|\\,2^{-52}` rev, e.g. 7e-17 rev for the Mid-40's fast prism
    (:math:`r = 1.2\\times10^{-3}` rev/point), plus the final rounding of the sum (below 1.2e-16
    rev, the same as the per-point kernel's own last rounding).

    Speed noise: the formula of :func:`add_speed_noise_kernel` point by point (same ``t``, same
    segment ``s``, same ``dt``); ``k + i`` is formed as ``float(k) + i`` (exact below 2^53), and the
    block is cut into runs of equal ``s`` so the segment's ``cum`` / ``eps`` are scalars per run.

    Times: ``floor((k + i) 1e9 / rate)`` exactly, with integer arithmetic once per block:
    ``k = q rate + r``, ``r 1e9 = q2 rate + R0``, so ``floor((k + i) 1e9 / rate) = q 1e9 + q2 +
    floor((R0 + i 1e9) / rate)``.  ``N = R0 + i 1e9 < 2e6 + 255e9 < 2^53`` is exact in float64 and
    the division is correctly rounded, so ``fl(N / rate)`` differs from ``x = N / rate`` by at most
    ``x 2^-53``.  If ``x`` is not a whole number, the next whole number ``c`` has
    ``c - x >= 1 / rate`` (``c rate - N`` is a positive integer), and ``x 2^-53 < 1 / rate``
    because ``N < 2^53``; rounding is monotone and ``c`` is representable, so ``fl(x) < c`` and
    ``floor(fl(x)) = floor(x)``.  If ``x`` is whole, it is representable and ``fl(x) = x``.
    """
    p_count = revs.shape[0]
    rate_f = float(rate_hz)
    k_f = float(k)
    # times
    q = k // rate_hz
    r = k - q * rate_hz
    num = r * _NS_PER_S
    q2 = num // rate_hz
    t_base = q * _NS_PER_S + q2
    r0 = float(num - q2 * rate_hz)
    # (Loops index slices from 0: numba's wrap-around test on an index like j0 + i, which might be
    # negative as far as the compiler knows, stops LLVM vectorising a loop.)
    t_blk = t_ns[j0:j0 + m]
    for i in range(m):
        t_blk[i] = t_base + np.int64(math.floor((r0 + _RAMP[i] * 1e9) / rate_f))
    # channels: (k + i) mod C read from the pattern ``channel_pattern[j] = j mod C`` at offset k mod C
    c0 = k % channel_count
    ch_blk = channel[j0:j0 + m]
    pat = channel_pattern[c0:c0 + m]
    for i in range(m):
        ch_blk[i] = pat[i]
    # phases (the caller keeps a block within one 256-point cell: off + m <= 256)
    off = k % _BLOCK
    anchor = k - off
    if noise_on:
        for i in range(m):
            tb[i] = (k_f + _RAMP[i]) / rate_f
    i = 0
    while i < m:
        e = m
        seg_f = 0.0
        si = 0
        if noise_on:
            # A point's segment floor(t / T) does not decrease along the block (its t increases, and a
            # correctly rounded division by T > 0 and floor are monotone), so the run of the segment of
            # point i ends at the first later point in a later segment: found from the block's last
            # point and a bisection, the segments asked of a few points, not of each (a block of 2.56 ms
            # usually lies in one 10 ms segment)
            seg_f = np.floor(tb[i] / segment_s)
            if np.floor(tb[m - 1] / segment_s) != seg_f:
                lo = i + 1
                hi = m - 1
                while lo < hi:
                    mid = (lo + hi) // 2
                    if np.floor(tb[mid] / segment_s) == seg_f:
                        lo = mid + 1
                    else:
                        hi = mid
                e = lo
            si = int(seg_f) - noise_seg0
        for p in range(p_count):
            # exact at the block's absolute anchor (a multiple of 256 at or before k), so that the
            # phase of a point does not depend on where the caller's chunk began
            base = _phase_rev_at(anchor, r_h1[p], r_h2[p], r_lo[p], phase0_rev[p])
            r_p = r_h1[p] + r_h2[p] + r_lo[p]
            row = revs[p]
            if noise_on:
                w = rev_per_s[p]
                cum = noise_cum[si, p]
                eps = noise_eps[si, p]
                s_t = seg_f * segment_s
                row_r = row[i:e]
                ramp_r = _RAMP[i + off:e + off]
                tb_r = tb[i:e]
                for ii in range(e - i):
                    v = (base + ramp_r[ii] * r_p) + w * (cum + eps * (tb_r[ii] - s_t))
                    row_r[ii] = v - np.floor(v)
            else:
                row_r = row[i:e]
                ramp_r = _RAMP[i + off:e + off]
                for ii in range(e - i):
                    v = base + ramp_r[ii] * r_p
                    row_r[ii] = v - np.floor(v)
        i = e


@njit(cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy")
def scan_exact_kernel(k0, rate_hz, r_h1, r_h2, r_lo, phase0_rev, noise_on, segment_s, noise_cum, noise_eps,
                      noise_seg0, rev_per_s, channel_count, incident, sin_wedge, cos_wedge, index, exit_tilted,
                      t_ns, channel, out_dir, status):
    """Points ``k0 .. k0 + N - 1`` of the exact model in one pass: what ``phase_revs_kernel`` +
    ``add_speed_noise_kernel`` + ``point_times_ns_kernel`` + channel ``k mod C`` +
    ``trace_exact_kernel`` give together (paper Section III, Appendix B), without the (P, N) phase
    array, the per-point double-double phase and the per-point int64 division.

    Per 256-ray block, aligned to absolute multiples of 256 points (:func:`_scan_block_setup`): the
    exact phase at the block's anchor, then
    ``+ i r_p`` in float64 (extra phase error <= 255 |r_p| 2^-52 rev, ~7e-17 rev at the Mid-40's
    speeds; the per-point kernel's is ~1e-15 rev), the piecewise-constant speed-noise phase error
    (same formula as ``add_speed_noise_kernel``; ``noise_on`` False skips it), exact times and the
    channels; then the trace of ``trace_exact_kernel`` (same ``_sincos_rev``, ``_refract``,
    ``_refract_flat``; a first prism whose flat face comes first refracts each channel's incident
    direction there once per call, not once per ray).  The slow sinusoidal drift is not here (the model keeps the composed path for it).

    Parameters
    ----------
    k0 : int >= 0                      index of the first point
    rate_hz : int in [1e3, 2e6]        point rate [points/s]
    r_h1, r_h2, r_lo, phase0_rev : (P,) float64   as for ``phase_revs_kernel``
    noise_on : bool
    segment_s : float > 0 [s]; noise_cum : (S+1, P); noise_eps : (S, P); noise_seg0 : int;
    rev_per_s : (P,) [rev/s]   as for ``add_speed_noise_kernel`` (from segment ``noise_seg0``, grown
        to cover the last point's segment + 1)
    channel_count : int >= 1           channels C; point k is fired by channel ``k mod C``
    incident, sin_wedge, cos_wedge, index, exit_tilted : as for ``trace_exact_kernel``
    t_ns : (N,) int64 [ns]; channel : (N,) uint8; out_dir : (N, 3) float64; status : (N,) uint8  outputs
    """
    n = out_dir.shape[0]
    revs, tb, bx, by, bz, bs, first, pre, channel_pattern = _scan_scratch(r_h1.shape[0], channel_count,
                                                                                 incident, index, exit_tilted)
    # Blocks start at absolute multiples of 256 points, so a point's phase (exact at its block's
    # start, + i r inside) does not depend on how the caller chunks the scan: the same bits for the
    # closed loop's 100 ms frames and the virtual lidar's packets.
    # np.int64, not the literal 0: numba's type inference first sees the literal, and a non-inlined
    # callee given it is compiled a second time for Literal[int](0) (never run; ~10 s of CPU here)
    j0 = np.int64(0)
    while j0 < n:
        m = min(_BLOCK - (k0 + j0) % _BLOCK, n - j0)
        _scan_block(k0 + j0, m, j0, rate_hz, r_h1, r_h2, r_lo, phase0_rev, noise_on, segment_s, noise_cum,
                    noise_eps, noise_seg0, rev_per_s, channel_count, sin_wedge, cos_wedge, index, exit_tilted,
                    channel_pattern, first, pre, revs, tb, t_ns, channel, bx, by, bz, bs)
        _store_block(out_dir, status, j0, m, bx, by, bz, bs)
        j0 += m


@njit(cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
def _scan_scratch(p_count, channel_count, incident, index, exit_tilted):
    """Scratch blocks of :func:`scan_exact_kernel` and what it computes once per call: each channel's
    direction after a first prism's flat entry face (``first``, with ``pre`` telling whether that face
    comes first) and the channel pattern ``j mod C``."""
    revs = np.empty((p_count, _BLOCK))
    tb = np.empty(_BLOCK)
    bx = np.empty(_BLOCK)
    by = np.empty(_BLOCK)
    bz = np.empty(_BLOCK)
    bs = np.empty(_BLOCK)
    # A first prism with its flat face first sees each channel's fixed incident direction there:
    # that refraction does not depend on the phase, so it is done once per channel, not per ray.
    pre = incident.shape[0] > 0 and exit_tilted[0]
    first = np.empty((incident.shape[0], 4))
    for c in range(incident.shape[0]):
        if pre:
            dx, dy, dz, st = _refract_flat(incident[c, 0], incident[c, 1], incident[c, 2], 1.0 / index[0], 0.0)
        else:
            dx, dy, dz, st = incident[c, 0], incident[c, 1], incident[c, 2], 0.0
        first[c, 0] = dx
        first[c, 1] = dy
        first[c, 2] = dz
        first[c, 3] = st
    channel_pattern = np.empty(_BLOCK + channel_count, dtype=np.uint8)
    for j in range(_BLOCK + channel_count):
        channel_pattern[j] = np.uint8(j % channel_count)
    return revs, tb, bx, by, bz, bs, first, pre, channel_pattern


@njit(cache=True, fastmath=_FASTMATH, error_model="numpy")   # not inlined: numba's inliner refuses 30+ arguments
def _scan_block(k, m, j0, rate_hz, r_h1, r_h2, r_lo, phase0_rev, noise_on, segment_s, noise_cum, noise_eps,
                noise_seg0, rev_per_s, channel_count, sin_wedge, cos_wedge, index, exit_tilted, channel_pattern,
                first, pre,
                revs, tb, t_ns, channel, bx, by, bz, bs):
    """One block of :func:`scan_exact_kernel` (``m`` points from ``k``, within one 256-point cell):
    times and channels at ``j0 ..``, and the traced rays left in ``bx, by, bz`` (optics frame) with
    their status in ``bs``."""
    _scan_block_setup(k, m, rate_hz, r_h1, r_h2, r_lo, phase0_rev, noise_on, segment_s, noise_cum,
                      noise_eps, noise_seg0, rev_per_s, channel_count, channel_pattern, revs, t_ns, channel, j0, tb)
    ch_blk = channel[j0:j0 + m]
    for i in range(m):
        c = ch_blk[i]
        bx[i] = first[c, 0]
        by[i] = first[c, 1]
        bz[i] = first[c, 2]
        bs[i] = first[c, 3]
    for p in range(revs.shape[0]):
        _trace_prism(revs[p], 0, m, bx, by, bz, bs, sin_wedge[p], cos_wedge[p], index[p], exit_tilted[p],
                     p == 0 and pre)
