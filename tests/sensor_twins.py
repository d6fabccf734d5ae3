"""Plain-numpy twin of :mod:`sim.sensor_kernels`: the sensor's returns as array operations (the
route the simulator took before the kernel), drawing from the same generators in the same order."""

import math

import numpy as np

from sim.effects import detection_probability
from sim.scan.kernels import RAY_OK


def returns_twin(prim, status, range_m, d_lidar, t_ns, refl_table, target_prim_end, rngs, params,
                 envelope_m=(0.0, np.inf)):
    """``rngs``: effect name -> Generator for the listed effects; ``params``: effect parameters;
    ``envelope_m``: (blind zone, maximum range) [m], applied to the measured range."""
    idx = np.flatnonzero((prim >= 0) & (status == RAY_OK))
    r = range_m[idx]
    refl = refl_table[prim[idx]]
    d = d_lidar[idx]
    keep = np.ones(idx.size, dtype=bool)
    if "return_probability" in rngs:
        keep &= rngs["return_probability"].random(idx.size) < detection_probability(r, refl, params["range_80pct_m"])
    if "dropouts" in rngs:
        keep &= rngs["dropouts"].random(idx.size) >= params["dropout_rate"]
    if "range_noise" in rngs:
        r = r + rngs["range_noise"].normal(0.0, params["range_noise_m"], idx.size)
    keep &= (r >= envelope_m[0]) & (r <= envelope_m[1])
    if "angular_noise" in rngs and idx.size:
        d = d + rngs["angular_noise"].normal(0.0, math.radians(params["angular_noise_deg"]), d.shape)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
    xyz = d * r[:, None]
    refl_byte = np.clip(np.round(refl * 100), 0, 255).astype(np.uint8)
    on_target = prim[idx] < target_prim_end
    return xyz[keep], t_ns[idx][keep], refl_byte[keep], on_target[keep]
