"""Numba kernels of the sensor's returns (:mod:`sim.sensor`): one pass from cast rays to points.

After ray casting, each frame turns the rays that hit something into points: the scene's effects
act on the hits, and the kept ones are gathered in scan order.  Done with numpy this takes ~20
array operations over the ~5 000 hits of a Mid-40 frame; here it is one pass.  Random numbers are
drawn by the caller with numpy, in the same calls and sizes as the effects in :mod:`sim.effects`,
so the streams (and so the points) do not depend on which route assembled them.  Plain-numpy twin:
``tests/sensor_twins.py``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from foveatrack.livox.protocol import INT32_MM_MAX, INT32_MM_MIN, MM_PER_M
from sim.portable_exp import exp_portable
from sim.scan.kernels import RAY_OK

# the client's conversion (foveatrack.livox.protocol.m_to_mm), as float bounds for the kernel
_INT32_MM_MIN, _INT32_MM_MAX = float(INT32_MM_MIN), float(INT32_MM_MAX)


@njit(cache=True, inline="always")
def _on_mm_grid(x_m):
    """One coordinate [m] as a Livox's Cartesian output gives it: ``rint(x * 1000)`` saturated to
    int32 millimetres, then ``mm * 1e-3`` in float64 — :func:`foveatrack.livox.protocol.quantise_to_mm_grid`
    for one value, the same bits (through int32, so -0.0 becomes +0.0 as there).  NaN is not allowed."""
    mm = np.int32(min(max(np.rint(x_m * MM_PER_M), _INT32_MM_MIN), _INT32_MM_MAX))
    return mm * 1e-3


@njit(cache=True, inline="always")
def _put_point(out_xyz, out_t_ns, k, x, y, z, t, mm_grid):
    """Output point ``k``: its coordinates [m] (on the Livox mm grid where asked) and its time."""
    if mm_grid:
        x = _on_mm_grid(x)
        y = _on_mm_grid(y)
        z = _on_mm_grid(z)
    out_xyz[k, 0] = x
    out_xyz[k, 1] = y
    out_xyz[k, 2] = z
    out_t_ns[k] = t


@njit(cache=True, nogil=True)
def quantise_to_mm_grid_kernel(xyz_m, out):
    """``out[:] = quantise_to_mm_grid(xyz_m)`` (any float64 shape, flattened alike); the test of
    :func:`_on_mm_grid` against its numpy original."""
    src = xyz_m.reshape(-1)
    dst = out.reshape(-1)
    for i in range(src.shape[0]):
        dst[i] = _on_mm_grid(src[i])


@njit(cache=True, nogil=True)
def count_hits_kernel(prim, status):
    """How many rays hit something (``prim >= 0``) and left the prisms (``status == RAY_OK``)."""
    n = 0
    for j in range(prim.shape[0]):
        if prim[j] >= 0 and status[j] == RAY_OK:
            n += 1
    return n


@njit(cache=True, nogil=True)
def object_rays_kernel(prim, status, object_of_prim, out_count):
    """Per object of a multi-object scene, the rays that hit it and left the prisms (``status ==
    RAY_OK``): ``out_count[object_of_prim[prim[j]]]`` counts ray j when ``prim[j]`` is one of the
    objects' primitives (``object_of_prim``: the object of each, drones then others; the background
    and a stray return after them count for none).  One pass instead of numpy's mask, searchsorted
    and bincount over the whole frame (~20 us of the ~10 000 rays of a Mid-40 frame); integers, so
    the same counts (numpy twin: ``object_rays_twin`` in ``tests/sensor_twins.py``).  Returns
    :func:`count_hits_kernel`'s count, from the same pass."""
    n_prims = object_of_prim.shape[0]
    n_hit = 0
    for j in range(prim.shape[0]):
        p = prim[j]
        if p >= 0 and status[j] == RAY_OK:
            n_hit += 1
            if p < n_prims:
                out_count[object_of_prim[p]] += 1
    return n_hit


@njit(cache=True, inline="always")
def _refl_byte(refl, gain):
    """The Livox reflectivity byte of a return of effective reflectivity ``refl * gain``:
    ``clip(rint(100 refl gain), 0, 255)`` (numpy's round: half to even)."""
    return np.uint8(min(max(np.rint(refl * gain * 100.0), 0.0), 255.0))


