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


def effect_rng(seed: int, name: str) -> np.random.Generator:
    """The random stream of one named noise source of a run (independent of the others)."""
    return np.random.default_rng(np.random.SeedSequence([seed, zlib.crc32(name.encode())]))


def range_noise(rng, rng_m: np.ndarray, sigma_m: float) -> np.ndarray:
    return rng_m + rng.normal(0.0, sigma_m, rng_m.shape)


def angular_noise(rng, d: np.ndarray, sigma_deg: float) -> np.ndarray:
    """Perturb unit directions by a small isotropic angle (sigma per axis), renormalised."""
    out = d + rng.normal(0.0, math.radians(sigma_deg), d.shape)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def detection_probability(range_m: np.ndarray, reflectivity: np.ndarray, range_80pct_m: float) -> np.ndarray:
    r_max = range_80pct_m * np.sqrt(np.clip(reflectivity, 1e-6, 1.0) / 0.8)
    z = (range_m - r_max) / (0.03 * r_max)
    return 1.0 / (1.0 + np.exp(np.clip(z, -50, 50)))


def keep_with_probability(rng, p: np.ndarray) -> np.ndarray:
    return rng.random(p.shape) < p


def footprint_offsets(divergence_deg: tuple[float, float], subrays: int) -> np.ndarray:
    """Angular offsets (rad) of sub-rays spread over the beam's divergence ellipse: the centre and
    ``subrays - 1`` points on the half-power ellipse (az, el)."""
    a = math.radians(divergence_deg[0]) / 2
    b = math.radians(divergence_deg[1]) / 2
    ang = np.linspace(0, 2 * math.pi, max(subrays - 1, 0), endpoint=False)
    pts = [(0.0, 0.0)] + [(a * math.cos(t), b * math.sin(t)) for t in ang]
    return np.array(pts)
