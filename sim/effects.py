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

Head and timing (no datasheet of the PTS-303H exists, ``/work/shared/facts/gimbal-pelco.md``; where no
source gives a value it is a stated assumption, with why it is plausible):

* ``head_thermal_drift`` — the speed curve scales by ``1 + head_speed_coeff_per_k * head_delta_t_k``
  against the curve the tracker's table was calibrated on.  Coefficient -0.1 %/K, an assumption: a
  brushed DC gear motor at fixed voltage loses speed as its copper winding's resistance rises
  (+0.39 %/K, the resistivity of copper) and gains as its ferrite magnet weakens (about -0.2 %/K,
  which raises the no-load speed by as much); at a load of a third of stall torque the net is about
  -0.1 %/K (worm-gear grease thinning when warm pulls the other way, so the sign is the uncertain
  part).  ``head_delta_t_k`` 20 K: calibrated indoors at 20 degC, running in the afternoon sun at
  40 degC.  Deterministic: no random draws.
* ``head_dead_time_jitter`` — each command's dead time is ``dead_time_s`` plus a uniform spread of
  ``dead_time_jitter_s`` = 20 ms around it (centred: the mean dead time, which the tracker's table
  holds, is unchanged).  An assumption: the head's controller acts on a command at its next control
  tick, and a 50 Hz tick (20 ms) is typical of the 8-bit controllers of such heads.  Its own stream.
* ``link_latency_jitter`` — host and link latency: each command's bytes reach the wire later than the
  time the host stamps on the write by an exponential delay of mean ``link_latency_jitter_s`` = 1 ms
  (the host never learns it).  An assumption: a USB-serial adapter sends a write in the next 1 ms
  USB full-speed frame (0-1 ms), and a non-real-time Linux host's wake-up latency adds a few tenths
  of a ms with a tail of ms; an exponential of mean 1 ms covers both.  Its own stream.
* ``lidar_clock_drift`` — the lidar's free-running clock (no PTP/PPS) runs at
  ``1 + lidar_clock_drift_ppm * 1e-6`` of true time: -20 ppm, the slow end of a common +-20 ppm
  crystal (an assumption: Livox publishes no clock tolerance).  The slow end is the harder one: the
  host - sensor offset, kept as a minimum over packets (``foveatrack.daemon.runtime``), does not
  follow a clock that falls behind, so the tracker's sensor time of "now" lags the true one by
  ``|ppm| * elapsed``.  Deterministic: no random draws.
* ``head_backlash`` — each axis's worm gear has ``head_backlash_deg`` = 0.2 deg of free play: on a
  reversal the motor turns that far before the output follows (:mod:`gimbal.pts303h.kinematics`).
  An assumption: a comparable worm-gear head states +-0.1 deg preset accuracy (BIT-PT850, the head
  facts), which its play cannot exceed by much; light worm gears of this class have 0.1-0.5 deg.
  The play starts centred (the output half the play from either end).  Deterministic: no draws.
  The head's exact constant-acceleration pieces are then not used: each point's pose comes from
  the head model (the slow route, as with ``head_ripple``).