@njit(cache=True, nogil=True, error_model="numpy")
def assemble_returns_kernel(prim, status, range_m, d_lidar, t_ns, range_limit_m, refl_byte_table, target_prim_end,
                            u_return, u_dropout, dropout_rate, range_normals, range_noise_m, angular_normals,
                            angular_noise_rad, mm_grid, min_range_m, max_range_m,
                            refl_table, ray_gain, extinction_1_m, noise_limit_m, clutter_range_m, clutter_refl_byte,
                            out_xyz, out_t_ns, out_refl, out_on_target):
    """Points of the hits, effects applied, in scan order; returns how many were kept.

    Hit ``h`` (the h-th ray with ``prim >= 0`` and status OK) uses entry ``h`` of each draw array;
    an empty draw array means "effect off":

    * ``u_return`` (uniform): kept if ``u < p``, with ``p`` the return probability of
      :func:`sim.effects.detection_probability`: logistic in range, 50 % at the primitive's range
      limit ``range_limit_m[m]`` (:func:`sim.effects.range_limit_m`), width 3 % of it.  Well inside
      the limit (z < -15) ``p > 1 - exp(z) - 2^-53 > 1 - 1e-6``, so a draw below ``1 - 1e-6`` is
      kept without the exponential (the same decision: only the cost changes);
    * ``u_dropout`` (uniform): kept if ``u >= dropout_rate``;
    * ``range_normals`` (standard normals): ``0.0 + sigma * z`` [m] is added to the range, with
      ``sigma = range_noise_m`` (``rng.normal(0, range_noise_m)``'s own expression, value for value:
      :func:`sim.effects.range_noise_draws`, here without its two array operations), or with
      ``noise_limit_m > 0`` (effect ``range_noise_model``) the sigma of
      :func:`sim.effects.range_noise_sigma_m`, growing with range and falling with reflectivity;
    * ``angular_normals`` (standard normals, 3 per hit, flat or (H, 3)): ``0.0 + angular_noise_rad * z``
      [rad] is added to the direction, which is then renormalised (:func:`sim.effects.angular_noise_draws`).

    The return's power gain against a clear, head-on return of the whole beam
    (:func:`sim.effects.return_gain`): ``ray_gain[j]`` (empty: off; effect ``incidence``'s
    ``|cos theta|`` times effect ``mixed_pixels``' share of the beam in the echo) times the two-way transmission
    ``exp(-2 extinction_1_m r)`` (effect ``weather``; 0: off).  It scales the effective reflectivity,
    so the range limit by ``sqrt(gain)`` (:func:`sim.effects.range_limit_m`), the range noise of the
    model, and the reflectivity byte (``refl_table[m] * gain``, :func:`_refl_byte`).

    ``clutter_range_m`` (effect ``weather``; empty: off): per ray, the range of a droplet's return
    (inf: none).  The lidar reports its first return: a droplet nearer than the point the ray would
    have given replaces it; on a ray that gives no point (nothing hit, lost to the effects) it is
    the ray's point.  Its reflectivity byte is ``clutter_refl_byte``; it takes no draw here, and a
    ray without a hit takes no hit index, so the other effects' draws go to the same hits.

    The range envelope, always on: a hit whose measured range (after the range noise) is below
    ``min_range_m`` (the blind zone) or above ``max_range_m`` gives no point; it takes no draw, so
    the effects' streams are the same with any envelope.

    ``refl_byte_table``: the Livox reflectivity byte per primitive; a primitive below
    ``target_prim_end`` belongs to a target (``out_on_target``).  ``mm_grid``: the points go out on
    the 1 mm grid of a Livox's Cartesian output (:func:`_on_mm_grid`, the bits of
    ``quantise_to_mm_grid`` applied afterwards, in this pass instead of five array operations).
    """
    use_ret = u_return.shape[0] > 0
    use_drop = u_dropout.shape[0] > 0
    use_rn = range_normals.shape[0] > 0
    an = angular_normals.reshape(-1)
    use_an = an.shape[0] > 0
    use_inc = ray_gain.shape[0] > 0
    use_ext = extinction_1_m > 0.0
    use_gain = use_inc or use_ext
    use_model = noise_limit_m > 0.0
    use_clutter = clutter_range_m.shape[0] > 0
    h = -1
    k = 0
    for j in range(prim.shape[0]):
        m = prim[j]
        ok = status[j] == RAY_OK
        c = clutter_range_m[j] if (use_clutter and ok) else math.inf
        keep = m >= 0 and ok
        r = range_m[j]
        gain = 1.0
        if keep:
            h += 1
            if use_inc:
                gain = ray_gain[j]
            if use_ext:
                gain = gain * exp_portable(-2.0 * extinction_1_m * r)
            r_max = range_limit_m[m]
            if use_gain:
                r_max = r_max * math.sqrt(gain)
            if use_ret:
                u = u_return[h]
                if not r_max > 0.0:       # no power comes back (a grazing ray)
                    keep = False
                # Within half the limit z < -16.6 (< -15 whatever the rounding): the draw alone decides,
                # without the division (the same decision as the test below, which the others take).
                elif not (r < 0.5 * r_max and u < 0.999999):
                    z = min(max((r - r_max) / (0.03 * r_max), -50.0), 50.0)
                    if not (z < -15.0 and u < 0.999999) and not u < 1.0 / (1.0 + exp_portable(z)):
                        keep = False
            if keep and use_drop and not u_dropout[h] >= dropout_rate:
                keep = False
            if keep and use_rn:
                sigma = range_noise_m
                if use_model:
                    q = r / r_max
                    q = q * q * noise_limit_m
                    sigma = math.sqrt(range_noise_m * range_noise_m + q * q)
                r = r + (0.0 + sigma * range_normals[h])
            if keep and not (min_range_m <= r <= max_range_m):   # the blind zone and beyond the maximum range
                keep = False
        if c < math.inf and (not keep or c < r):
            # a droplet's return: the ray's first, or the only one it gives
            if not (min_range_m <= c <= max_range_m):
                continue
            _put_point(out_xyz, out_t_ns, k, d_lidar[j, 0] * c, d_lidar[j, 1] * c, d_lidar[j, 2] * c, t_ns[j], mm_grid)
            out_refl[k] = clutter_refl_byte
            out_on_target[k] = False
            k += 1
            continue
        if not keep:
            continue
        dx = d_lidar[j, 0]
        dy = d_lidar[j, 1]
        dz = d_lidar[j, 2]
        if use_an:
            dx += 0.0 + angular_noise_rad * an[3 * h]
            dy += 0.0 + angular_noise_rad * an[3 * h + 1]
            dz += 0.0 + angular_noise_rad * an[3 * h + 2]
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            dx /= norm
            dy /= norm
            dz /= norm
        _put_point(out_xyz, out_t_ns, k, dx * r, dy * r, dz * r, t_ns[j], mm_grid)
        out_refl[k] = _refl_byte(refl_table[m], gain) if use_gain else refl_byte_table[m]
        out_on_target[k] = m < target_prim_end
        k += 1
    return k


