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

from numba import njit

from sim.scan.kernels import RAY_OK


@njit(cache=True, nogil=True)
def count_hits_kernel(prim, status):
    """How many rays hit something (``prim >= 0``) and left the prisms (``status == RAY_OK``)."""
    n = 0
    for j in range(prim.shape[0]):
        if prim[j] >= 0 and status[j] == RAY_OK:
            n += 1
    return n


@njit(cache=True, nogil=True, error_model="numpy")
def assemble_returns_kernel(prim, status, range_m, d_lidar, t_ns, range_limit_m, refl_byte_table, target_prim_end,
                            u_return, u_dropout, dropout_rate, range_noise, angular_noise,
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
    * ``range_noise`` [m]: added to the range;
    * ``angular_noise`` (H, 3) [rad]: added to the direction, which is then renormalised.

    ``refl_byte_table``: the Livox reflectivity byte per primitive; a primitive below
    ``target_prim_end`` belongs to a target (``out_on_target``).
    """
    use_ret = u_return.shape[0] > 0
    use_drop = u_dropout.shape[0] > 0
    use_rn = range_noise.shape[0] > 0
    use_an = angular_noise.shape[0] > 0
    h = -1
    k = 0
    for j in range(prim.shape[0]):
        m = prim[j]
        if m < 0 or status[j] != RAY_OK:
            continue
        h += 1
        r = range_m[j]
        if use_ret:
            r_max = range_limit_m[m]
            z = min(max((r - r_max) / (0.03 * r_max), -50.0), 50.0)
            u = u_return[h]
            if not (z < -15.0 and u < 0.999999) and not u < 1.0 / (1.0 + math.exp(z)):
                continue
        if use_drop and not u_dropout[h] >= dropout_rate:
            continue
        if use_rn:
            r = r + range_noise[h]
        dx = d_lidar[j, 0]
        dy = d_lidar[j, 1]
        dz = d_lidar[j, 2]
        if use_an:
            dx += angular_noise[h, 0]
            dy += angular_noise[h, 1]
            dz += angular_noise[h, 2]
            norm = math.sqrt(dx * dx + dy * dy + dz * dz)
            dx /= norm
            dy /= norm
            dz /= norm
        out_xyz[k, 0] = dx * r
        out_xyz[k, 1] = dy * r
        out_xyz[k, 2] = dz * r
        out_t_ns[k] = t_ns[j]
        out_refl[k] = refl_byte_table[m]
        out_on_target[k] = m < target_prim_end
        k += 1
    return k
