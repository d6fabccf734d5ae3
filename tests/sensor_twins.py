"""Plain-numpy twin of :mod:`sim.sensor_kernels`: the sensor's returns as array operations (the
route the simulator took before the kernel), drawing from the same generators in the same order."""

import math

import numpy as np

from sim.portable_exp import exp_portable_np
from sim.effects import detection_probability, range_limit_m, range_noise_sigma_m, return_gain
from sim.scan.kernels import RAY_OK


def returns_twin(prim, status, range_m, d_lidar, t_ns, refl_table, target_prim_end, rngs, params,
                 envelope_m=(0.0, np.inf), cos_incidence=None, extinction_1_m=0.0, noise_limit_m=0.0,
                 clutter_range_m=None, clutter_byte=1):
    """``rngs``: effect name -> Generator for the listed effects; ``params``: effect parameters;
    ``envelope_m``: (blind zone, maximum range) [m], applied to the measured range.

    ``cos_incidence`` (per ray, None: off), ``extinction_1_m`` (0: off): the return's power gain
    (:func:`sim.effects.return_gain`) scales the effective reflectivity; ``noise_limit_m`` > 0: the
    range noise model; ``clutter_range_m`` (per ray, inf: none; None: off): droplet returns, the
    first return of their ray.  Points come out in ray order."""
    n = prim.shape[0]
    idx = np.flatnonzero((prim >= 0) & (status == RAY_OK))
    r = range_m[idx]
    refl = refl_table[prim[idx]]
    d = d_lidar[idx]
    gain = np.ones(idx.size)
    use_gain = cos_incidence is not None or extinction_1_m > 0
    if use_gain:
        gain = return_gain(np.ones(idx.size) if cos_incidence is None else cos_incidence[idx], r, extinction_1_m)
    keep = np.ones(idx.size, dtype=bool)
    r_lim = range_limit_m(refl, params.get("range_80pct_m", 260.0))
    if use_gain:
        r_lim = r_lim * np.sqrt(gain)
    if "return_probability" in rngs:
        u = rngs["return_probability"].random(idx.size)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.clip((r - r_lim) / (0.03 * r_lim), -50, 50)
            p = 1.0 / (1.0 + exp_portable_np(z))
        keep &= (u < p) & (r_lim > 0)
        if not use_gain:
            assert np.array_equal(u < p, u < detection_probability(r, refl, params["range_80pct_m"]))
    if "dropouts" in rngs:
        keep &= rngs["dropouts"].random(idx.size) >= params["dropout_rate"]
    if "range_noise" in rngs:
        z = rngs["range_noise"].standard_normal(idx.size)
        if noise_limit_m > 0:
            with np.errstate(divide="ignore", invalid="ignore"):
                sigma = range_noise_sigma_m(r, r_lim, params["range_noise_m"], noise_limit_m)
            r = r + sigma * z
        else:
            r = r + rngs_normal_scale(params["range_noise_m"], z)
    with np.errstate(invalid="ignore"):
        keep &= (r >= envelope_m[0]) & (r <= envelope_m[1])
    if "angular_noise" in rngs and idx.size:
        d = d + rngs["angular_noise"].normal(0.0, math.radians(params["angular_noise_deg"]), d.shape)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
    xyz = d * r[:, None]
    if use_gain:
        refl_byte = np.clip(np.rint(refl * gain * 100), 0, 255).astype(np.uint8)
    else:
        refl_byte = np.clip(np.round(refl * 100), 0, 255).astype(np.uint8)
    on_target = prim[idx] < target_prim_end
    if clutter_range_m is None:
        return xyz[keep], t_ns[idx][keep], refl_byte[keep], on_target[keep]
    # droplets: per ray, the hit's point (if kept) or the droplet's, whichever is first
    c = np.where(status == RAY_OK, clutter_range_m, np.inf)
    hit_r = np.full(n, np.inf)
    hit_r[idx[keep]] = r[keep]
    use_c = np.isfinite(c) & (c < hit_r) & (c >= envelope_m[0]) & (c <= envelope_m[1])
    drop_hit = np.zeros(n, dtype=bool)
    drop_hit[np.isfinite(c) & (c < hit_r)] = True
    kept_hit = np.zeros(n, dtype=bool)
    kept_hit[idx[keep]] = True
    kept_hit &= ~drop_hit
    out_xyz = np.zeros((n, 3))
    out_refl = np.zeros(n, np.uint8)
    out_on = np.zeros(n, bool)
    pos = np.full(n, -1)
    pos[idx] = np.arange(idx.size)
    hk = pos[kept_hit]
    out_xyz[kept_hit] = xyz[hk]
    out_refl[kept_hit] = refl_byte[hk]
    out_on[kept_hit] = on_target[hk]
    out_xyz[use_c] = d_lidar[use_c] * c[use_c][:, None]
    out_refl[use_c] = clutter_byte
    sel = kept_hit | use_c
    return out_xyz[sel], t_ns[sel], out_refl[sel], out_on[sel]


def rngs_normal_scale(sigma_m, z):
    """``rng.normal(0, sigma)``'s expression from its standard normals: ``0.0 + sigma * z``."""
    return 0.0 + sigma_m * z


def mixed_pixel_twin(sub_r, sub_prim, refl_table, resolution_m):
    """One echo per beam, written from the model's words (sim.effects, mixed pixels): group the hit
    sub-rays by range gaps <= resolution, power rho / r^2, the strongest group (the nearer of equal
    ones) at its power-weighted range."""
    n, s = sub_r.shape
    out_r, out_p, out_share = np.full(n, np.inf), np.full(n, -1, dtype=np.int64), np.zeros(n)
    for k in range(n):
        hit = np.flatnonzero(sub_prim[k] >= 0)
        if hit.size == 0:
            continue
        hit = hit[np.argsort(sub_r[k, hit], kind="stable")]
        r = sub_r[k, hit]
        p = refl_table[sub_prim[k, hit]] / (r * r)
        groups = np.split(np.arange(hit.size), np.flatnonzero(np.diff(r) > resolution_m) + 1)
        best = None
        for g in groups:
            pg = p[g].sum()
            if best is None or pg > best[0]:
                best = (pg, g)
        pg, g = best
        out_r[k] = np.sum(p[g] * r[g]) / pg
        out_p[k] = sub_prim[k, hit[g[np.argmax(p[g])]]]
        out_share[k] = g.size / s
    return out_r, out_p, out_share


def object_rays_twin(prim, status, object_prim_start):
    """Per object, the rays that hit it and left the prisms, as the sensor counted them before
    ``object_rays_kernel``: ``object_prim_start`` the first primitive of each object and the end."""
    on = (prim >= 0) & (prim < object_prim_start[-1]) & (status == RAY_OK)
    which = np.searchsorted(object_prim_start, prim[on], side="right") - 1
    return np.bincount(which, minlength=object_prim_start.size - 1)
