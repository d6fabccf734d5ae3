"""Plain-numpy twins of the kernels in :mod:`sim.scan.kernels`.

Written independently from the kernels (vectorised, no numba), so that agreement between the two is
evidence that both are right.  ``scripts/bench_scan.py`` times them against the kernels.
"""

from __future__ import annotations

import numpy as np

from sim.scan.kernels import RAY_GRAZING, RAY_INVALID, RAY_OK, RAY_TIR


def phase_revs_twin(k0, r_exact_fractions, phase0_rev, count):
    """Fractional revolutions from exact rationals, via Python integers (slow, exact reference)."""
    from fractions import Fraction

    out = np.empty((count, len(r_exact_fractions)))
    for p, r in enumerate(r_exact_fractions):
        ph0 = Fraction(float(phase0_rev[p]))
        for j in range(count):
            v = ph0 + (k0 + j) * Fraction(r)
            out[j, p] = float(v - (v.numerator // v.denominator))
    return out


def _refract_twin(d, m, eta, status):
    """Vector Snell on arrays: d (N,3), m (N,3) normals along the ray, eta scalar; updates status."""
    ci = np.einsum("ij,ij->i", d, m)
    grazing = ci <= 0.0
    k = 1.0 - eta * eta * (1.0 - ci * ci)
    tir = (k < 0.0) & ~grazing
    invalid = ~grazing & ~tir & ~(k >= 0.0)   # NaN: neither test decides
    ok = status == RAY_OK
    status[ok & grazing] = RAY_GRAZING
    status[ok & tir] = RAY_TIR
    status[ok & invalid] = RAY_INVALID
    g = eta * ci - np.sqrt(np.where(k < 0.0, 0.0, k))
    return eta * d - g[:, None] * m


def trace_exact_twin(revs, channel, incident, sin_wedge, cos_wedge, index, exit_tilted):
    """Same contract as ``trace_exact_kernel``; returns (direction (N,3), status (N,))."""
    n, p_count = revs.shape
    d = incident[channel].astype(np.float64, copy=True)
    status = np.zeros(n, dtype=np.uint8)
    flat = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (n, 3))
    for p in range(p_count):
        th = 2.0 * np.pi * revs[:, p]
        sa = sin_wedge[p]
        sign = -1.0 if exit_tilted[p] else 1.0
        tilted = np.column_stack([sign * sa * np.cos(th), sign * sa * np.sin(th), np.full(n, cos_wedge[p])])
        if exit_tilted[p]:
            d = _refract_twin(d, flat, 1.0 / index[p], status)
            d = _refract_twin(d, tilted, index[p], status)
        else:
            d = _refract_twin(d, tilted, 1.0 / index[p], status)
            d = _refract_twin(d, flat, index[p], status)
    out = np.zeros((n, 3))
    ok = status == RAY_OK
    out[ok] = d[ok][:, [2, 0, 1]]
    return out, status


def trace_paraxial_twin(revs, channel, offset_rad, deviation_rad):
    th = 2.0 * np.pi * revs
    v = offset_rad[channel] + np.stack(
        [(deviation_rad * np.cos(th)).sum(axis=1), (deviation_rad * np.sin(th)).sum(axis=1)], axis=1
    )
    g = np.hypot(v[:, 0], v[:, 1])
    s = np.where(g > 0, np.sin(g) / np.where(g > 0, g, 1.0), 1.0)
    return np.column_stack([np.cos(g), v[:, 0] * s, v[:, 1] * s])


def point_times_ns_twin(k0, rate_hz, count):
    k = np.arange(k0, k0 + count, dtype=object)
    return np.array([(int(x) * 1_000_000_000) // rate_hz for x in k], dtype=np.int64)


def first_hit_twin(cell, k0, first_hit):
    first_hit = first_hit.copy()
    idx = np.flatnonzero(cell >= 0)
    cells, first = np.unique(cell[idx], return_index=True)
    fresh = first_hit[cells] < 0
    first_hit[cells[fresh]] = k0 + idx[first[fresh]]
    return first_hit, int(fresh.sum())


def paint_footprint_twin(az, el, k0, half_az, half_el, az_min, el_min, cell, shape):
    """Cell centres inside each ray's ellipse, first ray index per cell (brute force over cells)."""
    n_el, n_az = shape
    ca = az_min + (np.arange(n_az) + 0.5) * cell
    ce = el_min + (np.arange(n_el) + 0.5) * cell
    first = np.full(shape, -1, dtype=np.int64)
    for j in range(len(az) - 1, -1, -1):  # later rays first, so earlier ones overwrite
        inside = ((ca[None, :] - az[j]) ** 2 / half_az**2 + (ce[:, None] - el[j]) ** 2 / half_el**2) <= 1.0
        first[inside] = k0 + j
    return first


def paint_swath_twin(u, v, k0, radius, u_min, v_min, cell, shape):
    """Cell centres within ``radius`` of each sample, smallest sample index per cell (brute force)."""
    n_v, n_u = shape
    cu = u_min + (np.arange(n_u) + 0.5) * cell
    cv = v_min + (np.arange(n_v) + 0.5) * cell
    first = np.full(shape, np.iinfo(np.int64).max, dtype=np.int64)
    for j in range(len(u)):
        inside = (cu[None, :] - u[j]) ** 2 + (cv[:, None] - v[j]) ** 2 <= radius**2
        first[inside] = np.minimum(first[inside], k0 + j)
    first[first == np.iinfo(np.int64).max] = -1
    return first


def add_speed_noise_twin(k0, rate_hz, segment_s, cum, eps, rev_per_s, revs):
    t = (k0 + np.arange(revs.shape[1])) / rate_hz
    s = np.floor(t / segment_s).astype(int)
    v = revs + (rev_per_s[:, None] * (cum[s].T + eps[s].T * (t - s * segment_s)[None, :]))
    return v - np.floor(v)


def scan_exact_twin(k0, count, rate_hz, r_exact_fractions, phase0_rev, noise, channel_count, incident, sin_wedge,
                    cos_wedge, index, exit_tilted):
    """Same contract as ``scan_exact_kernel``, composed of the twins above: exact rational phases,
    the speed noise (``noise = (segment_s, cum, eps, rev_per_s)`` or None), the exact trace, the
    integer times and channel ``k mod C``.  Returns (t_ns, channel, direction, status)."""
    revs = phase_revs_twin(k0, r_exact_fractions, phase0_rev, count)  # (N, P)
    if noise is not None and count:
        segment_s, cum, eps, rev_per_s = noise
        revs = add_speed_noise_twin(k0, float(rate_hz), segment_s, cum, eps, rev_per_s, revs.T).T
    channel = (np.arange(k0, k0 + count, dtype=object) % channel_count).astype(np.int64)
    direction, status = trace_exact_twin(revs, channel, incident, sin_wedge, cos_wedge, index, exit_tilted)
    return point_times_ns_twin(k0, rate_hz, count), channel.astype(np.uint8), direction, status
