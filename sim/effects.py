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
* motor speed noise 1 % — the paper's Fig. 7 simulation;
* range noise model (``range_noise_model``, shapes ``range_noise``) — a pulsed time-of-flight
  ranger's timing jitter goes as 1/SNR, and the SNR of an extended diffuse target as
  ``rho cos(theta) T^2 / R^2`` (the lidar equation; e.g. Baltsavias 1999, "Airborne laser scanning:
  basic relations and formulas", ISPRS J. 54, eq. for sigma_R ~ 1/SNR).  With the detection
  threshold at the range limit of :func:`range_limit_m` (where SNR is the threshold's), the jitter is
  ``noise_limit_m (R / R_lim)^2``, added in quadrature to the floor ``range_noise_m`` (the
  datasheet's 2 cm at 20 m, where ``(R / R_lim)^2`` is < 0.02 for rho >= 0.2).  ``noise_limit_m``
  = 0.15 m is an assumption (no Livox datasheet gives the precision near the range limit; the
  Tele-15's "< 2 cm over 5-70 m" bounds it from below): measure it on a recording to replace it;
* incidence (``incidence``) — a diffuse (Lambertian) surface returns power in proportion to
  ``rho cos(theta)``, theta the angle between the beam and the surface normal (the lidar equation
  for an extended target; Kashani et al. 2015, "A review of LIDAR radiometric processing", Sensors
  15, sec. 2): the effective reflectivity is ``rho |cos theta|``;
* mixed pixels (``mixed_pixels``, on ``beam_footprint``'s sub-rays, equal shares of the beam) — a
  footprint partly on a near edge and partly on a surface behind: each sub-ray returns ``rho / r^2``;
  surfaces closer in range than the pulse can resolve give one echo at the power-weighted mean range
  (the "mixed pixel" between them: Hebert and Krotkov 1992, "3-D measurements from imaging laser
  radars: how good are they?", Image Vision Comput. 10(3), sec. 3.2; Tang et al. 2007, Autom.
  Constr. 16, mixed pixels at edges), farther ones separate echoes of which a single-return unit
  reports the strongest; the echo's power is its share of the beam (scaling the effective
  reflectivity).  Resolution ``c tau / 2`` = 0.75 m for a 5 ns pulse: an assumption typical of
  905 nm pulsed lidars (Livox publishes no pulse width), as is "strongest" (the Mid-40 has one
  return mode; the Horizon's default single return is the strongest, per its SDK's return modes);
* weather (``weather``: fog, haze, dust, rain given as a visibility) — extinction
  ``alpha = 3.912 / V (lambda / 550 nm)^-q`` (Koschmieder's law; Kim, McArthur, Korevaar 2001,
  "Comparison of laser beam propagation at 785 nm and 1550 nm in fog and haze for optical wireless
  communications", Proc. SPIE 4214, for q: 1.6 above 50 km, 1.3 at 6-50 km, 0.16 V + 0.34 at 1-6 km,
  V - 0.5 at 0.5-1 km, 0 below), the two-way transmission ``exp(-2 alpha R)`` scaling the effective
  reflectivity; droplets give false returns near the sensor (the backscatter of fog peaks within a
  few metres: Hahner et al. 2021, "Fog simulation on real LiDAR point clouds", ICCV, fig. 3):
  ``weather_clutter_prob`` of the beams return from a droplet at a range uniform in
  ``[weather_clutter_min_m, weather_clutter_max_m]``, reflectivity byte 1.  The clutter probability
  (0.2 %) is an assumption for moderate fog, not a datasheet figure.  A Livox's rain/fog
  suppression (SDK v1 lidar command 0x03; the protocol documents only the switch, not the
  algorithm) is modelled as removing those droplet returns (:class:`sim.sensor.SceneSensor`).
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


def return_gain(ray_gain, range_m, extinction_1_m: float) -> np.ndarray:
    """Returned power against a clear head-on return of the whole beam: ``g exp(-2 alpha R)``, ``g``
    = ``|cos theta|`` (effect ``incidence``) times the share of the beam in the echo (effect
    ``mixed_pixels``); pass ``ray_gain = 1`` or ``extinction_1_m = 0`` for either off."""
    return np.asarray(ray_gain, float) * np.exp(-2.0 * extinction_1_m * np.asarray(range_m, float))


def range_noise_sigma_m(range_m, range_limit_m_, range_noise_m: float, noise_limit_m: float) -> np.ndarray:
    """Range noise 1 sigma [m] of the model: ``sqrt(floor^2 + (noise_limit_m (R / R_lim)^2)^2)``, with
    ``R_lim`` the effective range limit (:func:`range_limit_m` of ``rho * gain``)."""
    q = np.asarray(range_m, float) / np.asarray(range_limit_m_, float)
    q = q * q * noise_limit_m
    return np.sqrt(range_noise_m * range_noise_m + q * q)


def extinction_1_m(visibility_m: float, wavelength_nm: float = 905.0) -> float:
    """Atmospheric extinction [1/m] at the lidar's wavelength for a meteorological visibility [m]
    (Koschmieder, with Kim et al.'s wavelength exponent; module docstring)."""
    v_km = visibility_m / 1000.0
    if v_km > 50:
        q = 1.6
    elif v_km > 6:
        q = 1.3
    elif v_km > 1:
        q = 0.16 * v_km + 0.34
    elif v_km > 0.5:
        q = v_km - 0.5
    else:
        q = 0.0
    return 3.912 / visibility_m * (wavelength_nm / 550.0) ** (-q)


def weather_clutter_draws(rng, ok_rays: np.ndarray, prob: float, lo_m: float, hi_m: float):
    """Droplet returns of one frame: ``(rays, ranges_m)``; a binomial count over the rays that left
    the prisms, the rays drawn without replacement, the ranges uniform.  Draws: count, rays, ranges."""
    k = int(rng.binomial(ok_rays.size, prob)) if ok_rays.size else 0
    if k == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    rays = rng.choice(ok_rays, k, replace=False)
    return rays, rng.uniform(lo_m, hi_m, k)