* ``head_wind`` — the wind's torque on the lidar bends the head's drive elastically (a worm gear is
  self-locking: the wind cannot turn it): deflection = torque / ``head_stiffness_nm_per_rad``, with
  torque ``0.5 rho Cd A L v(t)^2``.  Cd A = 1.2 x 0.02 m^2 (a Mid-40, 88 x 69 x 76 mm, on its bracket:
  a bluff box), L = 5 cm (the centre of pressure's offset from the pan axis; half that for tilt) and
  the stiffness 100 N m/rad of a light worm-gear stage and mount are stated assumptions (a
  harmonic drive of that size is some 40 times stiffer).  The wind ``wind_speed_m_s`` = 8 m/s
  (Beaufort 4-5), from the left, with gusts of relative rms ``wind_turbulence`` = 0.2 (open
  terrain, IEC 61400-1 class C's 0.12-0.2 at such speeds), as 16 sinusoids of random phase (the
  effect's own stream, drawn once) from 0.02 to 2 Hz weighted by a Kaimal spectrum (length scale
  50 m).  The torque is 0.05 N m, far below a 3 kg-payload head's holding torque: no slip.  At the
  defaults the deflection is about 0.03 deg: the effect is small, which is the point of measuring it.
"""

from __future__ import annotations

import math
import zlib

import numpy as np

from sim import random_kernels as rk
from sim.portable_exp import exp_portable_np


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
    return 1.0 / (1.0 + exp_portable_np(np.clip(z, -50, 50)))


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
    return np.asarray(ray_gain, float) * exp_portable_np(-2.0 * extinction_1_m * np.asarray(range_m, float))


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


# ------------------------------------------------------------------------------------------------
# head and timing effects
# ------------------------------------------------------------------------------------------------
def thermal_speed_scale(coeff_per_k: float, delta_t_k: float) -> float:
    """The head's speeds now over its calibrated curve: ``1 + coeff_per_k * delta_t_k``."""
    return 1.0 + coeff_per_k * delta_t_k


def link_latency_draw(rng, mean_s: float) -> float:
    """One command's extra delay [s] from the host's write to the wire: exponential of mean ``mean_s``."""
    return float(rng.exponential(mean_s))


class LidarClock:
    """The lidar's free-running clock, and the host's view of it as the daemon keeps it.

    Sensor time = true time ``* (1 + drift_ppm * 1e-6)``, both from power-on at virtual time 0 (a
    point's ns: ``t_ns + rint(t_ns * drift_ppm * 1e-6)``, exact to 1 ns).  The host maps its time to
    sensor time with ``offset = min(host receive time - sensor time)`` over what it has received, as
    :mod:`foveatrack.daemon.runtime` does (receive time = the point's true time: no transit delay).
    """

    def __init__(self, drift_ppm: float):
        self.drift_ppm = float(drift_ppm)
        self._k = self.drift_ppm * 1e-6
        self.offset_s = 0.0      # host - sensor at power-on (both clocks read 0 then)

    def sensor_ns(self, t_ns: np.ndarray) -> np.ndarray:
        t_ns = np.asarray(t_ns, dtype=np.int64)
        return t_ns + np.rint(t_ns * self._k).astype(np.int64)

    def sensor_s(self, t_s: float) -> float:
        """Sensor time [s] of a true time (on the ns grid of :meth:`sensor_ns`)."""
        t_ns = round(t_s * 1e9)
        return (t_ns + round(t_ns * self._k)) * 1e-9

    def observe(self, host_s: float, sensor_s: float) -> None:
        """A packet whose last point has sensor time ``sensor_s`` arrived at ``host_s``."""
        self.offset_s = min(self.offset_s, host_s - sensor_s)

    def host_to_sensor(self, host_s: float) -> float:
        return host_s - self.offset_s

    def sensor_to_host(self, sensor_s: float) -> float:
        return sensor_s + self.offset_s


AIR_DENSITY_KG_M3 = 1.225
HEAD_DRAG_AREA_M2 = 1.2 * 0.02     # Cd x frontal area of a Mid-40 on its bracket (a bluff box)
HEAD_WIND_ARM_M = 0.05             # centre of pressure off the pan axis (half that off the tilt axis)
GUST_LENGTH_SCALE_M = 50.0         # Kaimal spectrum's length scale near the ground


class WindOnHead:
    """The head's elastic deflection by the wind, a pure function of time (``gimbal.pts303h.PTS303H``'s
    ``deflection``): :meth:`angles_deg` and :meth:`rates_deg_s` at an array of times.

    v(t) = U (1 + I g(t)) with g a unit-variance sum of ``N_GUST`` sinusoids (random phases from
    ``rng``, drawn here once; a Kaimal spectrum's weights); deflection = 0.5 rho Cd A L v^2 / k,
    pan pushed right (negative) and tilt down by half as much.

    The angles interpolate g linearly between nodes on a fixed grid of ``NODE_S`` (k * 1 ms, the same
    nodes whatever is asked, so still a pure function of time): 16 sinusoids per node instead of per
    point (a frame's 10 000 points share 101 nodes).  The error against the exact sum
    (:meth:`angles_deg_exact`) is below :meth:`interpolation_bound_deg`: 3e-7 deg at 8 m/s, 1e-5 deg
    at 40 m/s (tested).  The rates are exact.
    """

    N_GUST = 16
    NODE_S = 0.001

    def __init__(self, speed_m_s: float, turbulence: float, stiffness_nm_per_rad: float, rng):
        f_hz = np.geomspace(0.02, 2.0, self.N_GUST)
        u = max(speed_m_s, 0.1)
        spectrum = f_hz / (1.0 + 6.0 * f_hz * GUST_LENGTH_SCALE_M / u) ** (5.0 / 3.0)   # f S(f): log spacing
        weights = spectrum / spectrum.sum()
        self.omega = 2 * math.pi * f_hz
        self.amp = np.sqrt(2.0 * weights)              # sum of amp^2 / 2 = 1: unit variance
        self.phase = rng.uniform(0.0, 2 * math.pi, self.N_GUST)
        self.speed_m_s = float(speed_m_s)
        self.turbulence = float(turbulence)
        # deflection per (m/s)^2 about the pan axis [deg]
        self.deg_per_speed2 = math.degrees(0.5 * AIR_DENSITY_KG_M3 * HEAD_DRAG_AREA_M2 * HEAD_WIND_ARM_M
                                           / stiffness_nm_per_rad)

    def _gust(self, t_s, rates: bool):
        """g(t) (or its rate) as a sum in a fixed order over the sinusoids (no BLAS: its order
        differs per CPU)."""
        t = np.asarray(t_s, dtype=float).reshape(-1)
        out = np.zeros(t.size)
        arg = np.empty(t.size)
        trig = np.cos if rates else np.sin
        for w, ph, a in zip(self.omega.tolist(), self.phase.tolist(), self.amp.tolist()):
            np.multiply(t, w, out=arg)
            arg += ph
            trig(arg, out=arg)
            arg *= a * w if rates else a
            out += arg
        return out

    def speed(self, t_s: np.ndarray, exact: bool = True) -> np.ndarray:
        """Wind speed [m/s] at each time (``exact=False``: g interpolated between the nodes)."""
        if self.turbulence == 0.0:
            return np.full(np.size(t_s), self.speed_m_s)
        return self.speed_m_s * (1.0 + self.turbulence * (self._gust(t_s, False) if exact else self._gust_nodes(t_s)))

    def _gust_nodes(self, t_s) -> np.ndarray:
        t = np.asarray(t_s, dtype=float).reshape(-1)
        u = t / self.NODE_S
        k = np.floor(u)
        frac = u - k
        k0 = int(k.min()) if k.size else 0
        if k.size and k.max() - k0 < 4 * k.size + 16:     # a span of nodes (a frame, a gyro batch)
            nodes = np.arange(k0, int(k.max()) + 2)
            g = self._gust(nodes * self.NODE_S, False)
            i = (k - k0).astype(np.intp)
        else:                                            # scattered times: only the nodes they need
            nodes, inv = np.unique(np.concatenate([k, k + 1]), return_inverse=True)
            g = self._gust(nodes * self.NODE_S, False)
            i = inv[:k.size]
            return g[i] + frac * (g[inv[k.size:]] - g[i])
        return g[i] + frac * (g[i + 1] - g[i])

    def speed_rate(self, t_s: np.ndarray) -> np.ndarray:
        """Its rate [m/s^2] at each time."""
        if self.turbulence == 0.0:
            return np.zeros(np.size(t_s))
        return self.speed_m_s * self.turbulence * self._gust(t_s, True)

    def angles_deg(self, t_s: np.ndarray, exact: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Deflection (pan, tilt) [deg]: pan pushed right (negative), tilt down by half as much (the
        gusts interpolated between the nodes unless ``exact``)."""
        v = self.speed(t_s, exact)
        pan = -self.deg_per_speed2 * v * v
        return pan, 0.5 * pan

    def interpolation_bound_deg(self) -> float:
        """Bound on ``|angles_deg - angles_deg_exact|`` (pan; tilt half): a linear interpolation's
        ``h^2 / 8 max|g''|``, with ``max|g''| <= sum a w^2`` and ``|d defl / d g| <= 2 c U^2 I (1 + I sum a)``."""
        sum_a = float(np.sum(self.amp))
        g2 = float(np.sum(self.amp * self.omega**2))
        slope = 2.0 * self.deg_per_speed2 * self.speed_m_s**2 * self.turbulence * (1.0 + self.turbulence * sum_a)
        return slope * self.NODE_S**2 / 8.0 * g2

    def angles_deg_exact(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`angles_deg` with every sinusoid evaluated at each time (the reference)."""
        return self.angles_deg(t_s, exact=True)

    def rates_deg_s(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Their rates [deg/s]."""
        pan_rate = -self.deg_per_speed2 * 2.0 * self.speed(t_s) * self.speed_rate(t_s)
        return pan_rate, 0.5 * pan_rate
