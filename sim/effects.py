"""Sensor effects a scene may list; each one is opt-in and owns its random stream.

An effect that the scene does not list is never called, so it draws no random numbers and costs
no time (``tests/world/test_loop.py`` checks both).  Streams are keyed by the effect's name, so
adding one effect to a scene does not change the draws of another.

Sources of the defaults:
* range noise 2 cm (1 sigma) — Livox Mid-40 range precision at 20 m;
* return probability — Livox detection range 260 m at 80 % reflectivity, 130 m at 20 %: the range
  limit scales as sqrt(reflectivity) (``R = 260 m sqrt(rho / 0.8)``); detection probability falls
  as a logistic of width 3 % of R around it (50 % at R);
* sunlight false alarms < 0.01 % — Livox specification ("false alarm rate < 0.01 %"), placed at
  uniform random ranges along the beam;
* motor speed noise 1 % — the paper's Fig. 7 simulation.
"""

from __future__ import annotations

import math
import zlib

import numpy as np

from sim import random_kernels as rk


def effect_rng(seed: int, name: str) -> np.random.Generator:
    """The random stream of one named noise source of a run (independent of the others)."""
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(name.encode())]))


# The draws of the per-hit effects, one call per frame and effect (``n_hits`` = rays that hit
# something).  :func:`sim.sensor_kernels.assemble_returns_kernel` applies them.

def return_draws(rng, n_hits: int) -> np.ndarray:
    """Uniforms for the return probability: hit ``h`` returns if ``u[h] < detection_probability``."""
    return rng.random(n_hits)


def dropout_draws(rng, n_hits: int) -> np.ndarray:
    """Uniforms for point dropouts: hit ``h`` is dropped if ``u[h] < dropout_rate``."""
    return rng.random(n_hits)


def standard_normals(rng, n: int) -> np.ndarray:
    """``rng.standard_normal(n)``, value for value: for a numpy Generator through numba's ziggurat
    (:mod:`sim.random_kernels`; 0.038 against numpy's 0.091 ms for 10 000 on the AVX-512 test machine);
    a stream drawn ahead (:class:`sim.ahead.DrawsAhead`) gives its own."""
    if isinstance(rng, np.random.Generator):
        out = np.empty(n)
        rk.fill_standard_normal_kernel(rng, out)
        return out
    return rng.standard_normal(n)


def range_noise_normals(rng, n_hits: int) -> np.ndarray:
    """The standard normals of the range noise; :func:`sim.sensor_kernels.assemble_returns_kernel`
    scales each as :func:`range_noise_draws` does (``0.0 + sigma_m * z``, the same bits)."""
    return standard_normals(rng, n_hits)


def angular_noise_normals(rng, n_hits: int) -> np.ndarray:
    """The 3 standard normals per hit of the angular noise, flat; scaled in the kernel as
    :func:`angular_noise_draws` does (``0.0 + radians(sigma_deg) * z``, the same bits)."""
    return standard_normals(rng, 3 * n_hits)


def range_noise_draws(rng, n_hits: int, sigma_m: float) -> np.ndarray:
    """Range errors [m], gaussian: ``rng.normal(0, sigma_m, n_hits)`` (which is ``0 + sigma * z``)."""
    return 0.0 + sigma_m * standard_normals(rng, n_hits)


def angular_noise_draws(rng, n_hits: int, sigma_deg: float) -> np.ndarray:
    """Direction errors (n_hits, 3) [rad], gaussian per axis: a small isotropic angle once the
    direction is renormalised.  ``rng.normal(0, sigma, (n_hits, 3))``, value for value."""
    return 0.0 + math.radians(sigma_deg) * standard_normals(rng, 3 * n_hits).reshape(n_hits, 3)


def range_limit_m(reflectivity: np.ndarray, range_80pct_m: float) -> np.ndarray:
    """Range [m] of 50 % detection probability: ``range_80pct_m * sqrt(reflectivity / 0.8)``."""
    return range_80pct_m * np.sqrt(np.clip(reflectivity, 1e-6, 1.0) / 0.8)


def detection_probability(range_m: np.ndarray, reflectivity: np.ndarray, range_80pct_m: float) -> np.ndarray:
    """Probability of a return (the kernel computes the same per hit; this is for plots and twins)."""
    r_max = range_limit_m(reflectivity, range_80pct_m)
    z = (range_m - r_max) / (0.03 * r_max)
    return 1.0 / (1.0 + np.exp(np.clip(z, -50, 50)))


def footprint_offsets(divergence_deg: tuple[float, float], subrays: int) -> np.ndarray:
    """Angular offsets (rad) of sub-rays spread over the beam's divergence ellipse: the centre and
    ``subrays - 1`` points on the half-power ellipse (az, el)."""
    a = math.radians(divergence_deg[0]) / 2
    b = math.radians(divergence_deg[1]) / 2
    ang = np.linspace(0, 2 * math.pi, max(subrays - 1, 0), endpoint=False)
    pts = [(0.0, 0.0)] + [(a * math.cos(t), b * math.sin(t)) for t in ang]
    return np.array(pts)
