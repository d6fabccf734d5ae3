"""The scan model: timestamped beam directions of a Risley-prism lidar.

Paper Section III (Fig. 3, 4, 8, 9) and Appendix B: the transceiver fires at a constant rate; each
point's direction follows from the prism angles at that point's own time, by exact refraction
(default) or by the paraxial vector sum (a named, cheaper approximation; its error is measured by
``foveatrack lidar info`` and the accuracy-vs-time study).

Point ``k`` (``k = 0, 1, ...``) is fired at ``t_k = k / point_rate_hz`` by channel ``k mod C``.
Phases are computed from the integer ``k`` (see :func:`sim.scan.kernels.phase_revs_kernel`), so a
direction after 24 h of virtual time is as exact as after 1 ms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.scan import kernels
from sim.scan.optics import RisleyOptics, SpeedNoise

_INT64_MAX = 2**63 - 1


def check_times_fit_ns(k0: int, count: int, rate_hz: int) -> None:
    """Refuse points whose time ``floor(k * 1e9 / rate)`` [ns] would not fit int64 (about 292 years
    of scanning): the kernels would wrap it silently."""
    if count > 0 and ((int(k0) + int(count) - 1) * 1_000_000_000) // int(rate_hz) > _INT64_MAX:
        raise ValueError(f"points {k0} .. {int(k0) + int(count) - 1} at {rate_hz} points/s are past the int64 "
                         f"nanosecond clock (about 292 years of scanning)")

SCAN_MODELS = ("exact", "paraxial")


@dataclass(frozen=True)
class ScanChunk:
    """Consecutive points ``k0 .. k0 + N - 1`` of the scan.

    Attributes
    ----------
    k0 : int                       index of the first point
    t_ns : (N,) int64 [ns]         point times, ``floor(k * 1e9 / rate)``
    direction : (N, 3) float64     unit beam direction, lidar frame (X fwd, Y left, Z up);
                                   (0, 0, 0) where ``status != RAY_OK``
    channel : (N,) uint8           transceiver channel (Livox line id)
    status : (N,) uint8            :data:`~sim.scan.kernels.RAY_OK`, ``RAY_TIR``, ``RAY_GRAZING`` or ``RAY_INVALID``
    """

    k0: int
    t_ns: np.ndarray
    direction: np.ndarray
    channel: np.ndarray
    status: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        return self.status == kernels.RAY_OK

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])


class ScanModel:
    """Beam directions and times of a scanner, optionally with motor speed noise.

    Parameters
    ----------
    optics : RisleyOptics
    model : {"exact", "paraxial"}
        ``exact`` traces vector Snell refraction at every face (the default and the reference);
        ``paraxial`` sums the prisms' first-order deviation vectors.
    speed_noise : SpeedNoise or None
        Motor speed errors (paper Fig. 7: 1 % gaussian).  None draws no random numbers at all.
    rng : numpy.random.Generator, optional
        The stream the speed noise draws from (required if ``speed_noise`` is given, so that the
        owner of the simulation controls seeding).
    """

    def __init__(
        self,
        optics: RisleyOptics,
        model: str = "exact",
        speed_noise: SpeedNoise | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        if model not in SCAN_MODELS:
            raise ValueError(f"scan model {model!r}: allowed {SCAN_MODELS}")
        if speed_noise is not None and rng is None:
            raise ValueError("speed_noise needs an rng (numpy.random.Generator) to draw from")
        self.optics = optics
        self.model = model
        self.speed_noise = speed_noise
        self._rng = rng
        prisms = optics.prisms
        split = [kernels.split_revs_per_point(optics.revs_per_point(i)) for i in range(len(prisms))]
        self._r_h1 = np.array([s[0] for s in split])
        self._r_h2 = np.array([s[1] for s in split])
        self._r_lo = np.array([s[2] for s in split])
        self._phase0_rev = np.array([(p.phase_deg / 360.0) % 1.0 for p in prisms])
        self._sin_wedge = np.array([math.sin(math.radians(p.wedge_deg)) for p in prisms])
        self._cos_wedge = np.array([math.cos(math.radians(p.wedge_deg)) for p in prisms])
        self._index = np.array([p.index for p in prisms])
        self._exit_tilted = np.array([p.tilted_face == "exit" for p in prisms])
        self._deviation_rad = np.radians([p.thin_prism_deviation_deg for p in prisms])
        off = np.radians(np.asarray(optics.channel_offsets_deg, dtype=float).reshape(-1, 2))
        self._offset_rad = np.ascontiguousarray(off)
        inc = np.column_stack([np.tan(off[:, 0]), np.tan(off[:, 1]), np.ones(len(off))])
        self._incident = np.ascontiguousarray(inc / np.linalg.norm(inc, axis=1, keepdims=True))
        self._rev_per_s = np.array([p.rpm / 60.0 for p in prisms])
        # several heads (optics.head_yaw_deg): each channel's beam turned about the lidar Z axis
        yaw = np.radians(np.asarray(optics.head_yaw_deg, dtype=float))
        self._head_cos_sin = np.column_stack([np.cos(yaw), np.sin(yaw)]) if yaw.size and yaw.any() else None
        # Speed-noise state, grown on demand in segment order so that the draws do not depend on
        # how the caller chunks the scan.
        self._noise_cum = np.zeros((1, len(prisms)))  # integral of relative speed error [s]
        self._noise_eps = np.zeros((0, len(prisms)))
        self._noise_seg0 = 0   # absolute index of the tables' first segment
        self._drift_phase = None
        self.noise_draws = 0  # how many random numbers the noise has drawn (tests count these)

    # ----------------------------------------------------------------------------------------------
    @property
    def prism_count(self) -> int:
        return len(self.optics.prisms)

    def index_at_time(self, t_s: float) -> int:
        """Index of the first point fired at or after ``t_s``."""
        return int(math.ceil(round(t_s * self.optics.point_rate_hz, 6)))

    def prism_revs(self, k0: int, count: int) -> np.ndarray:
        """Prism angles [rev, in [0, 1)] of points ``k0 .. k0 + count - 1``, shape (count, P).

        The array is a transposed view of a C-contiguous (P, count) block, the layout the trace
        kernels read (one prism's angles contiguous, so the inner loop vectorises).
        """
        out = np.empty((self.prism_count, count))
        kernels.phase_revs_kernel(int(k0), self._r_h1, self._r_h2, self._r_lo, self._phase0_rev, out)
        if self.speed_noise is not None and count:
            noise = self.speed_noise
            self._noise_for(k0, count)
            kernels.add_speed_noise_kernel(int(k0), float(self.optics.point_rate_hz), noise.segment_s,
                                           self._noise_cum, self._noise_eps, self._noise_seg0, self._rev_per_s, out)
            if noise.drift_frac > 0:
                t_s = (np.arange(count, dtype=np.float64) + float(k0)) / self.optics.point_rate_hz
                out += self._drift_revs(t_s).T
                np.mod(out, 1.0, out=out)
        return out.T

    def channels(self, k0: int, count: int) -> np.ndarray:
        c = self.optics.channels
        return ((np.arange(count, dtype=np.int64) + (k0 % c)) % c).astype(np.int64)

    def times_ns(self, k0: int, count: int) -> np.ndarray:
        check_times_fit_ns(k0, count, self.optics.point_rate_hz)
        out = np.empty(count, dtype=np.int64)
        kernels.point_times_ns_kernel(int(k0), int(self.optics.point_rate_hz), out)
        return out

    def directions_from_revs(self, revs: np.ndarray, channel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Directions and status for prism angles ``revs`` (N, P) [rev] and channels (N,)."""
        n = revs.shape[0]
        direction = np.empty((n, 3))
        status = np.zeros(n, dtype=np.uint8)
        revs_pn = np.ascontiguousarray(np.asarray(revs, dtype=np.float64).T)
        channel = np.ascontiguousarray(channel, dtype=np.int64)
        if self.model == "exact":
            kernels.trace_exact_kernel(
                revs_pn, channel, self._incident, self._sin_wedge, self._cos_wedge, self._index,
                self._exit_tilted, direction, status,
            )
        else:
            kernels.trace_paraxial_kernel(revs_pn, channel, self._offset_rad, self._deviation_rad, direction)
        self._turn_heads(direction, channel)
        return direction, status

    def _turn_heads(self, direction: np.ndarray, channel: np.ndarray) -> None:
        """Turn each beam by its head's yaw about Z, in place (no-op for a single-head scanner).
        One vectorised rotation per chunk: elementwise, so chunking cannot change a bit."""
        if self._head_cos_sin is None or not len(direction):
            return
        cs = self._head_cos_sin[np.asarray(channel, dtype=np.int64)]
        x, y = direction[:, 0].copy(), direction[:, 1].copy()
        direction[:, 0] = cs[:, 0] * x - cs[:, 1] * y
        direction[:, 1] = cs[:, 1] * x + cs[:, 0] * y

    @property
    def fused(self) -> bool:
        """True if :meth:`scan` runs the one-pass :func:`~sim.scan.kernels.scan_exact_kernel`: the
        exact model without the slow sinusoidal drift (``drift_frac == 0``, the default)."""
        return self.model == "exact" and (self.speed_noise is None or self.speed_noise.drift_frac == 0)

    def scan(self, k0: int, count: int) -> ScanChunk:
        """Points ``k0 .. k0 + count - 1``: times, directions, channels and ray status.

        Runs the fused kernel when :attr:`fused` (equal to :meth:`scan_composed` to ~1e-15 in
        direction, times and channels identical, the same noise draws), else :meth:`scan_composed`.
        """
        if k0 < 0 or count < 0:
            raise ValueError(f"k0 = {k0}, count = {count}: both must be >= 0")
        if not self.fused:
            return self.scan_composed(k0, count)
        k0 = int(k0)
        count = int(count)
        check_times_fit_ns(k0, count, self.optics.point_rate_hz)
        noise = self.speed_noise
        segment_s = 1.0
        if noise is not None and count:
            self._noise_for(k0, count)   # as prism_revs does, so the draws do not depend on the path
            segment_s = noise.segment_s
        t_ns = np.empty(count, dtype=np.int64)
        channel = np.empty(count, dtype=np.uint8)
        direction = np.empty((count, 3))
        status = np.empty(count, dtype=np.uint8)
        kernels.scan_exact_kernel(
            k0, int(self.optics.point_rate_hz), self._r_h1, self._r_h2, self._r_lo, self._phase0_rev,
            noise is not None, segment_s, self._noise_cum, self._noise_eps, self._noise_seg0, self._rev_per_s,
            int(self.optics.channels), self._incident, self._sin_wedge, self._cos_wedge, self._index,
            self._exit_tilted, t_ns, channel, direction, status,
        )
        self._turn_heads(direction, channel)
        return ScanChunk(k0=k0, t_ns=t_ns, direction=direction, channel=channel, status=status)

    def scan_composed(self, k0: int, count: int) -> ScanChunk:
        """:meth:`scan` through the separate kernels (phases, noise, drift, channels, times, trace):
        the path for the paraxial model and the drift, and the reference the fused kernel must equal."""
        if k0 < 0 or count < 0:
            raise ValueError(f"k0 = {k0}, count = {count}: both must be >= 0")
        revs = self.prism_revs(k0, count)
        channel = self.channels(k0, count)
        direction, status = self.directions_from_revs(revs, channel)
        return ScanChunk(
            k0=int(k0),
            t_ns=self.times_ns(k0, count),
            direction=direction,
            channel=channel.astype(np.uint8),
            status=status,
        )

    def scan_time(self, t0_s: float, t1_s: float) -> ScanChunk:
        """The points fired in ``[t0_s, t1_s)``."""
        k0 = self.index_at_time(t0_s)
        k1 = self.index_at_time(t1_s)
        return self.scan(k0, max(0, k1 - k0))

    def iter_chunks(self, duration_s: float, chunk_points: int = 100_000, k0: int = 0):
        """Consecutive chunks covering ``duration_s`` from point ``k0``."""
        total = int(round(duration_s * self.optics.point_rate_hz))
        k = k0
        while k < k0 + total:
            n = min(chunk_points, k0 + total - k)
            yield self.scan(k, n)
            k += n

    # ----------------------------------------------------------------------------------------------
    def _drift_revs(self, t_s: np.ndarray) -> np.ndarray:
        """Phase error [rev] of the slow sinusoidal speed drift, shape (N, P).

        Together with the segment errors added by :func:`sim.scan.kernels.add_speed_noise_kernel`
        (piecewise-constant relative errors :math:`\\varepsilon_j` on segments of length T), the
        phase error integrates the relative speed error exactly:

        .. math:: \\Delta\\phi_p(t) = \\frac{\\mathrm{rpm}_p}{60}\\Big[T\\sum_{i<j}\\varepsilon_{i,p}
                  + \\varepsilon_{j,p}(t - jT) + \\frac{A P_d}{2\\pi}
                  \\big(\\cos\\varphi_p - \\cos(2\\pi t/P_d + \\varphi_p)\\big)\\Big]
        """
        noise = self.speed_noise
        if self._drift_phase is None:
            self._drift_phase = self._rng.uniform(0, 2 * math.pi, self.prism_count)
            self.noise_draws += self.prism_count
        w = 2 * math.pi / noise.drift_period_s
        frac_s = noise.drift_frac / w * (
            np.cos(self._drift_phase)[None, :] - np.cos(w * t_s[:, None] + self._drift_phase[None, :]))
        return frac_s * self._rev_per_s[None, :]

    # Speed-noise tables: grown in blocks of at most _NOISE_GROW_MAX segments, and segments more than
    # _NOISE_KEEP behind the oldest point asked for are dropped (a day at 10 ms segments would
    # otherwise hold 280 MB; now at most ~6 MB).  The draws do not depend on either: a segment's error
    # is the same whenever it is drawn.
    _NOISE_GROW_MAX = 65_536
    _NOISE_KEEP = 65_536

    def _noise_for(self, k0: int, count: int) -> None:
        """Make the noise tables cover points ``k0 .. k0 + count - 1``; drop what lies far behind."""
        rate = self.optics.point_rate_hz
        seg = self.speed_noise.segment_s
        first = int(math.floor(k0 / rate / seg))
        if first < self._noise_seg0:
            raise ValueError(
                f"point {k0} (t = {k0 / rate:.3f} s) is older than the kept motor-speed noise (from "
                f"t = {self._noise_seg0 * seg:.3f} s): a scan with speed noise may go back at most "
                f"{self._NOISE_KEEP * seg:.0f} s behind the latest point it was asked for")
        self._grow_noise(int(math.floor((k0 + count - 1) / rate / seg)) + 2)
        drop = first - self._NOISE_KEEP - self._noise_seg0
        if drop > self._NOISE_KEEP:      # trim in big steps: a copy per ~11 min of virtual time
            self._noise_eps = self._noise_eps[drop:].copy()
            self._noise_cum = self._noise_cum[drop:].copy()
            self._noise_seg0 += drop

    def _grow_noise(self, segments: int) -> None:
        """Draw segments up to (absolute) ``segments``."""
        have = self._noise_seg0 + self._noise_eps.shape[0]
        if segments <= have:
            return
        noise = self.speed_noise
        grow = min(max(segments - have, have, 1024), max(segments - have, self._NOISE_GROW_MAX))
        eps = self._rng.normal(0.0, noise.sigma_frac, size=(grow, self.prism_count))
        self.noise_draws += eps.size
        self._noise_eps = np.vstack([self._noise_eps, eps])
        cum = self._noise_cum[-1] + np.cumsum(eps, axis=0) * noise.segment_s
        self._noise_cum = np.vstack([self._noise_cum, cum])