@njit(cache=True, nogil=True)
def mixed_pixel_kernel(sub_r, sub_prim, refl_table, resolution_m, out_r, out_prim, out_share):
    """One echo per beam from its footprint's sub-rays (effect ``mixed_pixels``, :mod:`sim.effects`).

    Row ``k``: the ranges ``sub_r[k]`` (inf: nothing) and primitives of the S sub-rays of one beam,
    equal shares of its energy.  Each sub-ray returns power ``rho / r^2`` (``refl_table[prim]``).
    Sorted by range, sub-rays closer than ``resolution_m`` to the previous one merge into one echo
    (a pulse cannot resolve them): its range is the power-weighted mean of theirs -- a mixed pixel
    between the surfaces.  The beam reports its strongest echo (ties: the nearer): ``out_r[k]``,
    ``out_prim[k]`` (the echo's strongest sub-ray's primitive) and ``out_share[k]``, the share of
    the beam's energy in that echo (its sub-rays / S), which scales the echo's power; inf, -1, 0
    when no sub-ray hits anything."""
    n, s = sub_r.shape
    order = np.empty(s, dtype=np.int64)
    for k in range(n):
        m = 0
        for i in range(s):             # the sub-rays that hit, by range (insertion sort: S <= 64)
            if sub_prim[k, i] < 0:
                continue
            r = sub_r[k, i]
            j = m
            while j > 0 and sub_r[k, order[j - 1]] > r:
                order[j] = order[j - 1]
                j -= 1
            order[j] = i
            m += 1
        best_p = -1.0
        best_r = math.inf
        best_prim = -1
        best_share = 0.0
        a = 0
        while a < m:
            b = a + 1
            while b < m and sub_r[k, order[b]] - sub_r[k, order[b - 1]] <= resolution_m:
                b += 1
            p_sum = 0.0
            pr_sum = 0.0
            p_max = -1.0
            prim_max = -1
            for q in range(a, b):
                i = order[q]
                r = sub_r[k, i]
                p = refl_table[sub_prim[k, i]] / (r * r)
                p_sum += p
                pr_sum += p * r
                if p > p_max:
                    p_max = p
                    prim_max = sub_prim[k, i]
            if p_sum > best_p:           # strictly stronger: of equal echoes the nearer stays
                best_p = p_sum
                best_r = pr_sum / p_sum
                best_prim = prim_max
                best_share = (b - a) / s
            a = b
        out_r[k] = best_r
        out_prim[k] = best_prim
        out_share[k] = best_share
